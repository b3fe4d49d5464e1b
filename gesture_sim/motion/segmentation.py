"""Segmentation of a motion into gesture phases (Levine 2009 §2.2, Gesture Controllers §4.2).

Phase boundaries are placed where the mean speed of the two hands crosses a threshold: strokes
and retractions are fast, holds are slow. Tiny segments are merged away unless they carry enough
motion (a minimum length *or* a minimum integral of speed, as in Levine 2009), and long still
segments are split so that no segment exceeds a maximum length.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

#: Fewest frames a segment may have: it needs three interruption frames strictly inside it.
MIN_FRAMES = 4


@dataclass(frozen=True)
class SegmentationSettings:
    """Thresholds of the segmentation.

    Attributes:
        threshold: mean hand speed (m/s) separating active phases from holds.
        smooth_s: standard deviation (s) of the Gaussian smoothing of the speed signal.
        min_length_s: a segment shorter than this is merged into a neighbour ...
        min_travel_m: ... unless the hands travel at least this far (m) during it.
        max_length_s: longer segments are split into equal parts no longer than this.
    """

    threshold: float = 0.2
    smooth_s: float = 0.05
    min_length_s: float = 0.3
    min_travel_m: float = 0.15
    max_length_s: float = 1.5

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict."""
        return asdict(self)


def hand_speed(hand_pos: np.ndarray, fps: float, smooth_s: float = 0.0) -> np.ndarray:
    """Mean speed of the hands per frame.

    Args:
        hand_pos: (T, H, 3) hand positions (m), usually H = 2 and in a body-relative frame.
        fps: frame rate (Hz).
        smooth_s: Gaussian smoothing (s) applied to the positions before differencing; 0 = none.

    Returns:
        (T,) mean over hands of the speed (m/s), central differences.
    """
    pos = np.asarray(hand_pos, dtype=float)
    if pos.shape[0] < 2:
        return np.zeros(pos.shape[0])
    if smooth_s > 0:
        pos = gaussian_filter1d(pos, smooth_s * fps, axis=0, mode="nearest")
    vel = np.gradient(pos, 1.0 / fps, axis=0)
    return np.linalg.norm(vel, axis=-1).mean(axis=-1)


def segment_clip(
    hand_pos: np.ndarray, fps: float, settings: SegmentationSettings | None = None,
) -> list[tuple[int, int]]:
    """Cut a clip into gesture phases.

    Args:
        hand_pos: (T, H, 3) hand positions (m) in a body-relative frame.
        fps: frame rate (Hz).
        settings: thresholds; defaults when ``None``.

    Returns:
        Segments as frame ranges ``[(start, end), ...]`` covering ``[0, T)`` without gaps; every
        segment has at least :data:`MIN_FRAMES` frames (a clip shorter than that is one segment).
    """
    s = settings or SegmentationSettings()
    speed = hand_speed(hand_pos, fps, s.smooth_s)
    n = len(speed)
    if n < 2 * MIN_FRAMES:
        return [(0, n)] if n else []
    active = speed > s.threshold
    cuts = np.flatnonzero(active[1:] != active[:-1]) + 1
    bounds = [0, *cuts.tolist(), n]
    travel = np.concatenate([[0.0], np.cumsum(speed) / fps])
    min_len = max(MIN_FRAMES, round(s.min_length_s * fps))

    def keeps(a: int, b: int) -> bool:
        length = b - a
        return length >= min_len or (
            length >= MIN_FRAMES and travel[b] - travel[a] >= s.min_travel_m)

    # Merge the weakest short segment into its shorter neighbour until all are kept.
    while len(bounds) > 2:
        lengths = np.diff(bounds)
        bad = [i for i in range(len(lengths)) if not keeps(bounds[i], bounds[i + 1])]
        if not bad:
            break
        i = min(bad, key=lambda k: lengths[k])
        if i == 0:
            del bounds[1]
        elif i == len(lengths) - 1:
            del bounds[-2]
        else:  # remove the boundary shared with the shorter neighbour
            del bounds[i if lengths[i - 1] <= lengths[i + 1] else i + 1]
    max_len = max(2 * MIN_FRAMES, round(s.max_length_s * fps))
    out: list[tuple[int, int]] = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        parts = int(np.ceil((b - a) / max_len))
        edges = np.round(np.linspace(a, b, parts + 1)).astype(int)
        out.extend((int(x), int(y)) for x, y in zip(edges[:-1], edges[1:], strict=True))
    return out
