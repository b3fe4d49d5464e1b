"""Praat's intensity of the prosody tracker's batches, from two long calls when the audio is
known ahead.

The tracker (:mod:`gesture_sim.audio.prosody`) takes the intensity of a batch's frames from one
call of Praat's ``Sound: To Intensity`` over the batch and its context frames
(:func:`praat_intensity`): one call per 50 ms, most of whose cost is the call itself. A frame's
value depends only on the samples of its window (``6.4 / minimum_pitch`` s, a Kaiser window
around the frame's middle sample, the window's mean subtracted); which sample is the middle one
Praat decides by rounding the frame's time on the call's own sample grid
(``Sampled_shortTermAnalysis`` and ``Sampled_xToNearestIndex``, Praat 6.1.38 as bundled with
``praat-parselmouth`` 0.4.7). A frame centred between samples ``c - 1`` and ``c`` may so be
centred on either, depending on the call.

So :class:`IntensityAhead` runs two long calls over many batches, one whose frames sit on the
later sample of each pair and one shifted by a sample, replays Praat's time arithmetic (IEEE
double, in the same order) for the long calls and for each batch's own call, and gives each
frame the value of the long call with the same middle sample. The result is the per-batch call's
to the last bit:

* a batch is taken from here only where the tracker's own samples of it equal the audio known
  ahead, and only where every frame's middle sample is found in a long call;
* per chunk, one batch is analysed by its own Praat call and must agree exactly (values, and
  Praat's times against the replayed ones); else the whole chunk falls back.

Live audio (a microphone) is not known ahead: each batch is one Praat call, as before.
"""

from __future__ import annotations

import math

import numpy as np

from gesture_sim.audio.praat_pitch import FIRST_CHUNK, BatchesAhead, chunk_end
from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE

#: The most batches whose frames one pair of long Praat calls analyses (400 batches = 20 s of
#: audio; the first chunks are shorter, as :func:`~gesture_sim.audio.praat_pitch.chunk_end`).
CHUNK_BATCHES = 400


def _to_intensity(samples: np.ndarray, start: int, minimum_pitch_hz: float):
    """Praat's Sound of ``samples`` (float64, 16 kHz) from absolute sample ``start`` and its
    ``To Intensity`` (mean subtracted, one frame per 10 ms): (``parselmouth.Sound``,
    ``parselmouth.Intensity``)."""
    import parselmouth

    snd = parselmouth.Sound(samples, SAMPLE_RATE, start_time=start / SAMPLE_RATE)
    return snd, snd.to_intensity(minimum_pitch=minimum_pitch_hz, time_step=PROSODY_FRAME_STEP,
                                 subtract_mean=True)


def _db(intensity) -> np.ndarray:
    """A ``parselmouth.Intensity``'s values (dB), -inf where Praat has none."""
    values = np.asarray(intensity.values[0], dtype=np.float64)
    return np.where(np.isfinite(values), values, -np.inf)


def praat_intensity(samples: np.ndarray, start: int, minimum_pitch_hz: float) -> np.ndarray:
    """Praat's ``To Intensity`` (dB, mean subtracted; -inf where Praat has none) of ``samples``
    (float64, 16 kHz) that start at absolute sample ``start``, one frame per 10 ms."""
    return _db(_to_intensity(samples, start, minimum_pitch_hz)[1])


