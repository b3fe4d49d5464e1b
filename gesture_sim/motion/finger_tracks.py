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

import numpy as np

from gesture_sim.errors import GestureSimError

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
    from gesture_sim.signals.hands import smplx_finger_targets

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
    from gesture_sim.sim.humanoid import FINGER_JOINTS

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
    from gesture_sim.sim.humanoid import FINGER_JOINTS

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
