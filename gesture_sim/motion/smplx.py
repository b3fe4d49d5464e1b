"""Reader for SMPL-X parameter files as published by BEAT2 / AMASS (npz).

Keys used: ``poses`` (T, 165) axis-angle (rad) of the 55 SMPL-X joints, ``trans`` (T, 3) root
translation (m), ``mocap_frame_rate`` (or ``mocap_framerate``). The SMPL-X body model itself is
licence-gated, so the rest-pose joint offsets are not read from it: they are built from the
humanoid's own proportions (:func:`humanoid_rest_offsets`) or, without a model, from a generic
adult table (:data:`GENERIC_OFFSETS`). SMPL-X axes: Y up, the body faces +Z, its left is +X;
the rest pose is a T-pose.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.skeleton import SkeletonMotion, forward_kinematics

_BODY = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
    "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "jaw", "left_eye_smplhf", "right_eye_smplhf",
)
_FINGERS = ("index", "middle", "pinky", "ring", "thumb")
#: The 55 SMPL-X joints in their parameter order.
SMPLX_JOINTS: tuple[str, ...] = _BODY + tuple(
    f"{side}_{finger}{k}" for side in ("left", "right") for finger in _FINGERS for k in (1, 2, 3)
)


def _parents() -> np.ndarray:
    body = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15]
    hands = []
    for wrist in (20, 21):
        for _ in _FINGERS:
            base = len(body) + len(hands)
            hands += [wrist, base, base + 1]
    return np.array(body + hands, dtype=int)


#: Parent of each SMPL-X joint (-1 for the pelvis).
SMPLX_PARENTS: np.ndarray = _parents()

# Generic adult (about 1.75 m) rest offsets in SMPL-X axes (m), T-pose, straight spine.
_GENERIC_BODY = {
    "pelvis": (0.0, 0.0, 0.0),
    "left_hip": (0.09, -0.08, 0.0), "right_hip": (-0.09, -0.08, 0.0),
    "spine1": (0.0, 0.11, 0.0), "left_knee": (0.0, -0.42, 0.0), "right_knee": (0.0, -0.42, 0.0),
    "spine2": (0.0, 0.13, 0.0), "left_ankle": (0.0, -0.42, 0.0), "right_ankle": (0.0, -0.42, 0.0),
    "spine3": (0.0, 0.07, 0.0), "left_foot": (0.0, -0.06, 0.13), "right_foot": (0.0, -0.06, 0.13),
    "neck": (0.0, 0.20, 0.0), "left_collar": (0.03, 0.13, 0.0), "right_collar": (-0.03, 0.13, 0.0),
    "head": (0.0, 0.09, 0.02), "left_shoulder": (0.15, 0.03, 0.0),
    "right_shoulder": (-0.15, 0.03, 0.0), "left_elbow": (0.28, 0.0, 0.0),
    "right_elbow": (-0.28, 0.0, 0.0), "left_wrist": (0.25, 0.0, 0.0),
    "right_wrist": (-0.25, 0.0, 0.0), "jaw": (0.0, 0.0, 0.05),
    "left_eye_smplhf": (0.03, 0.05, 0.08), "right_eye_smplhf": (-0.03, 0.05, 0.08),
}


def _finger_offsets(body: dict[str, tuple[float, float, float]]) -> np.ndarray:
    out = np.zeros((55, 3))
    for i, name in enumerate(_BODY):
        out[i] = body[name]
    for i in range(len(_BODY), 55):
        side = 1.0 if SMPLX_JOINTS[i].startswith("left") else -1.0
        first = SMPLX_PARENTS[i] in (20, 21)
        out[i] = (side * (0.09 if first else 0.03), 0.0, 0.0)
    return out


#: Generic rest offsets (55, 3) in SMPL-X axes (m), used when no humanoid model is given.
GENERIC_OFFSETS: np.ndarray = _finger_offsets(_GENERIC_BODY)


def humanoid_rest_offsets(model) -> np.ndarray:
    """SMPL-X rest offsets (55, 3) in SMPL-X axes (m), built from the humanoid's proportions.

    The humanoid's body origins at qpos = 0 give the trunk, leg and head offsets (converted from
    its z-up, +x-facing frame to SMPL-X's y-up, +z-facing frame); arm segments keep the
    humanoid's lengths but point sideways, since the SMPL-X rest pose is a T-pose.

    Args:
        model: a ``mujoco.MjModel`` of the humanoid (body names of the humanoid contract).
    """
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)

    def pos(body: str) -> np.ndarray:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
        if bid < 0:
            raise GestureSimError(f"humanoid model has no body {body!r}")
        p = data.xpos[bid]
        return np.array([p[1], p[2], p[0]])  # (x fwd, y left, z up) -> (X left, Y up, Z fwd)

    def site(name: str) -> np.ndarray:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        if sid < 0:
            raise GestureSimError(f"humanoid model has no site {name!r}")
        p = data.site_xpos[sid]
        return np.array([p[1], p[2], p[0]])

    world = {
        "pelvis": pos("pelvis"), "spine1": pos("abdomen"), "spine2": pos("chest"),
        "neck": pos("neck"), "head": pos("head"),
    }
    world["spine3"] = world["spine2"] + 0.4 * (world["neck"] - world["spine2"])
    for side in ("left", "right"):
        world[f"{side}_hip"] = pos(f"{side}_thigh")
        world[f"{side}_knee"] = pos(f"{side}_shin")
        world[f"{side}_ankle"] = pos(f"{side}_foot")
        world[f"{side}_foot"] = pos(f"{side}_toes")
        world[f"{side}_collar"] = pos(f"{side}_clavicle")
        world[f"{side}_shoulder"] = site(f"{side}_shoulder_site")
    body = {name: tuple(_GENERIC_BODY[name]) for name in _BODY}
    parents = SMPLX_PARENTS
    for i, name in enumerate(_BODY[:22]):
        if name in world and parents[i] >= 0 and _BODY[parents[i]] in world:
            body[name] = tuple(world[name] - world[_BODY[parents[i]]])
    for side, sign in (("left", 1.0), ("right", -1.0)):
        upper = np.linalg.norm(site(f"{side}_elbow_site") - site(f"{side}_shoulder_site"))
        fore = np.linalg.norm(site(f"{side}_wrist_site") - site(f"{side}_elbow_site"))
        body[f"{side}_elbow"] = (sign * upper, 0.0, 0.0)
        body[f"{side}_wrist"] = (sign * fore, 0.0, 0.0)
    return _finger_offsets(body)


def _describe(a: np.ndarray) -> str:
    """What an npz entry holds, for a message: ``text 'thirty'``, ``an array of shape (2,)``."""
    if a.dtype.kind in "US":
        first = str(a.reshape(-1)[0]) if a.size else ""
        return f"text {first[:24] + ('…' if len(first) > 24 else '')!r}"
    if a.dtype.kind not in "biuf":
        return f"{a.dtype} data"
    return f"an array of shape {a.shape}" if a.ndim else f"the number {a.item()!r}"


def _frame_rate(value: np.ndarray, path: Path, key: str) -> float:
    """The frame rate (fps) stored under ``key``: a number (a one-element array counts as its
    value); text or several values are a one-line GestureSimError."""
    a = np.asarray(value)
    if a.dtype.kind not in "biuf" or a.size != 1:
        raise GestureSimError(
            f"SMPL-X file {path}: {key!r} must be one number (frames per second), but it holds "
            f"{_describe(a)}")
    return float(a.reshape(()))


def read_smplx(
    path: str | os.PathLike[str], offsets: np.ndarray | None = None,
) -> SkeletonMotion:
    """Read an SMPL-X parameter npz (BEAT2 / AMASS layout) and run forward kinematics.

    Args:
        path: the .npz file with ``poses`` (T, 165 or more, axis-angle, rad), ``trans`` (T, 3, m)
            and ``mocap_frame_rate``/``mocap_framerate`` (fps).
        offsets: (55, 3) rest offsets in SMPL-X axes (m); :data:`GENERIC_OFFSETS` when ``None``.

    Returns:
        A :class:`SkeletonMotion` in SMPL-X axes (Y up), names = :data:`SMPLX_JOINTS`.
    """
    import zipfile

    path = Path(path)
    layout = "an SMPL-X motion is an npz of poses, trans and mocap_frame_rate (BEAT2, AMASS)"
    try:
        if not zipfile.is_zipfile(path):     # numpy's own advice would be to unpickle it
            raise GestureSimError(f"{path}: not a NumPy .npz archive (truncated, damaged, or "
                                  f"another kind of file named .npz); {layout}")
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise GestureSimError(f"cannot read SMPL-X file {path}: {exc}") from exc
    except ValueError as exc:
        why = "it holds pickled objects, which are never loaded" if "pickle" in str(exc) \
            else str(exc).splitlines()[0][:160]
        raise GestureSimError(f"cannot read SMPL-X file {path}: {why}; {layout}") from exc
    for key in ("poses", "trans"):
        if key not in data:
            raise GestureSimError(f"SMPL-X file {path} has no {key!r} array")
    rate_key = next((k for k in ("mocap_frame_rate", "mocap_framerate") if k in data), None)
    if rate_key is None:
        raise GestureSimError(f"SMPL-X file {path} has no 'mocap_frame_rate'")
    for key in ("poses", "trans"):
        if data[key].dtype.kind not in "biuf":
            raise GestureSimError(
                f"SMPL-X file {path}: {key!r} holds {_describe(data[key])}, not numbers")
    poses = np.asarray(data["poses"], dtype=float)
    trans = np.asarray(data["trans"], dtype=float)
    fps = _frame_rate(data[rate_key], path, rate_key)
    if poses.ndim != 2 or poses.shape[1] < 165:
        raise GestureSimError(
            f"SMPL-X file {path}: 'poses' has shape {poses.shape}, expected (T, 165)")
    if trans.shape != (poses.shape[0], 3):
        raise GestureSimError(
            f"SMPL-X file {path}: 'trans' has shape {trans.shape}, expected ({poses.shape[0]}, 3)")
    if not (fps > 0 and np.all(np.isfinite(poses)) and np.all(np.isfinite(trans))):
        raise GestureSimError(f"SMPL-X file {path}: non-finite values or frame rate")
    offsets = GENERIC_OFFSETS if offsets is None else np.asarray(offsets, dtype=float)
    n_frames = poses.shape[0]
    local = Rotation.from_rotvec(poses[:, :165].reshape(-1, 3)).as_matrix().reshape(
        n_frames, 55, 3, 3)
    translations = np.broadcast_to(offsets, (n_frames, 55, 3)).copy()
    translations[:, 0] = trans + offsets[0]
    positions, rotations = forward_kinematics(SMPLX_PARENTS, translations, local)
    return SkeletonMotion(
        names=SMPLX_JOINTS, parents=SMPLX_PARENTS.copy(), offsets=offsets.copy(),
        local_rotations=local, positions=positions, rotations=rotations, fps=fps,
        source=str(path), unit_scale=1.0,
    )
