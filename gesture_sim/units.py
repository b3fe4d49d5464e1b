"""Units the stages share (a ground module: the standard library and numpy only)."""

from __future__ import annotations

import math

import numpy as np


def semitones(f_hz: float | np.ndarray, ref_hz: float = 1.0) -> float | np.ndarray:
    """Pitch ``f_hz`` (Hz) in semitones above ``ref_hz`` (Hz): ``12 log2(f / ref)``.

    A number gives a float (``math.log2``: a value <= 0 raises ``ValueError``); an array gives an
    array of the same shape (``np.log2``: <= 0 gives -inf or NaN, as numpy does). A pitch change
    from ``a`` to ``b`` is ``semitones(b, a)``.
    """
    if isinstance(f_hz, np.ndarray):
        return 12.0 * np.log2(f_hz / ref_hz)
    return 12.0 * math.log2(f_hz / ref_hz)


def parse_seconds(text: str) -> float:
    """Seconds from an annotation's time: ``12.5``, ``mm:ss.ms`` or ``hh:mm:ss.ms`` (as CSV and
    ELAN exports write them); ``ValueError`` for anything else."""
    text = text.strip()
    if ":" in text:
        parts = [float(x) for x in text.split(":")]
        if len(parts) > 3:
            raise ValueError(text)
        sec = 0.0
        for x in parts:
            sec = 60.0 * sec + x
        return sec
    return float(text)
