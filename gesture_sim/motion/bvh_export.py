"""BVH export of the simulated humanoid's motion, for Blender, game engines and other BVH tools.

The skeleton is the MuJoCo humanoid's body tree (``assets/mjcf/humanoid.xml``): one BVH joint
per body that rotates (the free root and every body with hinge joints), named as motion-capture
tools name them (:data:`BVH_NAMES`: ``Hips``, ``Spine``, ``LeftArm``, ``LeftForeArm``, ...;
a body missing from the table keeps its MuJoCo name). The face's slide joints (brows, eyelids)
have no BVH equivalent and are left out; the jaw is kept.

Conventions (the usual BVH ones, so that importers need no settings beyond the scale):

* Axes: **Y up, the character facing +Z, its left towards +X** (right-handed). MuJoCo's world
  is z up, facing +x, left +y, so a MuJoCo vector (x, y, z) is written as (y, z, x)
  (:data:`MJ_TO_BVH`, a pure relabelling of the axes: no mirror).
* Lengths in **centimetres** by default (``unit="m"`` for metres). Offsets are the bodies'
  positions in their parent at qpos = 0, when the humanoid stands upright with its arms down;
  that is the BVH rest pose (every rotation zero).
* The root (``Hips``, the pelvis) has six channels: ``Xposition Yposition Zposition`` (world
  position of the pelvis origin) and ``Zrotation Xrotation Yrotation`` (its world orientation).
* Every other joint has three rotation channels, in degrees, intrinsic in the order listed (the
  BVH convention). The order follows the body's MuJoCo hinges: MuJoCo composes a body's hinges
  in XML order, and each hinge axis here is a coordinate axis, so each channel *is* one hinge
  (value = ±angle, the sign from the axis direction), followed by the unused axes at 0. For
  example the left shoulder (flex about -y, abduct about +x, twist about +z in MuJoCo) is
  ``Xrotation Zrotation Yrotation`` = (-flex, abduct, twist). A body whose hinges are not along
  coordinate axes (none in the shipped humanoid) gets ``Zrotation Xrotation Yrotation`` Euler
  angles of its composed rotation instead.
* Frames at the given rate (30 fps from ``render --bvh``); the hinge channels are the hinge
  angles themselves, and the decomposed ones (the root's) take, each frame, the Euler triple
  nearest to the previous frame's (:func:`gesture_sim.motion.euler.continuous_euler`), so
  curves have no ±180° jumps, at gimbal lock included.

:func:`write_bvh` writes a file; :func:`bvh_skeleton` and :func:`channel_values` give the
layout and the numbers for other uses. The project's reader (:func:`gesture_sim.motion.bvh.
read_bvh`) reads the files back, and its importer retargets them (the ``gesture_sim`` joint
map of :data:`gesture_sim.motion.retarget.FAMILIES`: ``library build`` takes them).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_write_text
from gesture_sim.motion.euler import continuous_euler

#: MuJoCo world/body axes -> BVH axes: ``v_bvh = MJ_TO_BVH @ v_mujoco`` (x->Z, y->X, z->Y).
MJ_TO_BVH = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

#: BVH joint names of the humanoid's bodies (the common Mixamo-style names).
BVH_NAMES: dict[str, str] = {
    "pelvis": "Hips", "abdomen": "Spine", "chest": "Spine1", "neck": "Neck", "head": "Head",
    "jaw": "Jaw",
    **{f"{side}_{body}": f"{side.capitalize()}{name}" for side in ("left", "right")
       for body, name in (("clavicle", "Shoulder"), ("upper_arm", "Arm"),
                          ("forearm", "ForeArm"), ("hand", "Hand"), ("thigh", "UpLeg"),
                          ("shin", "Leg"), ("foot", "Foot"), ("toes", "ToeBase"))},
}

#: Metres per file unit.
UNITS = {"cm": 0.01, "m": 1.0}
#: Euler order of the root and of bodies whose hinges are not along coordinate axes.
EULER_ORDER = "ZXY"
_ROOT_POSITION = ("Xposition", "Yposition", "Zposition")


@dataclass(frozen=True)
class BvhJoint:
    """One joint of the exported skeleton.

    Attributes:
        name: BVH joint name.
        body: MuJoCo body name; ``body_id`` its id.
        parent: index of the parent joint in the skeleton list (-1 for the root).
        offset: (3,) position in the parent joint's frame at rest, BVH axes, metres.
        channels: the channel names, in file order.
        hinges: for each rotation channel, ``(qpos address, sign)`` of the hinge it equals, or
            ``(-1, 0.0)`` for an unused axis; empty when the rotation is decomposed instead.
        end_site: (3,) End Site offset (BVH axes, metres) for a leaf joint, else ``None``.
    """

    name: str
    body: str
    body_id: int
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    hinges: tuple[tuple[int, float], ...]
    end_site: np.ndarray | None


def _name(model: mujoco.MjModel, kind: mujoco.mjtObj, index: int) -> str:
    return mujoco.mj_id2name(model, kind, index) or f"{kind.name.lower()}{index}"


def _root_body(model: mujoco.MjModel) -> int:
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise GestureSimError(f"BVH export needs exactly one free (root) joint, found {len(free)}")
    return int(model.jnt_bodyid[free[0]])


def _exported(model: mujoco.MjModel, body: int) -> bool:
    """A body is exported unless all of its joints are slides (the face's brows and lids)."""
    start = model.body_jntadr[body]
    types = model.jnt_type[start:start + model.body_jntnum[body]]
    return not (len(types) and np.all(types == mujoco.mjtJoint.mjJNT_SLIDE))


def _direct_channels(model: mujoco.MjModel, body: int) -> tuple[tuple[str, ...], tuple] | None:
    """Channels equal to the body's hinges, or ``None`` when it needs Euler decomposition."""
    if not np.allclose(model.body_quat[body], (1.0, 0.0, 0.0, 0.0)):
        return None
    start, count = int(model.body_jntadr[body]), int(model.body_jntnum[body])
    axes: list[str] = []
    hinges: list[tuple[int, float]] = []
    for j in range(start, start + count):
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            return None
        axis = MJ_TO_BVH @ model.jnt_axis[j]
        k = int(np.argmax(np.abs(axis)))
        if not np.isclose(abs(axis[k]), 1.0, atol=1e-9) or "XYZ"[k] in axes:
            return None
        axes.append("XYZ"[k])
        hinges.append((int(model.jnt_qposadr[j]), float(np.sign(axis[k]))))
    for k in EULER_ORDER:
        if k not in axes:
            axes.append(k)
            hinges.append((-1, 0.0))
    return tuple(f"{k}rotation" for k in axes), tuple(hinges)


def _end_site(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The body's farthest site or geom centre from its origin (BVH axes, m)."""
    points = [model.site_pos[s] for s in range(model.nsite) if model.site_bodyid[s] == body]
    points += [model.geom_pos[g] for g in range(model.ngeom) if model.geom_bodyid[g] == body]
    points = [p for p in points if np.linalg.norm(p) > 1e-6]
    if not points:
        return MJ_TO_BVH @ np.array([0.0, 0.0, 0.05])
    return MJ_TO_BVH @ max(points, key=lambda p: float(np.linalg.norm(p)))


def bvh_skeleton(model: mujoco.MjModel) -> list[BvhJoint]:
    """The exported joints, parents before children (depth-first, in XML order)."""
    root = _root_body(model)
    children: dict[int, list[int]] = {}
    for b in range(model.nbody):
        if b != root and model.body_parentid[b] != b:
            children.setdefault(int(model.body_parentid[b]), []).append(b)
    joints: list[BvhJoint] = []

    def visit(body: int, parent: int) -> None:
        kids = [c for c in children.get(body, []) if _exported(model, c)]
        name = _name(model, mujoco.mjtObj.mjOBJ_BODY, body)
        if body == root:
            channels = (*_ROOT_POSITION, *(f"{k}rotation" for k in EULER_ORDER))
            hinges: tuple = ()
            offset = np.zeros(3)
        else:
            direct = _direct_channels(model, body)
            if direct is None:
                channels, hinges = tuple(f"{k}rotation" for k in EULER_ORDER), ()
            else:
                channels, hinges = direct
            offset = MJ_TO_BVH @ model.body_pos[body]
        index = len(joints)
        joints.append(BvhJoint(BVH_NAMES.get(name, name), name, body, parent, offset, channels,
                               hinges, None if kids else _end_site(model, body)))
        for c in kids:
            visit(c, index)

    visit(root, -1)
    return joints


def _local_rotations(model: mujoco.MjModel, qpos: np.ndarray, bodies: list[int]) -> dict:
    """Per body, (F, 3, 3) rotations relative to the parent body (MuJoCo axes)."""
    data = mujoco.MjData(model)
    out = {b: np.empty((len(qpos), 3, 3)) for b in bodies}
    for f, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for b in bodies:
            parent = model.body_parentid[b]
            out[b][f] = data.xmat[parent].reshape(3, 3).T @ data.xmat[b].reshape(3, 3)
    return out


def _euler(rotations_mj: np.ndarray) -> np.ndarray:
    """(F, 3) intrinsic ``EULER_ORDER`` angles (deg) of (F, 3, 3) MuJoCo rotations, continuous
    over time (:func:`~gesture_sim.motion.euler.continuous_euler`)."""
    return continuous_euler(MJ_TO_BVH @ rotations_mj @ MJ_TO_BVH.T, EULER_ORDER)


def channel_values(
    model: mujoco.MjModel, qpos: np.ndarray, skeleton: list[BvhJoint] | None = None,
    unit: str = "cm",
) -> np.ndarray:
    """The MOTION block: (F, C) channel values (file units, degrees) of qpos frames (F, nq)."""
    qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(qpos) == 0:
        raise GestureSimError(f"expected qpos frames (F, {model.nq}), got {qpos.shape}")
    if unit not in UNITS:
        raise GestureSimError(f"unknown BVH unit {unit!r} (expected one of {sorted(UNITS)})")
    skeleton = skeleton if skeleton is not None else bvh_skeleton(model)
    decomposed = [j.body_id for j in skeleton if j.parent >= 0 and not j.hinges]
    local = _local_rotations(model, qpos, decomposed) if decomposed else {}
    columns: list[np.ndarray] = []
    for joint in skeleton:
        if joint.parent < 0:
            adr = int(model.jnt_qposadr[model.body_jntadr[joint.body_id]])
            columns.append((qpos[:, adr:adr + 3] @ MJ_TO_BVH.T) / UNITS[unit])
            wxyz = qpos[:, adr + 3:adr + 7]
            world = Rotation.from_quat(wxyz[:, [1, 2, 3, 0]]).as_matrix()
            columns.append(_euler(world))
        elif joint.hinges:
            for adr, sign in joint.hinges:
                columns.append((np.degrees(sign * qpos[:, adr]) if adr >= 0
                                else np.zeros(len(qpos)))[:, None])
        else:
            columns.append(_euler(local[joint.body_id]))
    return np.concatenate(columns, axis=1)


def bvh_text(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float = 30.0, unit: str = "cm",
) -> str:
    """The BVH file for qpos frames (F, nq) sampled at ``fps`` (Hz); see the module docstring."""
    if not fps > 0:
        raise GestureSimError(f"BVH frame rate must be positive, got {fps}")
    skeleton = bvh_skeleton(model)
    values = channel_values(model, qpos, skeleton, unit)
    scale = 1.0 / UNITS[unit]
    lines = ["HIERARCHY"]
    depth_of: list[int] = []
    open_depths: list[int] = []

    def close_to(depth: int) -> None:
        while open_depths and open_depths[-1] >= depth:
            d = open_depths.pop()
            lines.append("  " * d + "}")

    for joint in skeleton:
        depth = 0 if joint.parent < 0 else depth_of[joint.parent] + 1
        depth_of.append(depth)
        close_to(depth)
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {joint.name}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {_fmt_vec(joint.offset * scale)}")
        lines.append(f"{pad}  CHANNELS {len(joint.channels)} {' '.join(joint.channels)}")
        if joint.end_site is not None:
            lines += [f"{pad}  End Site", f"{pad}  {{",
                      f"{pad}    OFFSET {_fmt_vec(joint.end_site * scale)}", f"{pad}  }}"]
        open_depths.append(depth)
    close_to(0)
    lines += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {1.0 / fps:.7f}"]
    body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in values)
    return "\n".join(lines) + "\n" + body + "\n"


def _fmt_vec(v: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in v)


def write_bvh(
    path: str | os.PathLike[str], model: mujoco.MjModel, qpos: np.ndarray, fps: float = 30.0,
    unit: str = "cm",
) -> Path:
    """Write qpos frames (F, nq) at ``fps`` (Hz) as a BVH file, atomically; returns the path."""
    text = bvh_text(model, qpos, fps, unit)
    atomic_write_text(path, text)
    return Path(path)
