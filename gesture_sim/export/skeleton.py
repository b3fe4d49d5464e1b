"""The simulated humanoid's motion on a skeleton the user gives (``render --to-skeleton``).

Only the user's BVH *hierarchy* matters (its MOTION is ignored): joint names, parents, offsets,
End Sites and each joint's channels. The output is a BVH with exactly that hierarchy (the same
joints in the same order, the same offsets, the same channels in the same order) and the
simulated motion.

How the skeleton is understood:

* **Joint map.** The importer's joint maps (:data:`gesture_sim.motion.retarget.FAMILIES`,
  detected with :func:`~gesture_sim.motion.retarget.detect_family`): pelvis, spine, neck, head,
  shoulders, elbows, wrists, hand ends, hips, knees, ankles, toes. A skeleton no map fits as a
  whole is still taken when one map finds its trunk and both arms (an upper-body skeleton: the
  legs and hand ends then stay at rest); otherwise one :class:`GestureSimError` line names what
  is missing.
* **Axes and units.** The units are detected from the skeleton's size (as the reader does); the
  up axis is the coordinate axis nearest to pelvis -> neck at rest, the left axis the one
  nearest to right -> left shoulder (Y up / X left for most files; Z-up files and the Bandai
  skeleton, whose zero-rotation pose lies along +X, work the same way).
* **Rest pose.** The file's offsets at zero rotation, whatever it is (T-pose, A-pose, arms
  down): every mapped bone's rest direction is measured from the offsets and calibrated onto the
  humanoid's rest pose by :class:`gesture_sim.export.PoseTransfer`, as the Mixamo export does
  for its T-pose. :attr:`UserSkeleton.arm_angle_deg` reports the arms' rest angle below the
  horizontal (about 0 for a T-pose, 30-50 for an A-pose).

The mapping (table built by :func:`skeleton_follow`): every bone on a mapped chain (pelvis ->
neck, neck -> head, the collar bones, shoulder -> elbow -> wrist -> hand end, hip -> knee ->
ankle -> toe) points exactly where the humanoid's corresponding bone points; joints between two
mapped points (extra spine joints, twist bones on the arm, CMU's ``LHipJoint``, ``Neck1``) are
laid along the humanoid's bone at the user's length fractions (the spine on the humanoid's
pelvis -> abdomen -> chest -> neck polyline), so the spine's bend is shared by the user's spine
joints that span one of the humanoid's (a user bone lying within one humanoid segment stays
straight). Finger joints named thumb, index, middle, ring or pinky/little follow the
humanoid's finger bodies (:func:`_lay_fingers`); other joints off the chains (side twist bones,
face) keep their rest rotation relative to their parent. The root translation is the
humanoid's pelvis scaled by the leg-length ratio (trunk-length ratio for a skeleton without
legs), placed so that the user's pelvis joint lands there (a root above the pelvis, as Bandai's
``joint_Root``, included). The root's position channels hold its position (the project's reader,
like most, lets them replace the root's OFFSET); other joints' position channels hold their
OFFSET.

What is approximate: bone lengths are the user's (positions match up to proportions); a bone of
zero length cannot be aimed and takes its driving body's whole orientation; roll (twist) follows
the humanoid's body; a joint with fewer than three rotation channels gets the nearest rotation
it can express (Euler angles of the missing axes dropped).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.export import (
    Follow,
    PoseTransfer,
    TargetSkeleton,
    bvh_hierarchy,
    forward_positions,
)
from gesture_sim.fileio import atomic_write_text

#: The canonical points the motion needs on any skeleton: trunk and both arms.
REQUIRED = ("pelvis", "neck", "head", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder",
            "r_elbow", "r_wrist")
#: Canonical point -> the humanoid point it corresponds to.
_HUMANOID = {"pelvis": "body:pelvis", "neck": "body:neck", "head": "body:head"}
for _s, _side in (("l", "left"), ("r", "right")):
    _HUMANOID |= {f"{_s}_shoulder": f"site:{_side}_shoulder_site",
                  f"{_s}_elbow": f"site:{_side}_elbow_site",
                  f"{_s}_wrist": f"site:{_side}_wrist_site",
                  f"{_s}_hand_end": f"site:{_side}_hand_site",
                  f"{_s}_hip": f"body:{_side}_thigh", f"{_s}_knee": f"body:{_side}_shin",
                  f"{_s}_ankle": f"body:{_side}_foot", f"{_s}_toe": f"body:{_side}_toes"}
#: The humanoid's spine polyline and the bodies of its segments.
_SPINE = ("body:pelvis", "body:abdomen", "body:chest", "body:neck")
_SPINE_BODIES = ("pelvis", "abdomen", "chest")
_PARTS = {"the trunk (pelvis, neck, head)": ("pelvis", "neck", "head"),
          "the left arm": ("l_shoulder", "l_elbow", "l_wrist"),
          "the right arm": ("r_shoulder", "r_elbow", "r_wrist")}


@dataclass(frozen=True)
class UserSkeleton:
    """A user's BVH hierarchy and how it maps onto the humanoid.

    Attributes:
        path: the file it was read from.
        names: joint names in file order, End Sites included (``PARENT_End``, as the reader
            names them).
        parents: (J,) parent index, -1 for the root.
        offsets: (J, 3) offsets as in the file (file units and axes).
        channels: each joint's channel names, in the file's order (empty for End Sites).
        end_site: (J,) whether the joint is an End Site.
        unit_scale: metres per file unit.
        axes: (3, 3) the file's left, up and forward axes as columns (``v_file = axes @ v``,
            ``v`` in the exporters' X left, Y up, Z forward).
        family: the importer's joint map used.
        points: canonical point -> joint index (those the skeleton has).
        arm_angle_deg: the upper arms' rest angle below the horizontal (T-pose ~0).
    """

    path: Path
    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_site: np.ndarray
    unit_scale: float
    axes: np.ndarray
    family: str
    points: dict[str, int]
    arm_angle_deg: float

    @property
    def rest_pose(self) -> str:
        """``"T-pose"``, ``"A-pose"`` or ``"arms down"`` from :attr:`arm_angle_deg`."""
        a = self.arm_angle_deg
        return "T-pose" if a < 15 else "A-pose" if a < 65 else "arms down"

    def target(self) -> TargetSkeleton:
        """The skeleton in the exporters' axes (X left, Y up, Z forward), metres."""
        p = self.points
        return TargetSkeleton(
            names=self.names, parents=self.parents,
            offsets=self.offsets * self.unit_scale @ self.axes,
            frame_joints=tuple(self.names[p[k]] for k in ("pelvis", "neck", "l_shoulder",
                                                           "r_shoulder")))


