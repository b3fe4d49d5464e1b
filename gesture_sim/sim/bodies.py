"""The body registry: which physical body the speech drives (``--body``).

A body row says what the motion stage's humanoid targets become: ``humanoid`` is the project's
own MuJoCo humanoid (targets used as they are); a **robot** row is an MJCF plus a *map*
(:class:`RobotMap`, a small JSON file) naming which of the robot's joints play the spine, the
arms (shoulder … wrist), the legs, which bodies are the torso, the shoulders, elbows and hands,
the feet's soles, the standing pose, the motor gains and the order of its motors. The shipped
rows are ``g1`` (Unitree G1, 29 DoF) and ``h1`` (Unitree H1); a user's robot is a path to its
map file (``--body my_robot.json``), whose ``mjcf`` is relative to the map.

:func:`resolve_body` is the one place a name becomes a :class:`BodySpec`.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from gesture_sim import ASSETS_DIR
from gesture_sim.errors import GestureSimError

#: Folder of the shipped robots (``assets/robots``; Unitree's models, BSD 3-Clause).
ROBOTS_DIR = ASSETS_DIR / "robots"
#: The shipped robot rows: name -> map file.
ROBOT_MAPS = {"g1": ROBOTS_DIR / "g1_map.json", "h1": ROBOTS_DIR / "h1_map.json"}
#: Every body name ``--body`` takes besides a map path.
BODIES = ("humanoid", *ROBOT_MAPS)
_SIDES = ("left", "right")
#: Map entries the retarget does not read (left out of :attr:`RobotMap.fingerprint`).
_NOT_KINEMATIC = ("kp", "kd", "upper_gain", "shaper_omega", "shaper_a_max", "source",
                  "front_camera")


@dataclass(frozen=True)
class ArmMap:
    """One arm of a robot.

    Attributes:
        joints: the arm's hinge joints, shoulder to wrist (names in the MJCF).
        shoulder_body, elbow_body, hand_body: bodies whose origins (the hand: plus
            ``hand_offset``, m, in the hand body's frame) are the shoulder, elbow and hand points.
        hand_axes: (3, 3) rows: the hand body's x, y, z axes in the humanoid hand's frame (the
            hand orientation the retarget matches; used only when ``orient`` is true).
        orient: match the hand's orientation (a robot with wrists).
    """

    joints: tuple[str, ...]
    shoulder_body: str
    elbow_body: str
    hand_body: str
    hand_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hand_axes: tuple[tuple[float, ...], ...] = ((1, 0, 0), (0, 1, 0), (0, 0, 1))
    orient: bool = False


@dataclass(frozen=True)
class RobotMap:
    """What the project needs to know of a robot beyond its MJCF (a JSON map file).

    Attributes:
        name: the robot's name; mjcf: the scene file (floor included), absolute.
        torso_body, pelvis_body: bodies of the trunk above the spine and of the free root.
        spine: the spine/waist joints (the trunk's orientation over the pelvis is matched).
        nod_joint: the joint that carries the head's nods where the robot has no neck (a waist
            pitch), or None; nod_gain: its share of the humanoid's neck + head flexion.
        arms: ``left`` / ``right`` :class:`ArmMap`.
        legs: ``left`` / ``right`` leg joints, hip to ankle.
        feet: ``left`` / ``right`` (body, (x, y, z) sole centre in that body's frame, m).
        sole: (back, front, half-width) of the sole around its centre (m).
        stand: joint -> angle (rad) of the standing pose (others 0).
        kp, kd: joint-name substring -> PD gain (N·m/rad, N·m·s/rad), first match wins.
        velocity_limit: joint-name substring -> joint speed limit (rad/s), first match wins.
        upper_gain: factor on kp of the arms and spine in the simulation (kd: its square root);
            shaper_omega: bandwidth (rad/s) of the reference model between the 30 Hz target
            stream and the motors (:class:`~gesture_sim.sim.robot.RobotSim`); shaper_a_max:
            joint-name substring -> that reference's acceleration bound (rad/s², first match
            wins; a number: every joint; unmatched joints: :data:`~gesture_sim.sim.robot.A_MAX`).
        motor_order: the robot's own motor order (its low-level command), joint names.
        has_face, has_fingers, has_neck: what of the humanoid's layers the robot can show.
        head_body: a body standing for the head (the tracked head point), head_offset (m).
        source: where the map's figures come from (free text).
        front_camera: (distance in front, height) of the ``front`` camera added to the scene (m).
    """

    name: str
    mjcf: Path
    torso_body: str
    pelvis_body: str
    spine: tuple[str, ...]
    arms: dict[str, ArmMap]
    legs: dict[str, tuple[str, ...]]
    feet: dict[str, tuple[str, tuple[float, float, float]]]
    sole: tuple[float, float, float]
    stand: dict[str, float]
    kp: dict[str, float]
    kd: dict[str, float]
    velocity_limit: dict[str, float]
    motor_order: tuple[str, ...]
    nod_joint: str | None = None
    nod_gain: float = 0.0
    upper_gain: float = 1.0
    shaper_omega: float = 30.0
    shaper_a_max: dict[str, float] = field(default_factory=dict)
    has_face: bool = False
    has_fingers: bool = False
    has_neck: bool = False
    head_body: str = ""
    head_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: str = ""
    front_camera: tuple[float, float] = (2.2, 0.9)
    text: str = field(default="", repr=False)

    @property
    def fingerprint(self) -> str:
        """Hash of what the retarget reads of the map (all but the gains, the camera and the
        source note) and of the model files (MJCF and meshes) in the model's folder."""
        try:
            raw = json.loads(self.text)
        except ValueError:
            raw = {}
        for key in _NOT_KINEMATIC:
            raw.pop(key, None)
        h = hashlib.sha256(json.dumps(raw, sort_keys=True).encode())
        folder = self.mjcf.parent
        for p in sorted(folder.rglob("*")):
            if p.is_file() and p.suffix.lower() in (".xml", ".stl", ".obj"):
                h.update(p.relative_to(folder).as_posix().encode())
                h.update(p.read_bytes())
        return h.hexdigest()[:16]

    def lookup(self, table: dict[str, float], joint: str, default: float) -> float:
        """The first entry of ``table`` whose key is a substring of ``joint``."""
        for key, value in table.items():
            if key in joint:
                return float(value)
        return default

    def load_model(self) -> mujoco.MjModel:
        """Compile the robot's scene (floor included), integrator ``implicitfast``, with the
        sites the project tracks added: ``left/right_hand_site`` (the hand points),
        ``left/right_foot_site`` (the sole centres), ``head_site`` and a ``front`` camera.

        Raises:
            GestureSimError: the MJCF is missing or does not compile, or the map names a joint
                or body the model does not have.
        """
        if not self.mjcf.is_file():
            raise GestureSimError(f"robot model not found: {self.mjcf}")
        try:
            spec = mujoco.MjSpec.from_file(str(self.mjcf))
            for side in _SIDES:
                arm = self.arms[side]
                _site(spec, arm.hand_body, f"{side}_hand_site", arm.hand_offset)
                _site(spec, self.feet[side][0], f"{side}_foot_site", self.feet[side][1])
            _site(spec, self.head_body, "head_site", self.head_offset)
            dist, height = self.front_camera
            spec.worldbody.add_camera(name="front", pos=[dist, 0.0, height],
                                      xyaxes=[0, 1, 0, 0, 0, 1], fovy=45.0)
            m = spec.compile()
        except ValueError as exc:
            raise GestureSimError(f"cannot compile {self.mjcf.name}: {exc}") from exc
        m.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        self.check(m)
        return m

    def check(self, m: mujoco.MjModel) -> None:
        """Raise :class:`GestureSimError` unless every name of the map is in the model."""
        def need(kind: mujoco.mjtObj, name: str) -> None:
            if mujoco.mj_name2id(m, kind, name) < 0:
                raise GestureSimError(f"robot {self.name!r}: the model has no "
                                      f"{kind.name[6:].lower()} {name!r}")
        J, B = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_BODY
        for j in (*self.spine, *self.motor_order, *self.stand,
                  *(j for a in self.arms.values() for j in a.joints),
                  *(j for leg in self.legs.values() for j in leg)):
            need(J, j)
        for b in (self.torso_body, self.pelvis_body, *(f[0] for f in self.feet.values()),
                  *(x for a in self.arms.values()
                    for x in (a.shoulder_body, a.elbow_body, a.hand_body))):
            need(B, b)
        if self.nod_joint:
            need(J, self.nod_joint)
        motors = {m.joint(m.actuator_trnid[a, 0]).name for a in range(m.nu)}
        missing = [j for j in self.motor_order if j not in motors]
        if missing:
            raise GestureSimError(f"robot {self.name!r}: no motor drives {missing[0]!r}")

    @property
    def arm_joints(self) -> tuple[str, ...]:
        """Both arms' joints, left then right."""
        return (*self.arms["left"].joints, *self.arms["right"].joints)

    @property
    def leg_joints(self) -> tuple[str, ...]:
        """Both legs' joints, left then right."""
        return (*self.legs["left"], *self.legs["right"])


def _site(spec: mujoco.MjSpec, body: str, name: str, pos) -> None:
    b = spec.body(body)
    if b is None:
        raise GestureSimError(f"robot model has no body {body!r}")
    b.add_site(name=name, pos=list(pos), size=[0.01, 0.01, 0.01])


def _floats(x, n: int, what: str) -> tuple[float, ...]:
    a = np.asarray(x, dtype=float).reshape(-1)
    if len(a) != n:
        raise GestureSimError(f"robot map: {what} needs {n} numbers")
    return tuple(float(v) for v in a)


def _table(x) -> dict[str, float]:
    """A joint-name substring -> number table (a bare number: every joint, key ``""``)."""
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        x = {"": x}
    if not isinstance(x, dict):
        raise GestureSimError("robot map: shaper_a_max needs a number or a table of numbers")
    out = {str(k): float(v) for k, v in x.items()}
    if not all(np.isfinite(v) and v > 0 for v in out.values()):
        raise GestureSimError("robot map: shaper_a_max values must be positive numbers")
    return out


def load_robot_map(path: str | Path) -> RobotMap:
    """Read a robot map (JSON; see :class:`RobotMap` and ``assets/robots/g1_map.json``).

    Raises:
        GestureSimError: the file is missing or malformed.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        raw = json.loads(text)
    except (OSError, ValueError) as exc:
        raise GestureSimError(f"cannot read robot map {path}: {exc}") from exc
    try:
        arms = {}
        for s in _SIDES:
            a = raw["arms"][s]
            arms[s] = ArmMap(
                joints=tuple(a["joints"]), shoulder_body=a["shoulder_body"],
                elbow_body=a["elbow_body"], hand_body=a["hand_body"],
                hand_offset=_floats(a.get("hand_offset", (0, 0, 0)), 3, "hand_offset"),
                hand_axes=tuple(tuple(r) for r in np.asarray(
                    a.get("hand_axes", np.eye(3)), dtype=float).reshape(3, 3).tolist()),
                orient=bool(a.get("orient", False)))
        feet = {s: (raw["feet"][s]["body"], _floats(raw["feet"][s]["sole_centre"], 3,
                                                    "sole_centre")) for s in _SIDES}
        return RobotMap(
            name=str(raw.get("name", path.stem)), mjcf=(path.parent / raw["mjcf"]).resolve(),
            torso_body=raw["torso_body"], pelvis_body=raw["pelvis_body"],
            spine=tuple(raw.get("spine", ())), arms=arms,
            legs={s: tuple(raw["legs"][s]) for s in _SIDES}, feet=feet,
            sole=_floats(raw.get("sole", (0.05, 0.12, 0.03)), 3, "sole"),
            stand={str(k): float(v) for k, v in raw.get("stand", {}).items()},
            kp=dict(raw["kp"]), kd=dict(raw["kd"]),
            velocity_limit=dict(raw.get("velocity_limit", {})),
            motor_order=tuple(raw["motor_order"]),
            nod_joint=raw.get("nod_joint"), nod_gain=float(raw.get("nod_gain", 0.0)),
            upper_gain=float(raw.get("upper_gain", 1.0)),
            shaper_omega=float(raw.get("shaper_omega", 30.0)),
            shaper_a_max=_table(raw.get("shaper_a_max", {})),
            has_face=bool(raw.get("has_face", False)),
            has_fingers=bool(raw.get("has_fingers", False)),
            has_neck=bool(raw.get("has_neck", False)),
            head_body=raw.get("head_body", raw["torso_body"]),
            head_offset=_floats(raw.get("head_offset", (0, 0, 0)), 3, "head_offset"),
            source=str(raw.get("source", "")),
            front_camera=_floats(raw.get("front_camera", (2.2, 0.9)), 2, "front_camera"),
            text=text)
    except (KeyError, TypeError) as exc:
        raise GestureSimError(f"robot map {path}: missing or malformed entry {exc}") from exc


@dataclass(frozen=True)
class BodySpec:
    """A row of the body registry.

    Attributes:
        name: ``humanoid``, ``g1``, ``h1`` or the user's robot's name.
        robot: the robot's map, or None for the humanoid.
    """

    name: str
    robot: RobotMap | None = None

    @property
    def is_robot(self) -> bool:
        """Whether the body is a robot (targets retargeted onto it)."""
        return self.robot is not None

    @property
    def has_face(self) -> bool:
        """Whether the body shows the face layers (the humanoid does)."""
        return self.robot is None or self.robot.has_face


def resolve_body(body: str | Path | BodySpec | None) -> BodySpec:
    """The registry row for ``body``: a name of :data:`BODIES`, a map file path (``.json``), or a
    :class:`BodySpec` (returned as is); None is the humanoid.

    Raises:
        GestureSimError: an unknown name or an unreadable map.
    """
    if isinstance(body, BodySpec):
        return body
    if body is None or str(body) == "humanoid":
        return BodySpec("humanoid")
    key = str(body)
    if key in ROBOT_MAPS:
        robot = load_robot_map(ROBOT_MAPS[key])
        return BodySpec(key, robot)
    if key.endswith(".json"):
        if not Path(key).is_file():
            raise GestureSimError(f"robot map not found: {key}")
        robot = load_robot_map(key)
        return BodySpec(robot.name, robot)
    raise GestureSimError(f"unknown body {key!r}; choose one of {', '.join(BODIES)} "
                          "or give a robot map file (.json)")
