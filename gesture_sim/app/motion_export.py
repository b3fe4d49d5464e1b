"""Motion outputs other tools read: ``render --bvh`` (BVH), ``render --npz`` (numpy arrays),
``render --smplx`` (SMPL-X in BEAT2's layout), ``render --mixamo`` (BVH on the Mixamo rig) and
``render --to-skeleton`` (BVH on the user's own skeleton).

BVH: the simulated body resampled to :data:`BVH_FPS` and written by
:mod:`gesture_sim.motion.bvh_export` (Y up, centimetres, Mixamo-style joint names).
SMPL-X and Mixamo: the same frames, mapped onto those skeletons by :mod:`gesture_sim.export`
(:mod:`~gesture_sim.export.smplx`, :mod:`~gesture_sim.export.mixamo`).

NPZ (``numpy.load(path)``, no pickle needed), format ``gesture_sim.motion_npz`` version 1:

============== ========== ===========================================================
key            shape      meaning
============== ========== ===========================================================
format         ()         ``"gesture_sim.motion_npz"``; ``version`` () int
time           (T,)       recorded simulation rows (s)
qpos           (T, nq)    full MuJoCo state of the humanoid (root position m, root
                          quaternion w x y z, then each joint: rad, m for slides)
qpos_names     (nq,)      name of each qpos column (``root_x`` ... ``root_qz``, joints)
joint_names    (n,)       the actuated joints (``sim.humanoid.ACTUATED_JOINTS``)
q              (T, n)     simulated joint positions (rad; m for slides)
q_target       (T, n)     the target pose q*(t) the controller asked for
decision_t     (D,)       decision times (s); ``decision_segment``, ``decision_frame``
                          (D,) int; ``decision_kind``, ``decision_clip`` (D,) str
decisions_json ()         the whole decision log with its cost terms, as JSON text
============== ========== ===========================================================
"""

from __future__ import annotations

import json
import os
from typing import Any

import mujoco
import numpy as np

from gesture_sim.fileio import jsonable
from gesture_sim.motion.bvh_export import bvh_text

#: Frame rate of the BVH export (Hz).
BVH_FPS = 30.0
NPZ_FORMAT = "gesture_sim.motion_npz"
NPZ_VERSION = 1


def write_bvh_from_trace(path: str | os.PathLike[str], model: mujoco.MjModel, trace: Any,
                         duration_s: float, fps: float = BVH_FPS) -> int:
    """Write the trace's motion (``trace.time`` (T,), ``trace.qpos`` (T, nq)) as BVH.

    The poses are resampled to ``fps`` over ``duration_s`` seconds (the audio's length, as the
    video is). Returns the number of frames. ``path`` is written directly: pass a temporary.
    """
    from gesture_sim.app.video import frames_for_duration, resample_qpos

    n_frames = frames_for_duration(duration_s, fps)
    qpos = resample_qpos(model, trace.time, trace.qpos, fps, n_frames=n_frames)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(bvh_text(model, qpos, fps))
    return n_frames


def _export_frames(model: mujoco.MjModel, trace: Any, duration_s: float,
                   fps: float) -> np.ndarray:
    """The trace's qpos resampled to ``fps`` over ``duration_s`` seconds, as for the BVH."""
    from gesture_sim.app.video import frames_for_duration, resample_qpos

    n_frames = frames_for_duration(duration_s, fps)
    return resample_qpos(model, trace.time, trace.qpos, fps, n_frames=n_frames)


def write_smplx_from_trace(path: str | os.PathLike[str], model: mujoco.MjModel, trace: Any,
                           duration_s: float, fps: float = BVH_FPS) -> int:
    """Write the trace's motion as SMPL-X parameters in BEAT2's npz layout
    (:mod:`gesture_sim.export.smplx`), resampled like :func:`write_bvh_from_trace`. Returns the
    number of frames. ``path`` is written directly: pass a temporary."""
    from gesture_sim.export.smplx import save_npz, smplx_arrays

    qpos = _export_frames(model, trace, duration_s, fps)
    arrays = smplx_arrays(model, qpos, fps)
    with open(path, "wb") as fh:
        save_npz(fh, arrays)
    return len(qpos)


def write_mixamo_from_trace(path: str | os.PathLike[str], model: mujoco.MjModel, trace: Any,
                            duration_s: float, fps: float = BVH_FPS) -> int:
    """Write the trace's motion as a BVH on the Mixamo rig (:mod:`gesture_sim.export.mixamo`),
    resampled like :func:`write_bvh_from_trace`. Returns the number of frames. ``path`` is
    written directly: pass a temporary."""
    from gesture_sim.export.mixamo import bvh_text as mixamo_bvh_text

    qpos = _export_frames(model, trace, duration_s, fps)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(mixamo_bvh_text(model, qpos, fps))
    return len(qpos)