def _strip(name: str) -> str:
    return name.rsplit(":", 1)[-1]


def _hierarchy(path: Path):
    from gesture_sim.motion.bvh import _parse_hierarchy, _Tokens

    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise GestureSimError(f"cannot read BVH skeleton {path}: {exc.strerror}") from exc
    lines = text.splitlines()
    end = next((i for i, ln in enumerate(lines) if ln.strip() == "MOTION"), len(lines))
    if not any(ln.strip() == "HIERARCHY" for ln in lines[:end]):
        raise GestureSimError(f"malformed BVH {path}: no HIERARCHY section")
    return _parse_hierarchy(_Tokens(lines[:end], str(path)))


def _ancestor(parents: np.ndarray, joints: list[int]) -> int:
    """The lowest common ancestor of ``joints``."""
    chains = []
    for j in joints:
        chain = []
        while j >= 0:
            chain.append(j)
            j = int(parents[j])
        chains.append(chain[::-1])
    common = chains[0][0]
    for k in range(min(map(len, chains))):
        if len({c[k] for c in chains}) != 1:
            break
        common = chains[0][k]
    return common


def _map_points(names: tuple[str, ...], parents: np.ndarray, path: Path
                ) -> tuple[str, dict[str, int]]:
    """The importer's joint map that fits (whole, else trunk and arms) and its points."""
    from gesture_sim.motion.retarget import FAMILIES, detect_family

    index = {}
    for i, n in enumerate(names):
        index.setdefault(_strip(n), i)
    try:
        families = [detect_family(names)]
    except GestureSimError:
        families = list(FAMILIES)
    best: tuple[int, str, list[str]] | None = None
    for family in families:
        pts, missing = {}, []
        for key, value in FAMILIES[family]["points"].items():
            js = value if isinstance(value, tuple) else (value,)
            if all(_strip(j) in index for j in js):
                ids = [index[_strip(j)] for j in js]
                pts[key] = ids[0] if len(ids) == 1 else _ancestor(parents, ids)
            elif key in REQUIRED:
                missing.append(key)
        if not missing:
            return family, pts
        if best is None or len(missing) < best[0]:
            best = (len(missing), family, missing)
    assert best is not None
    _, family, missing = best
    parts = [part for part, keys in _PARTS.items() if set(keys) & set(missing)]
    want = [FAMILIES[family]["points"][k] for k in missing]
    raise GestureSimError(
        f"{path}: this skeleton cannot take the motion: no joint map finds {' and '.join(parts)} "
        f"(the closest map, {family}, lacks joints {', '.join(map(str, want))}); known maps: "
        f"{', '.join(FAMILIES)}")


