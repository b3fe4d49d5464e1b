"""Finger motion of a library's clips, beside the library: ``<library>/fingers.npz``.

The library's clips carry the body's joints; a clip whose source has finger motion (an SMPL-X
take with its hand pose, as BEAT2's) can also carry the humanoid's 40 finger joint targets
(rad; 0 = MakeHuman's rest hand, :data:`gesture_sim.sim.humanoid.FINGER_JOINTS` order), one
row per clip frame. They are stored apart from ``library.npz`` so that adding them changes
neither the library's content nor its fingerprint (the inference model and the policy still
fit); ``library build`` and ``train --corpus`` write them for their SMPL-X inputs
(:func:`smplx_finger_track`, through :func:`gesture_sim.motion.build.analyse_clip`),
``tools/build_finger_tracks.py`` for an existing library's clips, and the hand layer
(:class:`gesture_sim.signals.hands.HandLayer`) plays them while their clip plays.

File: ``format`` ``"gesture_sim.finger_tracks"``, ``library_fingerprint``, ``joints`` (40,),
``names`` (K,) clip names and ``track_<name>`` (T, 40) float32 for each.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim.humanoid import FINGER_JOINTS, FINGERS

if TYPE_CHECKING:
    import mujoco

#: The angle from straight (deg) of each finger joint at qpos = 0: the MakeHuman rest hand as
#: tools/build_skin.py fits it (each phalanx against the proximal one about the joint's axis;
#: the thumb's carpometacarpal joint and the spreads are measured from that rest, 0).
MESH_REST_DEG: dict[str, float] = {
    "thumb_cmc_oppose": 0.0, "thumb_cmc_flex": 0.0, "thumb_mcp_flex": -3.2, "thumb_ip_flex": 15.6,
    "index_spread": 0.0, "index_mcp_flex": 13.8, "index_pip_flex": 12.1, "index_dip_flex": 7.5,
    "middle_spread": 0.0, "middle_mcp_flex": 21.5, "middle_pip_flex": 5.8, "middle_dip_flex": 7.6,
    "ring_spread": 0.0, "ring_mcp_flex": 21.9, "ring_pip_flex": 7.0, "ring_dip_flex": 7.0,
    "little_spread": 0.0, "little_mcp_flex": 20.6, "little_pip_flex": 9.6, "little_dip_flex": -0.1,
}

#: The SMPL-X joint whose rotation each finger joint takes (SMPL-X names its little finger
#: ``pinky``; ``1`` is the MCP (the thumb's CMC), ``2`` PIP (thumb MCP), ``3`` DIP (thumb IP)).
SMPLX_OF: dict[str, str] = {
    "thumb_cmc_oppose": "thumb1", "thumb_cmc_flex": "thumb1", "thumb_mcp_flex": "thumb2",
    "thumb_ip_flex": "thumb3",
    **{f"{f}_{j}": f"{'pinky' if f == 'little' else f}{k}" for f in FINGERS[1:]
       for j, k in (("spread", 1), ("mcp_flex", 1), ("pip_flex", 2), ("dip_flex", 3))},
}

#: The humanoid's hand frame at qpos = 0 -> SMPL-X's (T-pose, Y up, facing +Z, the body's
#: left at +X), per side, as a rotation (columns: the images of the humanoid's x, y, z). The
#: humanoid's hand hangs with the fingers down (-z), the palm towards the thigh (left: -y,
#: right: +y), the thumb forward (+x); SMPL-X's left hand points along +X, the right along -X,
#: both palms down (-Y), the thumbs forward (+Z).
HAND_TO_SMPLX: dict[str, np.ndarray] = {
    "left": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "right": np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]),
}


def smplx_finger_angles(poses: np.ndarray, model: mujoco.MjModel) -> np.ndarray:
    """Finger angles from straight (rad), shape (T, 40) in :data:`FINGER_JOINTS` order, from
    SMPL-X poses (T, 165) axis-angle (rad), the 55 joints of
    :data:`gesture_sim.motion.smplx.SMPLX_JOINTS`.

    Each finger joint's angle is the component of its SMPL-X joint's axis-angle vector along
    the finger joint's axis (the humanoid's, from ``model``, taken into SMPL-X's hand frame by
    :data:`HAND_TO_SMPLX`): flexion about the finger's flexion axis, spread about the palm
    normal. A flat SMPL-X hand is 0, a straight finger; the SMPL-X template's finger
    directions and the MakeHuman rest hand's differ by a few degrees, which this ignores.
    """
    from gesture_sim.motion.smplx import SMPLX_JOINTS

    p = np.asarray(poses, dtype=float).reshape(len(poses), -1, 3)
    out = np.zeros((len(p), len(FINGER_JOINTS)))
    for c, name in enumerate(FINGER_JOINTS):
        side, joint = name.split("_", 1)
        axis = HAND_TO_SMPLX[side] @ model.jnt_axis[model.joint(name).id]
        src = SMPLX_JOINTS.index(f"{side}_{SMPLX_OF[joint]}")
        out[:, c] = p[:, src] @ axis
    return out


def smplx_finger_targets(poses: np.ndarray, model: mujoco.MjModel,
                         margin: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Finger joint targets q (rad), shape (T, 40), from SMPL-X poses (T, 165); the angles
    less the mesh's rest (:data:`MESH_REST_DEG`), clamped into the joints' ranges less
    ``margin`` of each span. Also returns the unclamped values (T, 40)."""
    rest = np.radians([MESH_REST_DEG[j.split("_", 1)[1]] for j in FINGER_JOINTS])
    q = smplx_finger_angles(poses, model) - rest
    rng = np.array([model.jnt_range[model.joint(j).id] for j in FINGER_JOINTS])
    span = rng[:, 1] - rng[:, 0]
    return np.clip(q, rng[:, 0] + margin * span, rng[:, 1] - margin * span), q