def write_skeleton_from_trace(path: str | os.PathLike[str],
                              skeleton: str | os.PathLike[str] | Any, model: mujoco.MjModel,
                              trace: Any, duration_s: float, fps: float = BVH_FPS) -> int:
    """Write the trace's motion as a BVH on a user's skeleton (a BVH file or a
    :class:`gesture_sim.export.skeleton.UserSkeleton`; :mod:`gesture_sim.export.skeleton`),
    resampled like :func:`write_bvh_from_trace`. Returns the number of frames. ``path`` is
    written directly: pass a temporary."""
    from gesture_sim.export.skeleton import UserSkeleton, read_skeleton, skeleton_bvh_text

    if not isinstance(skeleton, UserSkeleton):
        skeleton = read_skeleton(skeleton)
    qpos = _export_frames(model, trace, duration_s, fps)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(skeleton_bvh_text(skeleton, model, qpos, fps))
    return len(qpos)


def read_motion_npz(path: str | os.PathLike[str]) -> Any:
    """The ``time`` (T,) and ``qpos`` (T, nq) of a motion npz written by ``render --npz``, as an
    object with those two attributes (what the ``*_from_trace`` writers read of a trace)."""
    from types import SimpleNamespace

    from gesture_sim.errors import GestureSimError

    try:
        with np.load(path, allow_pickle=False) as z:
            if "format" not in z.files or str(z["format"]) != NPZ_FORMAT:
                raise GestureSimError(f"{path}: {_npz_kind(z.files)}, not a {NPZ_FORMAT} "
                                      "file (the motion `gesture-sim render --npz` writes: "
                                      "time, qpos, ...), which is what export reads")
            return SimpleNamespace(time=np.asarray(z["time"], dtype=float),
                                   qpos=np.asarray(z["qpos"], dtype=float))
    except (OSError, KeyError, ValueError) as exc:
        raise GestureSimError(f"cannot read motion file {path}: {exc}") from exc


def _npz_kind(keys: list[str]) -> str:
    """What an npz that is not a motion file seems to be, from its array names."""
    have = set(keys)
    if {"poses", "trans"} <= have or {"betas", "poses"} <= have:
        return ("an SMPL-X/SMPL motion (poses, trans, betas: the BEAT2/AMASS layout, which "
                "`render --smplx` and `export --format smplx` write and `library build` reads)")
    if not have:
        return "an empty npz archive"
    shown = ", ".join(sorted(have)[:6]) + (", ..." if len(have) > 6 else "")
    return f"an npz of other arrays ({shown})"


def qpos_names(model: mujoco.MjModel) -> list[str]:
    """Names of the ``model.nq`` qpos columns: joint names, with suffixes for free/ball joints."""
    names = [""] * model.nq
    suffixes = {mujoco.mjtJoint.mjJNT_FREE: ("x", "y", "z", "qw", "qx", "qy", "qz"),
                mujoco.mjtJoint.mjJNT_BALL: ("qw", "qx", "qy", "qz")}
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
        adr = int(model.jnt_qposadr[j])
        parts = suffixes.get(int(model.jnt_type[j]))
        if parts is None:
            names[adr] = name
        else:
            for k, s in enumerate(parts):
                names[adr + k] = f"{name}_{s}"
    return names


def motion_arrays(model: mujoco.MjModel, trace: Any,
                  decisions: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """The NPZ's arrays (see the module docstring) from a trace and the decision log rows."""
    return {
        "format": np.array(NPZ_FORMAT), "version": np.array(NPZ_VERSION),
        "time": np.asarray(trace.time, dtype=float),
        "qpos": np.asarray(trace.qpos, dtype=float),
        "qpos_names": np.array(qpos_names(model)),
        "joint_names": np.array(list(trace.joint_names)),
        "q": np.asarray(trace.q, dtype=float),
        "q_target": np.asarray(trace.q_target, dtype=float),
        "decision_t": np.array([d["t"] for d in decisions], dtype=float),
        "decision_segment": np.array([d["segment_id"] for d in decisions], dtype=int),
        "decision_frame": np.array([d["frame"] for d in decisions], dtype=int),
        "decision_kind": np.array([str(d["kind"]) for d in decisions], dtype=str),
        "decision_clip": np.array([str(d.get("clip", "")) for d in decisions], dtype=str),
        "decisions_json": np.array(json.dumps(jsonable(decisions), default=str)),
    }


def write_npz(path: str | os.PathLike[str], arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` compressed to exactly ``path`` (no ``.npz`` appended): pass a temporary."""
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)