def _snap(v: np.ndarray, exclude: int | None = None) -> np.ndarray:
    """The signed coordinate axis nearest to ``v`` (not axis ``exclude``)."""
    a = np.abs(v).astype(float)
    if exclude is not None:
        a[exclude] = -1.0
    k = int(np.argmax(a))
    out = np.zeros(3)
    out[k] = np.sign(v[k]) or 1.0
    return out


def read_skeleton(path: str | os.PathLike[str]) -> UserSkeleton:
    """Read a user's BVH skeleton (hierarchy only) and map it (see the module docstring).

    Raises:
        GestureSimError: unreadable or malformed file, or a skeleton without trunk or arms.
    """
    from gesture_sim.motion.bvh import detect_unit_scale
    from gesture_sim.motion.skeleton import forward_kinematics

    path = Path(path)
    joints = _hierarchy(path)
    names = tuple(j.name for j in joints)
    parents = np.array([j.parent for j in joints], dtype=int)
    offsets = np.stack([j.offset for j in joints]).astype(float)
    has_child = np.zeros(len(joints), dtype=bool)
    has_child[parents[parents >= 0]] = True
    end_site = np.array([not j.channels and j.parent >= 0 and not has_child[i]
                         and j.name == joints[j.parent].name + "_End"
                         for i, j in enumerate(joints)])
    n = len(joints)
    rest, _ = forward_kinematics(parents, offsets[None], np.broadcast_to(np.eye(3), (1, n, 3, 3)))
    rest = rest[0]
    unit = detect_unit_scale(rest)
    family, pts = _map_points(names, parents, path)
    up = _snap(rest[pts["neck"]] - rest[pts["pelvis"]])
    left = _snap(rest[pts["l_shoulder"]] - rest[pts["r_shoulder"]], exclude=int(np.argmax(
        np.abs(up))))
    axes = np.stack([left, up, np.cross(left, up)], axis=-1)
    angles = []
    for s in "lr":
        arm = (rest[pts[f"{s}_elbow"]] - rest[pts[f"{s}_shoulder"]]) @ axes
        angles.append(np.degrees(np.arctan2(-arm[1], np.hypot(arm[0], arm[2]))))
    return UserSkeleton(
        path=path, names=names, parents=parents, offsets=offsets,
        channels=tuple(tuple(j.channels) for j in joints), end_site=end_site,
        unit_scale=float(unit), axes=axes, family=family, points=pts,
        arm_angle_deg=float(np.mean(angles)))


def _path(parents: np.ndarray, a: int, b: int) -> list[int] | None:
    """Joints a, ..., b down the tree, or ``None`` when a is not an ancestor of b."""
    out = [b]
    while out[-1] != a:
        p = int(parents[out[-1]])
        if p < 0:
            return None
        out.append(p)
    return out[::-1]


def _humanoid_spine_fractions(model: mujoco.MjModel) -> np.ndarray:
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    pts = np.array([data.body(p.split(":")[1]).xpos for p in _SPINE])
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    return np.cumsum(seg) / seg.sum()