def middle_samples(starts: np.ndarray, n_samples: int, minimum_pitch_hz: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The middle sample (absolute index) of each frame of Praat's intensity of ``n_samples``
    samples from each absolute sample of ``starts`` (n,), (n, frames), and the first frame's
    time (s, (n,)), with Praat's double arithmetic: the Sound's ``x1 = start / fs + 0.5 / fs``,
    ``Sampled_shortTermAnalysis``'s frame count and first time, ``Sampled_indexToX`` and
    ``Sampled_xToNearestIndex`` (``floor (x + 0.5)``)."""
    starts = np.asarray(starts, dtype=np.int64).reshape(-1)
    dx = 1.0 / SAMPLE_RATE
    x1 = starts / SAMPLE_RATE + 0.5 / SAMPLE_RATE
    duration = dx * n_samples
    step = PROSODY_FRAME_STEP
    n_frames = math.floor((duration - 6.4 / minimum_pitch_hz) / step) + 1
    mid_time = x1 - 0.5 * dx + 0.5 * duration
    t1 = mid_time - 0.5 * (n_frames * step) + 0.5 * step
    times = t1[:, None] + np.arange(n_frames, dtype=np.float64) * step
    nearest = np.floor((times - x1[:, None]) / dx + 1.0 + 0.5).astype(np.int64)   # 1-based
    return nearest - 1 + starts[:, None], t1


class IntensityAhead(BatchesAhead):
    """The intensity of the tracker's batches from audio known ahead (see the module docstring
    and :class:`~gesture_sim.audio.praat_pitch.BatchesAhead` for the other arguments).

    Args:
        half: samples a batch's segment reaches past its first and last frame centres.
        minimum_pitch_hz: Praat's "minimum pitch" (the window is 6.4 / this, s).
    """

    def __init__(self, audio: np.ndarray, origin: int, batch_frames: int, context_frames: int,
                 half: int, minimum_pitch_hz: float) -> None:
        # a sample to spare each side: the shifted long call
        super().__init__(audio, origin, batch_frames, context_frames, half, margin=1)
        self.min_pitch = float(minimum_pitch_hz)
        self.half_window = math.floor(0.5 * (6.4 / self.min_pitch) / (1.0 / SAMPLE_RATE))
        self._values = np.zeros((len(self._known), self.B + self.C))

    def values(self, j: int, segment: np.ndarray | None) -> np.ndarray | None:
        """Intensity (dB, -inf where none) of batch ``j``'s frames ``jB - C .. jB + B - 1``
        (see :meth:`~gesture_sim.audio.praat_pitch.BatchesAhead._row` for ``segment`` and
        None: here also a frame not found in the long calls, or a chunk whose check failed)."""
        i = self._row(j, segment)
        return None if i is None else self._values[i]

    def _compute(self, i0: int) -> None:
        """Analyse the frames of batches ``i0 ..`` (one chunk) by two long calls and pick each
        batch frame's value from the call with its middle sample."""
        i1 = chunk_end(i0, len(self._known), CHUNK_BATCHES, FIRST_CHUNK)
        B, C, o, F = self.B, self.C, self.origin, self.B + self.C
        j = np.arange(self.j_lo + i0, self.j_lo + i1)
        k_first, k_last = j[0] * B - C, j[-1] * B + B - 1
        a, b = self.bounds(k_first, k_last)
        n_frames = k_last - k_first + 1
        calls = []                                       # (values, middle samples) of each call
        for lo, hi in ((a, b + 1), (a - 1, b)):
            mids, _ = middle_samples(np.array([lo]), hi - lo, self.min_pitch)
            vals = praat_intensity(self.audio[lo + o: hi + o], lo, self.min_pitch)
            self.stats["praat_calls"] += 1
            if mids.shape[1] != n_frames or len(vals) != n_frames:   # pragma: no cover
                self._known[i0:i1] = -1
                return
            calls.append((vals, mids[0]))
        (va, ma), (vb, mb) = calls
        lo, hi = self.bounds(j * B - C, j * B + B - 1)             # each batch's own call
        mids, _ = middle_samples(lo, hi[0] - lo[0], self.min_pitch)
        if mids.shape[1] != F:      # pragma: no cover - guarded by the window arithmetic
            self._known[i0:i1] = -1
            return
        rows = (j - j[0])[:, None] * B + np.arange(F)
        from_a, from_b = ma[rows] == mids, mb[rows] == mids
        inside = ((mids[:, 0] - self.half_window >= lo)
                  & (mids[:, -1] + self.half_window < hi))
        known = np.where(inside & np.all(from_a | from_b, axis=1), 1, -1).astype(np.int8)
        self._values[i0:i1] = np.where(from_a, va[rows], vb[rows])
        ok = np.flatnonzero(known > 0)
        if len(ok) and not self._agrees(int(j[ok[0]]), self._values[i0 + ok[0]]):
            known[:] = -1
        self._known[i0:i1] = known

    def _agrees(self, j: int, picked: np.ndarray) -> bool:
        """Whether batch ``j``'s own Praat call gives ``picked`` and the replayed times."""
        lo, hi = self.bounds(j * self.B - self.C, j * self.B + self.B - 1)
        snd, it = _to_intensity(self.audio[lo + self.origin: hi + self.origin], lo,
                                self.min_pitch)
        self.stats["praat_calls"] += 1
        _, t1 = middle_samples(np.array([lo]), hi - lo, self.min_pitch)
        return (snd.x1 == lo / SAMPLE_RATE + 0.5 / SAMPLE_RATE and it.x1 == t1[0]
                and np.array_equal(_db(it), picked))

