"""Where real strokes sit against the speech, and how much real motion's own timing varies:
functions on arrays (issue 51, "measure the real motion's timing first").

* :func:`stroke_offsets` — for each target (a stressed-vowel centre or an accent, s), the signed
  time (s) to the nearest hand-speed peak (> 0: the stroke apex comes after the target). Its
  median over the real take is the lead the planner aims strokes by.
* :func:`stroke_phases` — the real motion's own variation of the three things the timing layer
  warps: the **rate** (durations of the stroke phases, dip → peak → dip, whose spread across one
  speaker's strokes bounds a playback-rate change a viewer cannot tell from the speaker's own
  variation), the **holds** (spans where the hands are nearly still while speech goes on), and
  the **amplitude** (the peak hand speed of each stroke).

Hand speed is the mean speed (m/s) of the two hands per frame, as the evaluation computes it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import find_peaks


def stroke_offsets(targets_s: np.ndarray, peaks_s: np.ndarray, max_s: float = 0.5
                   ) -> np.ndarray:
    """(M',) signed offsets (s) from each target to its nearest peak, ``peak - target``, for
    the targets with a peak within ``max_s`` (the others have no stroke of their own)."""
    t = np.sort(np.asarray(targets_s, dtype=float).ravel())
    p = np.sort(np.asarray(peaks_s, dtype=float).ravel())
    if t.size == 0 or p.size == 0:
        return np.zeros(0)
    i = np.clip(np.searchsorted(p, t), 1, max(len(p) - 1, 1)) if len(p) > 1 else \
        np.zeros(len(t), int)
    cand = np.stack([p[np.maximum(i - 1, 0)], p[np.minimum(i, len(p) - 1)]], axis=1) - t[:, None]
    off = cand[np.arange(len(t)), np.argmin(np.abs(cand), axis=1)]
    return off[np.abs(off) <= max_s]


def _quantiles(x: np.ndarray) -> dict[str, float]:
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return {"n": 0.0}
    q = np.quantile(x, [0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95])
    return {"n": float(x.size), "mean": float(x.mean()), "std": float(x.std()),
            **{f"q{k:02d}": float(v) for k, v in zip((5, 10, 25, 50, 75, 90, 95), q,
                                                     strict=True)}}


@dataclass(frozen=True)
class StrokePhases:
    """The real motion's timing variation (see the module docstring).

    Attributes:
        rise_s: (P,) dip → peak durations (s) of its strokes (the preparation and stroke).
        fall_s: (P,) peak → dip durations (s) (the retraction towards the next hold point).
        hold_s: (H,) durations (s) of the spans where the hand speed stays below
            ``hold_speed`` (m/s) for at least two frames.
        peak_speed: (P,) hand speed (m/s) at each stroke apex.
        peaks_per_s: strokes per second.
    """

    rise_s: np.ndarray
    fall_s: np.ndarray
    hold_s: np.ndarray
    peak_speed: np.ndarray
    peaks_per_s: float

    def rate_bounds(self, lo: float = 0.25, hi: float = 0.75) -> tuple[float, float]:
        """The playback-rate range (× the clip's own speed) inside which a stroke's duration
        stays within the ``lo``–``hi`` quantiles of the real strokes' own durations about their
        median: ``(median / q_hi, median / q_lo)`` of the rise times."""
        if self.rise_s.size < 4:
            return (1.0, 1.0)
        q_lo, med, q_hi = np.quantile(self.rise_s, [lo, 0.5, hi])
        return (float(med / q_hi), float(med / max(q_lo, 1e-9)))

    def summary(self) -> dict:
        d = {k: _quantiles(v) for k, v in asdict(self).items() if isinstance(v, np.ndarray)}
        d["peaks_per_s"] = self.peaks_per_s
        d["rate_bounds_iqr"] = list(self.rate_bounds())
        d["amplitude_cv"] = (float(self.peak_speed.std() / self.peak_speed.mean())
                             if self.peak_speed.size else float("nan"))
        return d


def stroke_phases(speed: np.ndarray, fps: float, rel_prominence: float = 0.1,
                  hold_speed: float = 0.1, speaking: np.ndarray | None = None) -> StrokePhases:
    """The stroke phases, holds and apex speeds of one hand-speed curve ``speed (T,)`` (m/s at
    ``fps``); peaks as :func:`gesture_sim.metrics.motion.speed_peaks` finds them (prominence
    ``rel_prominence`` × the range). ``speaking`` (T,) bool keeps only the holds during speech."""
    s = np.asarray(speed, dtype=float).ravel()
    span = float(np.ptp(s)) if s.size else 0.0
    if span <= 0:
        z = np.zeros(0)
        return StrokePhases(z, z, z, z, 0.0)
    peaks, _ = find_peaks(s, prominence=rel_prominence * span)
    dips, _ = find_peaks(-s, prominence=rel_prominence * span)
    rise, fall = [], []
    for p in peaks:
        before = dips[dips < p]
        after = dips[dips > p]
        if len(before):
            rise.append((p - before[-1]) / fps)
        if len(after):
            fall.append((after[0] - p) / fps)
    slow = s < hold_speed
    if speaking is not None:
        slow &= np.asarray(speaking, dtype=bool).ravel()[:len(s)]
    holds, run = [], 0
    for v in np.append(slow, False):
        if v:
            run += 1
        else:
            if run >= 2:
                holds.append(run / fps)
            run = 0
    return StrokePhases(np.asarray(rise), np.asarray(fall), np.asarray(holds), s[peaks],
                        len(peaks) / (len(s) / fps))
