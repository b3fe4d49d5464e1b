"""The prosody frames of a whole recording with the stream time each became known, as a
listener hears them: a test's and a figure's input for the listeners
(:mod:`gesture_sim.signals.listener`), which read the partner's frames as they arrive."""

from __future__ import annotations

import numpy as np

from gesture_sim.audio.prosody import ProsodyTracker
from gesture_sim.audio.sources import iter_blocks


def tracked_frames(x: np.ndarray, block: int = 160) -> tuple[np.ndarray, ...]:
    """A :class:`~gesture_sim.audio.prosody.ProsodyTracker` fed ``x`` (16 kHz mono samples,
    shape ``(N,)``) in blocks of ``block`` samples.

    Returns:
        ``(times, intensity_db, silent, t_known, f0_hz)``, each of shape ``(F,)``: frame
        centres (s), intensity (dB), the silence flags, the stream time (s) at which each frame
        became known, and F0 (Hz; NaN or 0 where unvoiced, as the tracker gives it).
    """
    tr = ProsodyTracker()
    parts = []
    for chunk in iter_blocks(np.ascontiguousarray(x, dtype=np.float32), block):
        tr.push(chunk)
        k = sum(len(p[0]) for p in parts)
        if tr.n_frames > k:
            fr, known = tr.frames_since(k)
            parts.append((fr.times, fr.intensity_db, fr.silent, known, fr.f0_hz))
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(5))