def skeleton_follow(skeleton: UserSkeleton, model: mujoco.MjModel) -> dict[str, Follow]:
    """User joint -> the humanoid body and point it follows (see the module docstring)."""
    names, parents, pts = skeleton.names, skeleton.parents, skeleton.points
    off = np.linalg.norm(skeleton.offsets, axis=1) * skeleton.unit_scale
    follow: dict[str, Follow] = {}

    std = skeleton.target().offsets

    def aim(j: int, nxt: int) -> str | None:
        return names[nxt] if off[nxt] > 1e-5 else None

    def pick(roll, nxt: int, other: str = "left"):
        """``roll``, unless the user's rest bone is nearly parallel to it: then the first of
        ``other``, "fwd", "left", "up" that neither rest bone is parallel to (``other``'s
        alternatives exclude the axis the humanoid's rest bone runs along: up for the limbs
        and spine, left for the collar bones, forward for the feet)."""
        if not isinstance(roll, str) or off[nxt] <= 1e-5:
            return roll
        bad = {"left": "up", "up": "left", "fwd": "up"}.get(other, "up")
        if roll == "up":
            bad = "fwd"
        d = np.abs(std[nxt]) / np.linalg.norm(std[nxt])
        for cand in (roll, other, "fwd", "left", "up"):
            if cand != bad and d[{"left": 0, "up": 1, "fwd": 2}[cand]] < 0.9:
                return cand
        return roll

    def fractions(chain: list[int]) -> np.ndarray:
        lengths = np.concatenate([[0.0], np.cumsum(off[chain[1:]])])
        return lengths / lengths[-1] if lengths[-1] > 0 else np.linspace(0, 1, len(chain))

    def lay(chain: list[int] | None, p_from: str, p_to: str, body: str, roll="fwd",
            skip_first: bool = False, other: str = "left") -> None:
        if chain is None or len(chain) < 2:
            return
        fr = fractions(chain)
        for i, j in enumerate(chain[:-1]):
            if i == 0 and skip_first:
                continue
            at = p_from if fr[i] == 0 else ("lerp", p_from, p_to, float(fr[i]))
            follow[names[j]] = Follow(body, at, aim(j, chain[i + 1]),
                                      pick(roll, chain[i + 1], other))

    # the trunk: pelvis -> neck on the humanoid's spine polyline, at the user's fractions
    trunk = _path(parents, pts["pelvis"], pts["neck"])
    if trunk is None:
        raise GestureSimError(f"{skeleton.path}: the neck ({names[pts['neck']]}) does not hang "
                              f"below the pelvis ({names[pts['pelvis']]})")
    hum = _humanoid_spine_fractions(model)
    fr = fractions(trunk)
    hips = ("l_hip" in pts and "r_hip" in pts)
    for i, j in enumerate(trunk[:-1]):
        body = _SPINE_BODIES[int(np.clip(np.searchsorted(hum, fr[i], side="right"), 0, 2))]
        roll = ((names[pts["l_hip"]], names[pts["r_hip"]]) if i == 0 and hips
                else pick("fwd", trunk[i + 1]))
        follow[names[j]] = Follow(body, ("chain", _SPINE, float(fr[i])) if i else "body:pelvis",
                                  aim(j, trunk[i + 1]), roll)
    follow[names[pts["neck"]]] = Follow("neck", "body:neck")
    lay(_path(parents, pts["neck"], pts["head"]), "body:neck", "body:head", "neck")
    follow[names[pts["head"]]] = Follow("head", "body:head")
    trunk_set = set(trunk)
    for s, side in (("l", "left"), ("r", "right")):
        # collar bones: from where the arm leaves the trunk to the shoulder
        sh = pts[f"{s}_shoulder"]
        branch = sh
        while branch not in trunk_set and parents[branch] >= 0:
            branch = int(parents[branch])
        collar = _path(parents, branch, sh)
        if collar is not None and len(collar) > 2:
            lay(collar[1:], f"body:{side}_clavicle", _HUMANOID[f"{s}_shoulder"],
                f"{side}_clavicle", other="up")
        for a, b, body, roll in (("shoulder", "elbow", "upper_arm", "fwd"),
                                 ("elbow", "wrist", "forearm", "fwd"),
                                 ("wrist", "hand_end", "hand", "fwd"),
                                 ("hip", "knee", "thigh", "fwd"),
                                 ("knee", "ankle", "shin", "fwd"),
                                 ("ankle", "toe", "foot", "up")):
            ka, kb = f"{s}_{a}", f"{s}_{b}"
            if ka in pts and kb in pts:
                lay(_path(parents, pts[ka], pts[kb]), _HUMANOID[ka], _HUMANOID[kb],
                    f"{side}_{body}", roll)
        if f"{s}_hand_end" in pts and f"{s}_wrist" in pts and _path(
                parents, pts[f"{s}_wrist"], pts[f"{s}_hand_end"]):
            follow[names[pts[f"{s}_hand_end"]]] = Follow(None, _HUMANOID[f"{s}_hand_end"])
        elif f"{s}_wrist" in pts:
            follow[names[pts[f"{s}_wrist"]]] = Follow(f"{side}_hand", _HUMANOID[f"{s}_wrist"])
        if f"{s}_wrist" in pts:
            _lay_fingers(follow, names, parents, pts[f"{s}_wrist"], side, off,
                         pts.get(f"{s}_hand_end"))
        if f"{s}_toe" in pts and f"{s}_ankle" in pts:
            follow[names[pts[f"{s}_toe"]]] = Follow(f"{side}_toes", _HUMANOID[f"{s}_toe"])
        if f"{s}_hip" in pts:   # between the pelvis and the hip (CMU's LHipJoint)
            hip = pts[f"{s}_hip"]
            lay(_path(parents, pts["pelvis"], hip), "body:pelvis", _HUMANOID[f"{s}_hip"],
                "pelvis", skip_first=True)
            if names[hip] not in follow:
                follow[names[hip]] = Follow(f"{side}_thigh", _HUMANOID[f"{s}_hip"])
    root = names[0]
    if root not in follow:      # a root above the pelvis (Bandai's joint_Root)
        follow[root] = Follow("pelvis", "body:pelvis")
    return follow


