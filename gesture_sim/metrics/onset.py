"""Voice onset after a pause -> first stroke: the reference onsets and the latency's parts, as
functions on arrays (``gesture-sim bench onset``).

The reference onset is found offline (non-causally) on the samples: 10 ms frames whose RMS
level is at least ``rel_db`` under the file's loud level (its 99th-percentile frame) and above
``floor_db`` are *active*; a run of active frames (gaps shorter than ``bridge_s`` bridged) is a
voice when it lasts ``min_voice_s`` and reaches ``peak_db`` under the loud level somewhere (a
breath before a phrase, 25-30 dB under the voice, is no voice: it neither starts nor breaks a
pause); a voice that follows ``min_pause_s`` without one (from the start of the samples for the
first) is an onset, at its first active frame's start. The causal pipeline knows none of this.
"""

from __future__ import annotations

import numpy as np

#: Frame hop and window of the reference level (s).
HOP_S = 0.010


def frame_levels_db(x: np.ndarray, sr: int, hop_s: float = HOP_S) -> np.ndarray:
    """RMS level (dB re full scale) of consecutive ``hop_s`` frames of ``x (n,)``, ``(F,)``."""
    x = np.asarray(x, dtype=np.float64).ravel()
    hop = int(round(hop_s * sr))
    n = len(x) // hop
    if n == 0:
        return np.zeros(0)
    frames = x[: n * hop].reshape(n, hop)
    return 20.0 * np.log10(np.maximum(np.sqrt(np.mean(frames**2, axis=1)), 1e-10))


def voice_onsets(x: np.ndarray, sr: int, *, min_pause_s: float = 1.0, rel_db: float = -30.0,
                 floor_db: float = -55.0, min_voice_s: float = 0.1, bridge_s: float = 0.05,
                 peak_db: float = -15.0) -> np.ndarray:
    """Times (s) of the voice onsets after a pause of at least ``min_pause_s`` in ``x (n,)``
    at ``sr`` Hz (see the module docstring); the first onset counts when at least
    ``min_pause_s`` of inactivity precedes it in ``x``. ``(K,)``, ascending."""
    lev = frame_levels_db(x, sr)
    if lev.size == 0:
        return np.zeros(0)
    loud = float(np.percentile(lev, 99))
    thr = max(loud + rel_db, floor_db)
    active = lev >= thr
    # bridge short gaps inside the voice (stop closures)
    bridge = int(round(bridge_s / HOP_S))
    idx = np.nonzero(active)[0]
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if 1 < b - a <= bridge + 1:
            active[a:b] = True
    # runs of active frames
    d = np.diff(np.concatenate([[0], active.astype(np.int8), [0]]))
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    keep = np.array([(e - s) * HOP_S >= min_voice_s and lev[s:e].max() >= loud + peak_db
                     for s, e in zip(starts, ends, strict=True)], dtype=bool)
    starts, ends = starts[keep], ends[keep]
    out = []
    prev_end = None
    for s, e in zip(starts, ends, strict=True):
        pause = s * HOP_S if prev_end is None else (s - prev_end) * HOP_S
        if pause >= min_pause_s - 1e-9:
            out.append(s * HOP_S)
        prev_end = e
    return np.asarray(out, dtype=float)


def first_at_or_after(times: np.ndarray, t: float, within_s: float = np.inf) -> float:
    """The first of ``times (K,)`` at or after ``t`` and within ``within_s`` of it (NaN if
    none)."""
    times = np.asarray(times, dtype=float)
    later = times[(times >= t - 1e-9) & (times <= t + within_s)]
    return float(later.min()) if later.size else float("nan")