#: The file beside a library's ``library.npz``.
FINGER_TRACKS = "fingers.npz"
FORMAT = "gesture_sim.finger_tracks"


def smplx_finger_track(path: str | os.PathLike[str], model, fps: float,
                       n_frames: int) -> np.ndarray | None:
    """The humanoid's 40 finger joint targets (rad), shape (n_frames, 40), of an SMPL-X take's
    hand pose, resampled to ``fps`` (Hz; frame j at j / fps s, linear between the source's
    frames, held at its ends) so that row j goes with frame j of the clip the file became;
    ``None`` when the file carries no hand pose (fewer than 165 pose columns, or hands that
    never leave the zero pose). ``model``: the humanoid (its finger joint ranges).
    """
    with np.load(path, allow_pickle=False) as z:
        poses = np.asarray(z["poses"], dtype=float)
        rate_key = next((k for k in ("mocap_frame_rate", "mocap_framerate") if k in z), None)
        src_fps = float(z[rate_key]) if rate_key else fps
    if poses.ndim != 2 or poses.shape[1] < 165 or not np.any(np.abs(poses[:, 75:165]) > 1e-6):
        return None
    q, _ = smplx_finger_targets(poses[:, :165], model)
    t_src = np.arange(len(q)) / src_fps
    t = np.arange(n_frames) / float(fps)
    return np.stack([np.interp(t, t_src, q[:, k]) for k in range(q.shape[1])],
                    axis=1).astype(np.float32)


def save_finger_tracks(library_dir: str | os.PathLike[str], library,
                       tracks: dict[str, np.ndarray]) -> Path:
    """Write ``tracks`` (clip name -> (T, 40) rad, T = the clip's frames) beside the library
    (atomically); returns the path.

    Raises:
        GestureSimError: a name that is no clip of the library, or a track of the wrong shape.
    """
    from gesture_sim.fileio import atomic_path
    names = [c.name for c in library.clips]
    arrays = {}
    for name, track in tracks.items():
        if name not in names:
            raise GestureSimError(f"finger tracks: {name!r} is not a clip of the library")
        clip = library.clips[names.index(name)]
        a = np.asarray(track, dtype=np.float32)
        if a.shape != (clip.n_frames, len(FINGER_JOINTS)):
            raise GestureSimError(f"finger tracks: {name!r} has shape {a.shape}; the clip has "
                                  f"{clip.n_frames} frames of {len(FINGER_JOINTS)} joints")
        arrays[f"track_{name}"] = a
    path = Path(library_dir) / FINGER_TRACKS
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, format=np.array(FORMAT),
                            library_fingerprint=np.array(library.fingerprint),
                            joints=np.array(FINGER_JOINTS), names=np.array(list(tracks)),
                            **arrays)
    return path


def load_finger_tracks(library_dir: str | os.PathLike[str], library) -> dict[int, np.ndarray]:
    """The finger tracks beside a library: clip index -> (T, 40) float rad. Empty when there is
    no file, or when it belongs to another library (fingerprint) or other finger joints (a
    stale file is ignored, not an error: the hands then rest as they do without one)."""
    path = Path(library_dir) / FINGER_TRACKS
    if not path.is_file():
        return {}
    try:
        with np.load(path, allow_pickle=False) as z:
            if (str(z["format"]) != FORMAT
                    or str(z["library_fingerprint"]) != library.fingerprint
                    or tuple(str(j) for j in z["joints"]) != tuple(FINGER_JOINTS)):
                return {}
            names = [c.name for c in library.clips]
            out = {}
            for name in (str(n) for n in z["names"]):
                if name in names:
                    track = np.asarray(z[f"track_{name}"], dtype=float)
                    if len(track) == library.clips[names.index(name)].n_frames:
                        out[names.index(name)] = track
            return out
    except (OSError, KeyError, ValueError) as exc:
        raise GestureSimError(f"cannot read finger tracks {path}: {exc}") from exc