#: Finger names in user skeletons (lower case, in a joint's name) -> the humanoid's finger.
_FINGER_WORDS = (("thumb", "thumb"), ("index", "index"), ("middle", "middle"),
                 ("ring", "ring"), ("pinky", "little"), ("little", "little"))


def _lay_fingers(follow: dict[str, Follow], names: tuple[str, ...], parents: np.ndarray,
                 wrist: int, side: str, off: np.ndarray, hand_end: int | None) -> None:
    """The user's finger joints below ``wrist`` follow the humanoid's finger bodies, where
    their names say which finger they are (thumb, index, middle, ring, pinky/little): a
    finger's first three joints from the hand (a metacarpal joint numbered 0 is skipped) as
    :func:`gesture_sim.export.finger_follows` lays SMPL-X's and the Mixamo rig's. The joint
    the wrist aims at (``hand_end``) stays rigid with the hand."""
    from gesture_sim.export import FINGER_SEGMENTS

    below = [j for j in range(len(names)) if j != wrist and _path(parents, wrist, j)]
    for word, finger in _FINGER_WORDS:
        chain = [j for j in below if word in _strip(names[j]).lower()
                 and not _strip(names[j]).lower().endswith(("end", "nub", "site"))]
        chain.sort(key=lambda j: len(_path(parents, wrist, j)))
        if chain and _strip(names[chain[0]]).endswith("0") and len(chain) > 3:
            chain = chain[1:]
        chain = chain[:3]
        if len(chain) < 2 or any(parents[b] != a for a, b in zip(chain, chain[1:], strict=False)):
            continue
        bodies = [f"{side}_{finger}_{seg}" for seg in FINGER_SEGMENTS[finger]]
        for i, j in enumerate(chain):
            nxt = chain[i + 1] if i + 1 < len(chain) else None
            if j == hand_end:
                continue                        # the wrist's aim: rigid with the hand
            if nxt is not None and i < 2 and off[nxt] > 1e-5:
                follow[names[j]] = Follow(bodies[i], f"body:{bodies[i]}", aim=names[nxt])
            else:
                follow[names[j]] = Follow(None, f"body:{bodies[i]}")


