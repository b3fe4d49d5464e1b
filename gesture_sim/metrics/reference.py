"""Reference ("real") motion and the FGD feature extractor of the motion metrics.

The library's co-speech clips (those whose source is BEAT2; all clips if there are none), posed
kinematically on the standing body (upper-body joint angles of the clip, legs at the standing
pose, root upright), i.e. the real motion as the pipeline would ask the body to play it. The
FGD extractor (:class:`~gesture_sim.metrics.motion.FGDExtractor`, PCA, 32 components, 34-frame
windows, pelvis-relative, per-coordinate deviations floored at 2 cm: :func:`fit_extractor`) is
fitted on *all* clips of the library and stored as ``<library>/fgd_extractor.npz``
(:func:`save_extractor`, :func:`load_extractor`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics.points import POINT_NAMES, PointFK

#: FGD window (frames at 30 fps) and the extractor's file name inside a library folder.
FGD_WINDOW = 34
FGD_COMPONENTS = 32
#: Lower bound of a window coordinate's standard deviation in the FGD extractor (m).
FGD_STD_FLOOR_M = 0.02
EXTRACTOR_FILE = "fgd_extractor.npz"


def legs_zeroed(q: np.ndarray, joint_names: Sequence[str]) -> np.ndarray:
    """A copy of ``q (T, n)`` with the leg columns (``LEG_JOINTS``) at 0 (the standing pose),
    as the pipeline holds them (:func:`gesture_sim.sim.humanoid.hold_legs`)."""
    from gesture_sim.sim.humanoid import hold_legs

    return hold_legs(q, joint_names)


def to_actuated(q: np.ndarray, joint_names: Sequence[str]) -> np.ndarray:
    """Columns ``joint_names`` of ``q (T, n)`` reordered to ``ACTUATED_JOINTS`` (missing: 0)."""
    from gesture_sim.sim.humanoid import ACTUATED_JOINTS

    names = list(joint_names)
    if tuple(names) == tuple(ACTUATED_JOINTS):
        return np.asarray(q, dtype=float)
    out = np.zeros((len(q), len(ACTUATED_JOINTS)))
    for j, n in enumerate(ACTUATED_JOINTS):
        if n in names:
            out[:, j] = q[:, names.index(n)]
    return out


def clip_positions(library, fk: PointFK, clips: Sequence[int] | None = None
                   ) -> list[np.ndarray]:
    """Joint positions of library clips on the standing body: a list of ``(T_c, 12, 3)`` (m)
    at the library's frame rate (legs at the standing pose, root upright)."""
    idx = range(len(library.clips)) if clips is None else clips
    out = []
    for c in idx:
        q = legs_zeroed(library.clips[c].qpos, library.joint_names)
        out.append(fk.standing(to_actuated(q, library.joint_names)))
    return out


def cospeech_clips(library) -> list[int]:
    """Indices of the library's co-speech clips (source BEAT2); all clips when none is."""
    idx = [i for i, c in enumerate(library.clips) if "BEAT" in c.source.upper()]
    return idx or list(range(len(library.clips)))


def library_windows(positions: Sequence[np.ndarray], window: int = FGD_WINDOW) -> np.ndarray:
    """Pelvis-relative windows ``(N, window, 12, 3)`` of every clip, concatenated."""
    parts = [mm.motion_windows(p, window, root_joint=0) for p in positions if len(p) >= window]
    if not parts:
        raise GestureSimError(f"no library clip is {window} frames long")
    return np.concatenate(parts)


def fit_extractor(library, fk: PointFK | None = None, std_floor: float = FGD_STD_FLOOR_M
                  ) -> mm.FGDExtractor:
    """The FGD extractor fitted on every clip of ``library`` (deterministic).

    As :meth:`FGDExtractor.fit <gesture_sim.metrics.motion.FGDExtractor.fit>` (standardise
    each window coordinate, then PCA), except that a coordinate's standard deviation is raised
    to at least ``std_floor`` metres (:data:`FGD_STD_FLOOR_M`) rather than to 1 % of the
    median. Trunk points relative to the pelvis vary by millimetres in the library; with a
    relative floor the few millimetres of balance sway of a simulated body became many
    standard deviations and dominated FGD (the real take replayed through physics, tracked to
    within 8 mm, scored 430 against a split-half floor of 53; with the 2 cm floor: 11).
    """
    fk = fk or PointFK()
    w = library_windows(clip_positions(library, fk))
    x = w.reshape(len(w), -1)
    ext = mm.FGDExtractor(FGD_COMPONENTS)
    ext.mean = x.mean(axis=0)
    ext.std = np.maximum(x.std(axis=0), std_floor)
    k = max(1, min(ext.n_components, x.shape[0] - 1, x.shape[1]))
    _, _, vt = np.linalg.svd((x - ext.mean) / ext.std, full_matrices=False)
    ext.components = vt[:k]
    ext.window_shape = tuple(w.shape[1:])
    return ext


def save_extractor(extractor: mm.FGDExtractor, path: str | os.PathLike[str], library) -> None:
    """Write the extractor with the library's fingerprint and the point names (atomically)."""
    from gesture_sim.fileio import atomic_path

    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        np.savez(
            fh, kind="fgd_pca", version=1, n_components=extractor.n_components,
            window_shape=np.asarray(extractor.window_shape), mean=extractor.mean,
            std=extractor.std, components=extractor.components,
            library_fingerprint=str(library.fingerprint), points=np.array(POINT_NAMES),
            window=FGD_WINDOW, fps=float(library.fps), std_floor_m=FGD_STD_FLOOR_M,
        )


def load_extractor(library_dir: str | os.PathLike[str], library, fk: PointFK | None = None
                   ) -> tuple[mm.FGDExtractor, str]:
    """The stored extractor of ``library_dir`` if it fits ``library``, else one fitted now.

    Returns ``(extractor, origin)`` with origin ``"stored"`` or ``"fitted in memory"``.
    """
    from gesture_sim.fileio import decoding_errors

    path = Path(library_dir) / EXTRACTOR_FILE
    if path.is_file():
        # a damaged file (truncated, not an archive, a bad entry) is one line naming it; an
        # extractor of another library or an older layout (an entry missing) is refitted
        rebuild = (f"refit it with 'python tools/fit_fgd_extractor.py {library_dir}', or "
                   "delete it (eval then fits one in memory)")
        with decoding_errors(path, "FGD feature extractor", rebuild):
            with np.load(path, allow_pickle=False) as d:
                try:
                    ok = (str(d["library_fingerprint"]) == str(library.fingerprint)
                          and tuple(str(p) for p in d["points"]) == POINT_NAMES
                          and float(d["std_floor_m"]) == FGD_STD_FLOOR_M)
                except KeyError:
                    ok = False
            if ok:
                return mm.FGDExtractor.load(path), "stored"
    return fit_extractor(library, fk), "fitted in memory"
