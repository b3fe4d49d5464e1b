"""Scenes of several humanoids in one MuJoCo model, simulated together (a conversation).

:func:`conversation_model` compiles ``conversation.xml`` (floor, lights, cameras) with two copies
of ``humanoid.xml`` attached under the name prefixes :data:`PERSON_PREFIXES` (``"a/"``,
``"b/"``): person 0 stands at the origin facing +x, person 1 at ``distance`` metres along +x
facing it (yaw 180°). Each keeps its own free root, PD tracking and balance controller (a
:class:`~gesture_sim.sim.tracking.HumanoidSim` bound to its prefix on the shared ``MjData``);
nothing holds or pushes either body. :class:`SceneSim` steps them together through one
:class:`~gesture_sim.sim.world.PhysicsLoop`: every control update sets each body's actuators,
then one ``mj_step`` advances the whole scene, so contacts between them (if they ever touched)
would be real.

Cameras: ``both`` (from the side, framing the two people), ``person_0`` / ``person_1`` (a
three-quarter view of each person from beside the other), ``face_0`` / ``face_1`` (close-ups).

Each body's :class:`~gesture_sim.sim.trace.SimTrace` has the single-person layout (its own root
and joints), so every metric and exporter works per person; :func:`scene_qpos` puts the bodies'
recorded poses back together for the renderer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from gesture_sim import MJCF_DIR
from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim import looks
from gesture_sim.sim.trace import SimTrace
from gesture_sim.sim.world import PhysicsLoop, Sample

CONVERSATION_XML = MJCF_DIR / "conversation.xml"
#: Name prefixes of the people in a conversation scene (person 0, person 1).
PERSON_PREFIXES: tuple[str, ...] = ("a/", "b/")
#: Default distance between the two pelvis origins (m): a personal-zone conversation (Hall's
#: 0.45-1.2 m personal distance between the bodies' fronts, about 1.4 m between their centres).
DEFAULT_DISTANCE = 1.4

#: Each person's clothes and hair (material rgba), so that the two can be told apart.
_LOOKS: tuple[dict[str, list[float]], ...] = (
    {},
    {"shirt": [0.62, 0.30, 0.24, 1.0], "trousers": [0.30, 0.27, 0.22, 1.0],
     "hair": [0.12, 0.10, 0.09, 1.0]},
)

def conversation_model(distance: float = DEFAULT_DISTANCE,
                       look: str = looks.DEFAULT_LOOK) -> mujoco.MjModel:
    """Compile the two-person scene (see the module docstring); ``distance`` in metres;
    ``look`` (:data:`gesture_sim.sim.looks.LOOKS`) dresses both people (no physics changes)."""
    looks.check_look(look)
    if not (math.isfinite(distance) and 0.8 <= distance <= 4.0):
        raise GestureSimError(f"distance must be in [0.8, 4.0] m, got {distance}")
    for path in (CONVERSATION_XML, hm.HUMANOID_XML):
        if not path.is_file():
            raise GestureSimError(f"scene file not found: {path}")
    try:
        spec = mujoco.MjSpec.from_file(str(CONVERSATION_XML))
        for k, prefix in enumerate(PERSON_PREFIXES):
            yaw = math.pi * k
            frame = spec.worldbody.add_frame(
                pos=[distance * k, 0.0, 0.0], quat=[math.cos(yaw / 2), 0.0, 0.0,
                                                   math.sin(yaw / 2)])
            child = looks.apply_look(mujoco.MjSpec.from_file(str(hm.HUMANOID_XML)), look,
                                     person=k)
            for name, rgba in _LOOKS[k].items():
                child.material(name).rgba = rgba
            spec.attach(child, frame=frame, prefix=prefix)
        _add_cameras(spec, distance)
        return spec.compile()
    except ValueError as exc:
        raise GestureSimError(f"cannot compile the conversation scene: {exc}") from exc


def _look(pos: np.ndarray, target: np.ndarray) -> list[float]:
    """MuJoCo ``xyaxes`` of a camera at ``pos`` looking at ``target`` with z up."""
    fwd = np.asarray(target, float) - np.asarray(pos, float)
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    return [*x.tolist(), *y.tolist()]


def _add_cameras(spec: mujoco.MjSpec, distance: float) -> None:
    mid = 0.5 * distance
    cams = {"both": ([mid, -2.9, 1.35], [mid, 0.0, 1.0], 42.0)}
    for k in range(2):
        x = distance * k
        toward = 1.0 if k == 0 else -1.0            # the direction person k faces (+x / -x)
        cams[f"person_{k}"] = ([x + toward * 2.0, -toward * 2.0, 1.45], [x, 0.0, 1.1], 40.0)
        cams[f"face_{k}"] = ([x + toward * 0.9, 0.0, 1.62], [x, 0.0, 1.60], 25.0)
    for name, (pos, target, fovy) in cams.items():
        cam = spec.worldbody.add_camera(name=name, pos=pos, fovy=fovy)
        cam.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
        cam.alt.xyaxes = _look(np.asarray(pos), np.asarray(target))


class SceneSim:
    """Several humanoids of one compiled scene, PD-tracked and balanced, stepped together.

    Args:
        model: a compiled scene (default :func:`conversation_model`).
        prefixes: the humanoids' name prefixes (default :data:`PERSON_PREFIXES`).
        seeds: one seed per body (initial-state noise), default 0, 1, ...
        **kwargs: passed to every :class:`~gesture_sim.sim.tracking.HumanoidSim`.
    """

    def __init__(self, model: mujoco.MjModel | None = None,
                 prefixes: Sequence[str] = PERSON_PREFIXES, seeds: Sequence[int] | None = None,
                 **kwargs) -> None:
        from gesture_sim.sim.tracking import HumanoidSim

        self.model = conversation_model() if model is None else model
        self.data = mujoco.MjData(self.model)
        seeds = list(range(len(prefixes))) if seeds is None else list(seeds)
        if len(seeds) != len(prefixes):
            raise GestureSimError("give one seed per body")
        self.bodies = [HumanoidSim(self.model, seed=s, prefix=p, data=self.data, **kwargs)
                       for p, s in zip(prefixes, seeds, strict=True)]
        ce = {b.control_every for b in self.bodies}
        re = {b.record_every for b in self.bodies}
        if len(ce) != 1 or len(re) != 1:
            raise GestureSimError("every body of a scene needs the same control/record rates")
        self.control_every, self.record_every = ce.pop(), re.pop()
        self._loop = PhysicsLoop(self.model, self.data, self.bodies, self.control_every,
                                 self.record_every)

    @property
    def loop(self) -> PhysicsLoop:
        """The :class:`~gesture_sim.sim.world.PhysicsLoop` that steps the scene."""
        return self._loop

    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    def reset(self, poses: Sequence[np.ndarray | None] | None = None, settle: float = 0.6
              ) -> None:
        """Stand every body up (``poses[k]``: (n_act,) or None for standing) and let them
        settle together for ``settle`` s; time restarts at 0."""
        m, d = self.model, self.data
        poses = [None] * len(self.bodies) if poses is None else list(poses)
        self._loop.flush()                  # deferred physics first (world.PhysicsLoop.defer_s)
        mujoco.mj_resetData(m, d)
        q0 = [b.place(q) for b, q in zip(self.bodies, poses, strict=True)]
        mujoco.mj_forward(m, d)
        self._loop.settle(q0, settle)

    def begin_trace(self, record: bool = True, expected_s: float = 60.0) -> None:
        """Start a streamed run at the current state (see :meth:`advance_to`)."""
        for b in self.bodies:
            b.begin_trace(record=record, expected_s=expected_s)
        self._loop.begin(record)

    def advance_to(self, t_end: float, samples: Sequence[Sample]) -> None:
        """Step the scene until stream time ``t_end`` (s); body k tracks ``samples[k](t) ->
        (q, qd)`` (each (n_act,)), re-sampled at the control rate."""
        self._loop.run_until(t_end, samples)

    def traces(self) -> list[SimTrace]:
        """Each body's :class:`SimTrace` of the streamed run (single-person layout)."""
        self._loop.flush()
        return [b.trace() for b in self.bodies]


def scene_qpos(model: mujoco.MjModel, traces: Sequence[SimTrace],
               prefixes: Sequence[str] = PERSON_PREFIXES) -> np.ndarray:
    """The scene's qpos rows (T, model.nq) from the bodies' traces (each (T, 7 + n_act)),
    cut to the shortest trace."""
    n = min(len(tr.qpos) for tr in traces)
    out = np.tile(model.qpos0, (n, 1))
    for tr, prefix in zip(traces, prefixes, strict=True):
        adr = int(model.jnt_qposadr[model.joint(prefix + "root").id])
        out[:, adr: adr + tr.qpos.shape[1]] = tr.qpos[:n]
    return out