def _scale(skeleton: UserSkeleton, model: mujoco.MjModel) -> float:
    """User / humanoid leg length (trunk length without legs): the root translation scale."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    target = skeleton.target()
    rest = target.rest_positions()
    pts = skeleton.points
    if all(f"l_{k}" in pts for k in ("hip", "knee", "ankle")):
        keys, bodies = ("l_hip", "l_knee", "l_ankle"), ("left_thigh", "left_shin", "left_foot")
    else:
        keys, bodies = ("pelvis", "neck"), ("pelvis", "neck")
    user = rest[[pts[k] for k in keys]]
    hum = np.array([data.body(b).xpos for b in bodies])
    return float(np.linalg.norm(np.diff(user, axis=0), axis=1).sum()
                 / np.linalg.norm(np.diff(hum, axis=0), axis=1).sum())


def skeleton_motion(skeleton: UserSkeleton, model: mujoco.MjModel, qpos: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations (F, J, 3, 3) in the file's axes and the root joint's position (F, 3) in
    file units, for qpos frames (F, nq)."""
    target = skeleton.target()
    transfer = PoseTransfer(model, target, skeleton_follow(skeleton, model))
    local, glob, point = transfer.pose(qpos)
    pelvis = skeleton.points["pelvis"]
    if pelvis != 0:     # place the root so that the pelvis joint lands on the humanoid's pelvis
        rel = forward_positions(target, glob, np.zeros((len(qpos), 3)))[:, pelvis]
    else:
        rel = 0.0
    root = point * _scale(skeleton, model) - rel
    a = skeleton.axes
    local = a @ local @ a.T
    return local, root @ a.T / skeleton.unit_scale


def _num(x: float) -> str:
    return np.format_float_positional(float(x), unique=True, trim="-")


def _euler(local: np.ndarray, axes: str) -> np.ndarray:
    """(F, len(axes)) intrinsic Euler angles (deg, unwrapped over time) in the order ``axes``;
    missing axes are completed for the decomposition and dropped."""
    order = axes + "".join(k for k in "XYZ" if k not in axes)
    ang = Rotation.from_matrix(local).as_euler(order.upper())
    return np.degrees(np.unwrap(ang, axis=0))[:, :len(axes)]


def skeleton_bvh_text(skeleton: UserSkeleton, model: mujoco.MjModel, qpos: np.ndarray,
                      fps: float = 30.0) -> str:
    """The BVH of qpos frames (F, nq) at ``fps`` (Hz) on the user's hierarchy."""
    if not (np.isfinite(fps) and fps > 0):
        raise GestureSimError(f"BVH frame rate must be positive, got {fps}")
    local, root = skeleton_motion(skeleton, model, qpos)
    n_f = len(local)
    columns: list[np.ndarray] = []
    for j, chans in enumerate(skeleton.channels):
        rot = "".join(c[0] for c in chans if c.endswith("rotation"))
        angles = _euler(local[:, j], rot) if rot else np.zeros((n_f, 0))
        k = 0
        for c in chans:
            if c.endswith("position"):
                axis = "XYZ".index(c[0])
                columns.append(root[:, axis] if j == 0 else
                               np.full(n_f, skeleton.offsets[j, axis]))
            else:
                columns.append(angles[:, k])
                k += 1
    def head(j: int) -> list[str]:
        name, end = skeleton.names[j], skeleton.end_site[j]
        out = ["ROOT " + name if skeleton.parents[j] < 0 else "End Site" if end else
               "JOINT " + name, f"OFFSET {' '.join(_num(x) for x in skeleton.offsets[j])}"]
        if not end:
            chans = skeleton.channels[j]
            out.append(f"CHANNELS {len(chans)}" + "".join(" " + c for c in chans))
        return out

    lines = bvh_hierarchy(skeleton.parents, head)
    lines += ["MOTION", f"Frames: {n_f}", f"Frame Time: {1.0 / fps:.7f}"]
    values = np.stack(columns, axis=1) if columns else np.zeros((n_f, 0))
    body = "\n".join(" ".join(f"{x:.6f}" for x in row) for row in values)
    return "\n".join(lines) + "\n" + body + "\n"


def write_skeleton(path: str | os.PathLike[str], skeleton: str | os.PathLike[str] | UserSkeleton,
                   model: mujoco.MjModel, qpos: np.ndarray, fps: float = 30.0) -> Path:
    """Write qpos frames (F, nq) at ``fps`` (Hz) as a BVH on ``skeleton``, atomically."""
    if not isinstance(skeleton, UserSkeleton):
        skeleton = read_skeleton(skeleton)
    atomic_write_text(path, skeleton_bvh_text(skeleton, model, qpos, fps))
    return Path(path)
