"""Praat's autocorrelation pitch of the prosody tracker's batches, each frame analysed once.

The tracker (:mod:`gesture_sim.audio.prosody`) takes the F0 of a batch of ``B`` frames from one
call of Praat's ``Sound: To Pitch (ac)`` (Boersma 1993) over the batch and ``C`` frames of
context before it: :func:`batch_f0`. Praat analyses every frame of that call (its candidates),
then runs its path finder (a Viterbi search through the candidates) over the call's frames. So
each frame is analysed ``(B + C) / B`` times (2.2 with the default 5 + 6).

A frame's candidates depend on its own samples only: a local mean over one longest period
(``1 / pitch_floor``) each side of its centre, a Hanning window of three periods, the
autocorrelation and its interpolated maxima. Only the path finder depends on the call: on the
call's frames and, through each frame's ``intensity`` (the frame's local peak over the call's
global peak, which sets the strength of "unvoiced"), on the call's samples. So when the audio
is known ahead (a file), :class:`PitchAhead` lets Praat analyse many frames in one call, reads
their candidates back, and runs Praat's path finder (``Pitch_pathFinder``, Praat 6.1.38 as
bundled with ``praat-parselmouth`` 0.4.7) itself over each batch's frames with that batch's
global peak — the same arithmetic in the same order, with the C library's ``log`` as Praat
calls it (through :func:`scipy.special.xlogy`; numpy's SIMD ``log`` differs in the last bit) —
for all batches at once. The F0 is the same to the last bit as one Praat call per batch:

* a frame's local peak, which Praat does not hand out, is recomputed here and checked against
  the intensity Praat reports for every frame of the long call (any difference: that stretch
  falls back to one Praat call per batch);
* a batch's global peak needs the mean of its samples; Praat sums in extended precision, numpy
  pairwise in double: where the mean's error bound could change the peak, that batch falls back
  to its own Praat call;
* a batch is taken from here only when the tracker's own samples of it equal the audio known
  ahead (else the tracker stops using it).

Live audio (a microphone) is not known ahead: each batch is one Praat call, as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE

#: Samples per prosody frame step (160 at 16 kHz).
HOP = int(round(PROSODY_FRAME_STEP * SAMPLE_RATE))
#: Extra samples around each Praat segment so that its frame count is exact.
PAD = 8
#: Praat's defaults for the rest of "To Pitch (ac)" (the tracker sets floor, ceiling and the
#: voicing threshold): silence threshold, octave cost, octave-jump cost, voiced/unvoiced cost.
SILENCE_THRESHOLD = 0.03
OCTAVE_COST = 0.01
OCTAVE_JUMP_COST = 0.35
VOICED_UNVOICED_COST = 0.14
MAX_CANDIDATES = 15
#: Praat's ``NUMlog2e``: ``NUMlog2 (x) = log (x) * NUMlog2e``.
_LOG2E = 1.4426950408889634074
#: The most batches whose frames are analysed at a time (a bounded working set: 400 batches =
#: 20 s of audio = 2006 frames).
CHUNK_BATCHES = 400
#: The first chunk's batches: chunks then grow with the position, so that the first control
#: steps (and a physics process waiting for them) do not wait for 20 s of analysis.
FIRST_CHUNK = 40


def chunk_end(i0: int, n: int, most: int, first: int) -> int:
    """End (exclusive) of the chunk of items (batches, windows) that starts at ``i0`` of ``n``:
    ``first`` items at the start, then as many as come before it (doubling), at most ``most``."""
    return min(i0 + min(max(first, i0), most), n)


@dataclass(frozen=True)
class PitchSettings:
    """The pitch analysis: floor and ceiling (Hz), voicing threshold (Praat's defaults for the
    rest)."""

    floor_hz: float = 75.0
    ceiling_hz: float = 500.0
    voicing_threshold: float = 0.45

    @property
    def half(self) -> int:
        """Samples a batch's segment reaches past its first and last frame centres."""
        return int(round(3.0 / self.floor_hz * SAMPLE_RATE)) // 2 + PAD


def praat_pitch(samples: np.ndarray, start: int, s: PitchSettings):
    """Praat's ``To Pitch (ac)`` of ``samples`` (float64, 16 kHz) that start at absolute sample
    ``start``: a ``parselmouth.Pitch`` with one frame per 10 ms centred on the frame grid."""
    import parselmouth

    snd = parselmouth.Sound(samples, SAMPLE_RATE, start_time=start / SAMPLE_RATE)
    return snd.to_pitch_ac(
        time_step=PROSODY_FRAME_STEP, pitch_floor=s.floor_hz, pitch_ceiling=s.ceiling_hz,
        max_number_of_candidates=MAX_CANDIDATES, silence_threshold=SILENCE_THRESHOLD,
        voicing_threshold=s.voicing_threshold, octave_cost=OCTAVE_COST,
        octave_jump_cost=OCTAVE_JUMP_COST, voiced_unvoiced_cost=VOICED_UNVOICED_COST)


def batch_f0(segment: np.ndarray, k0: int, s: PitchSettings) -> np.ndarray:
    """F0 (Hz, 0 where unvoiced) of frames ``k0 ..`` from one Praat call over ``segment``, the
    samples from ``k0 * HOP - s.half`` to ``k1 * HOP + s.half`` (k1 the last frame)."""
    p = praat_pitch(segment, k0 * HOP - s.half, s)
    return np.asarray(p.selected_array["frequency"], dtype=np.float64)


class _FrameGeometry:
    """Praat's sample counts for the AC method (``Sound_to_Pitch_any``, method AC_HANNING,
    three periods a window), relative to a frame centre ``c`` lying between samples ``c - 1``
    and ``c`` (absolute indices)."""

    def __init__(self, s: PitchSettings) -> None:
        dx = 1.0 / SAMPLE_RATE
        self.period = math.floor(1.0 / dx / s.floor_hz)             # nsamp_period
        half_period = self.period // 2 + 1                          # halfnsamp_period
        half_window = math.floor(3.0 / s.floor_hz / dx) // 2 - 1     # halfnsamp_window
        n_window = 2 * half_window
        self.half_window = half_window
        # the Hanning window, as Praat computes it (the C library's cos through math.cos)
        window = np.array([0.5 - 0.5 * math.cos(2.0 * math.pi * i / (n_window + 1))
                           for i in range(1, n_window + 1)])
        lo = max(1, half_window + 1 - half_period)                   # local peak: 1-based
        hi = min(n_window, half_window + half_period)
        self.peak_window = window[lo - 1:hi]
        self.peak_from = -half_window + lo - 1                       # first sample - c
        if s.half < max(self.period, half_window):  # pragma: no cover - settings contract
            raise ValueError("pitch segment margin shorter than Praat's frame")

    def local_peaks(self, x: np.ndarray, first: int, n: int) -> np.ndarray:
        """Praat's ``localPeak`` of ``n`` frames centred at ``first, first + HOP, ..`` (indices
        into ``x``), (n,): the largest windowed magnitude within half a period of the centre,
        after removing the mean over one period each side (summed in order, as Praat's loop
        does)."""
        from numpy.lib.stride_tricks import sliding_window_view

        p, end = self.period, first + n * HOP
        sums = x[first - p: end - p: HOP]
        for i in range(1 - p, p):       # in Praat's order: one rounding per added sample
            sums = sums + x[first + i: end + i: HOP]
        means = sums / (2 * p)
        near = sliding_window_view(x, len(self.peak_window))[
            first + self.peak_from: end + self.peak_from: HOP]
        return np.max(np.abs((near - means[:, None]) * self.peak_window), axis=1)


#: Relative precision of numpy's extended-precision sums (and of Praat's ``longdouble``).
_EPS_LD = float(np.finfo(np.longdouble).eps)


def _peak_within(top: np.ndarray, bottom: np.ndarray, mean: np.ndarray, err: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``max(top - m, m - bottom)`` (double arithmetic, as Praat's ``fabs (z - mean)``) at
    ``m = mean`` rounded to double, and whether it is the same for every double ``m`` within
    ``err`` of ``mean`` (rounding is monotone, so the two ends decide)."""
    m = mean.astype(np.float64)
    lo = np.nextafter(np.nextafter((mean - err).astype(np.float64), -np.inf), -np.inf)
    hi = np.nextafter(np.nextafter((mean + err).astype(np.float64), np.inf), np.inf)
    certain = ((top - lo) == (top - hi)) & ((lo - bottom) == (hi - bottom))
    return np.maximum(top - m, m - bottom), certain


def global_peaks(rows: np.ndarray, refine: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Praat's ``globalPeak`` (the largest |sample - mean|) of each row of ``rows`` (nb, L), and
    whether it is certain. Praat sums the mean in extended precision (pairwise); here numpy
    sums pairwise in ``longdouble``, and where the bound of the difference between the two
    means could change the peak, the row's mean is summed exactly (:func:`math.fsum`) and
    checked against Praat's own bound; a row still undecided is marked uncertain (its batch
    takes its own Praat call). With ``refine`` false no row is summed exactly."""
    n = rows.shape[1]
    top, bottom = np.max(rows, axis=1), np.min(rows, axis=1)
    scale = np.sum(np.abs(rows), axis=1) / n
    mean = np.sum(rows, axis=1, dtype=np.longdouble) / n
    peak, certain = _peak_within(top, bottom, mean, (256.0 * _EPS_LD) * scale)
    certain |= (top == 0.0) & (bottom == 0.0)          # digital silence: mean and peak 0
    for i in np.flatnonzero(~certain) if refine else ():
        exact = np.array([math.fsum(rows[i].tolist()) / n], dtype=np.longdouble)
        err = 32.0 * _EPS_LD * scale[i] + 4.0 * np.spacing(np.abs(exact.astype(np.float64)))
        p, c = _peak_within(top[i:i + 1], bottom[i:i + 1], exact, err)
        peak[i], certain[i] = p[0], c[0]
    return peak, certain


def _log2(x: np.ndarray) -> np.ndarray:
    """Praat's ``NUMlog2`` elementwise, with the C library's ``log`` (``xlogy (1, x)`` is
    ``1.0 * log (x)`` in scipy's C loop; numpy's own ``log`` is a SIMD one)."""
    from scipy.special import xlogy

    return xlogy(1.0, x) * _LOG2E


#: Frames per Praat call when analysing ahead: Praat runs one thread for up to 20 frames and
#: more beyond, which would take the core a physics process runs on (the work is the same).
PIECE_FRAMES = 20


class _Candidates:
    """The candidates of frames ``k_first .. k_first + n - 1`` from Praat calls of up to
    :data:`PIECE_FRAMES` frames, in Praat's own order (the path finder's swap of each frame's
    winner into place 1 undone), with the path finder's frame-independent terms, and whether
    the intensities each call reports are the local peaks ``peaks`` over its global peak
    (``ok``: every call whose global peak is certain agrees, and there is one)."""

    def __init__(self, seg: np.ndarray, k_first: int, n: int, peaks: np.ndarray,
                 s: PitchSettings) -> None:
        half, checked, agree = s.half, 0, True
        freq = np.full((n, MAX_CANDIDATES), np.nan)
        strength = np.full((n, MAX_CANDIDATES), np.nan)
        starts = range(0, n, PIECE_FRAMES)
        length = (PIECE_FRAMES - 1) * HOP + 2 * half
        full = [a for a in starts if a + PIECE_FRAMES <= n]
        peak, sure = np.zeros(len(starts)), np.zeros(len(starts), dtype=bool)
        if full:                    # the pieces' global peaks, unrefined: check the certain
            from numpy.lib.stride_tricks import sliding_window_view

            rows = sliding_window_view(seg, length)[::PIECE_FRAMES * HOP][: len(full)]
            peak[:len(full)], sure[:len(full)] = global_peaks(rows, refine=False)
        if len(full) < len(starts):
            a = starts[-1]
            p, c = global_peaks(seg[a * HOP:][None, :], refine=False)
            peak[-1], sure[-1] = p[0], c[0]
        for piece_no, a in enumerate(starts):
            b = min(a + PIECE_FRAMES, n)                             # frames a .. b - 1
            piece = seg[a * HOP: (b - 1) * HOP + 2 * half]
            pitch = praat_pitch(piece, (k_first + a) * HOP - half, s)
            arr = pitch.to_array()                      # (most candidates, frames), NaN-padded
            if arr.shape[1] != b - a:  # pragma: no cover - guarded by the window arithmetic
                raise AssertionError(f"Praat returned {arr.shape[1]} frames, expected {b - a}")
            freq[a:b, :arr.shape[0]] = arr["frequency"].T
            strength[a:b, :arr.shape[0]] = arr["strength"].T
            g = peak[piece_no]
            if agree and sure[piece_no] and g > 0.0:
                reported = [pitch.get_frame(i + 1).intensity for i in range(b - a)]
                lp = peaks[a:b]
                checked += 1
                agree = np.array_equal(np.where(lp > g, 1.0, lp / g), reported)
        self.ok = agree and checked > 0
        valid = np.isfinite(freq)
        m = max(int(valid.sum(axis=1).max()), 1)       # the most candidates of any frame
        freq, strength, valid = freq[:, :m], strength[:, :m], valid[:, :m]
        rows = np.arange(n)
        # the unvoiced candidate (frequency 0) stood first: swap it back
        place = np.argmax(valid & (freq == 0.0), axis=1)
        for a in (freq, strength):
            a[rows, 0], a[rows, place] = a[rows, place], a[rows, 0].copy()
        voiced = valid & (freq > 0.0) & (freq < s.ceiling_hz)
        self.valid, self.voiced, self.freq = valid, voiced, freq
        # delta of a voiced candidate: strength - octaveCost * NUMlog2 (ceiling / frequency)
        dv = np.zeros_like(freq)
        dv[voiced] = strength[voiced] - OCTAVE_COST * _log2(s.ceiling_hz / freq[voiced])
        self.delta_voiced = dv
        # transition costs from frame i - 1 (candidate b1) to frame i (b2): (n, M, M)
        v1, v2 = voiced[:-1, None, :], voiced[1:, :, None]
        both = v1 & v2
        trans = np.where(v1 ^ v2, VOICED_UNVOICED_COST, 0.0)
        f1 = np.broadcast_to(freq[:-1, None, :], both.shape)[both]
        f2 = np.broadcast_to(freq[1:, :, None], both.shape)[both]
        trans[both] = OCTAVE_JUMP_COST * np.abs(_log2(f1 / f2))
        self.trans = np.concatenate([np.zeros((1,) + trans.shape[1:]), trans])


def path_find(c: _Candidates, first: np.ndarray, n_frames: int, intensity: np.ndarray,
              s: PitchSettings) -> np.ndarray:
    """Praat's ``Pitch_pathFinder`` over frames ``first[b] .. first[b] + n_frames - 1`` (rows
    of ``c``) for each batch b, with the frames' intensities (nb, n_frames) relative to that
    batch's global peak. Returns the chosen candidates' frequencies (nb, n_frames) (Hz; 0 or out
    of range: unvoiced)."""
    idx = first[:, None] + np.arange(n_frames)                       # (nb, F)
    unvoiced = 2.0 - intensity / (SILENCE_THRESHOLD / (1.0 + s.voicing_threshold))
    unvoiced = s.voicing_threshold + np.where(unvoiced > 0.0, unvoiced, 0.0)
    delta = np.where(c.voiced[idx], c.delta_voiced[idx], unvoiced[:, :, None])
    delta = np.where(c.valid[idx], delta, -np.inf)                   # (nb, F, M)
    nb, m = len(first), delta.shape[2]
    psi = np.zeros((nb, n_frames, m), dtype=np.intp)
    acc = delta[:, 0]
    for f in range(1, n_frames):
        # value = prevDelta [icand1] - transitionCost + curDelta [icand2]; ties: first icand1
        value = (acc[:, None, :] - c.trans[idx[:, f]]) + delta[:, f, :, None]
        psi[:, f] = np.argmax(value, axis=2)
        acc = np.take_along_axis(value, psi[:, f, :, None], axis=2)[:, :, 0]
    place = np.argmax(acc, axis=1)
    out = np.empty((nb, n_frames))
    rows = np.arange(nb)
    for f in range(n_frames - 1, -1, -1):
        out[:, f] = c.freq[idx[:, f], place]
        place = psi[rows, f, place]
    return out


class BatchesAhead:
    """What the analyses of the tracker's batches from audio known ahead share: the batches
    whose segments (``half`` samples past their first and last frame centres, and ``margin``
    more each side) lie in the audio; each computed a chunk at a time on first use
    (:meth:`_compute` sets ``_known`` of the chunk's batches to 1, or -1: their own Praat
    calls), and answered only where the tracker's own samples are the audio known ahead.

    Args:
        audio: the high-pass filtered samples (float64) of the whole stream as the tracker will
            hold them, from absolute sample ``-origin`` (zeros before the stream and after it).
        origin: the index in ``audio`` of the stream's sample 0.
        batch_frames, context_frames: the tracker's batch (B) and context (C) frames.
    """

    def __init__(self, audio: np.ndarray, origin: int, batch_frames: int, context_frames: int,
                 half: int, margin: int = 0) -> None:
        self.audio = np.ascontiguousarray(audio, dtype=np.float64)
        self.origin = int(origin)
        self.B, self.C, self.half = int(batch_frames), int(context_frames), int(half)
        # batches j whose segment [(jB - C) HOP - half, (jB + B - 1) HOP + half) lies in audio
        reach = self.half + int(margin)
        first_ok = -(-(self.C * HOP + reach - self.origin) // (self.B * HOP))
        last_ok = (len(self.audio) - self.origin - reach - (self.B - 1) * HOP) // (self.B * HOP)
        self.j_lo, self.j_hi = max(first_ok, 0), max(last_ok + 1, 0)
        self._known = np.zeros(max(self.j_hi - self.j_lo, 0), dtype=np.int8)
        self.stats = {"batches": 0, "fallbacks": 0, "praat_calls": 0}

    def bounds(self, k0, k1):
        """Absolute samples [a, b) of the segment of frames k0..k1 (ints or arrays): from
        ``k0 * HOP - half`` to ``k1 * HOP + half``."""
        return k0 * HOP - self.half, k1 * HOP + self.half

    def segment(self, k0: int, k1: int) -> np.ndarray:
        """The audio known ahead of frames k0..k1 (:meth:`bounds`)."""
        a, b = self.bounds(k0, k1)
        return self.audio[a + self.origin: b + self.origin]

    def _row(self, j: int, segment: np.ndarray | None) -> int | None:
        """Batch ``j``'s row, given the tracker's own ``segment`` of its frames ``jB - C ..
        jB + B - 1`` (None: the caller knows its samples are the audio known ahead); None where
        the batch must take its own Praat call (out of range, undecided, or the tracker's
        samples differ from the audio known ahead)."""
        i = j - self.j_lo
        if not 0 <= i < len(self._known):
            return None
        k0 = j * self.B - self.C
        if segment is not None and not np.array_equal(
                segment, self.segment(k0, k0 + self.B + self.C - 1)):
            return None
        if self._known[i] == 0:
            self._compute(i)
        self.stats["batches"] += 1
        if self._known[i] < 0:
            self.stats["fallbacks"] += 1
            return None
        return i

    def _compute(self, i0: int) -> None:  # pragma: no cover - each analysis has its own
        raise NotImplementedError


class PitchAhead(BatchesAhead):
    """The F0 of the tracker's batches from audio known ahead (see the module docstring and
    :class:`BatchesAhead` for the arguments)."""

    def __init__(self, audio: np.ndarray, origin: int, batch_frames: int, context_frames: int,
                 settings: PitchSettings) -> None:
        super().__init__(audio, origin, batch_frames, context_frames, settings.half)
        self.s = settings
        self._geo = _FrameGeometry(settings)
        self._f0 = np.zeros((len(self._known), self.B))

    def f0(self, j: int, segment: np.ndarray | None) -> np.ndarray | None:
        """F0 (Hz, 0 unvoiced) of batch ``j``'s B frames (see :meth:`BatchesAhead._row` for
        ``segment`` and None)."""
        i = self._row(j, segment)
        return None if i is None else self._f0[i]

    def _compute(self, i0: int) -> None:
        """Analyse the frames of batches ``i0 ..`` (one chunk) and path-find each batch."""
        i1 = chunk_end(i0, len(self._known), CHUNK_BATCHES, FIRST_CHUNK)
        B, C, half = self.B, self.C, self.half
        j0, j1 = self.j_lo + i0, self.j_lo + i1                    # batches j0 .. j1 - 1
        k_first, k_last = j0 * B - C, (j1 - 1) * B + B - 1
        seg = self.segment(k_first, k_last)
        n_frames = k_last - k_first + 1
        peaks = self._geo.local_peaks(seg, half, n_frames)
        cand = _Candidates(seg, k_first, n_frames, peaks, self.s)
        self.stats["praat_calls"] += -(-n_frames // PIECE_FRAMES)
        known = self._known[i0:i1]
        if not cand.ok:             # Praat disagrees with the local peaks: its own calls
            known[:] = -1
            return
        from numpy.lib.stride_tricks import sliding_window_view

        F = B + C
        length = (F - 1) * HOP + 2 * half
        rows = sliding_window_view(seg, length)[::B * HOP][: i1 - i0]
        local = peaks[np.arange(i1 - i0)[:, None] * B + np.arange(F)]
        # Only a frame quieter than 2 * silence / (1 + voicing) of the peak (0.041) gets an
        # unvoiced strength that depends on the peak: elsewhere the peak is never read. A
        # double mean finds those batches (its error is far below 0.05 / 0.041); their peak
        # is then Praat's to the last bit, or the batch falls back.
        mean = np.mean(rows, axis=1)
        g = np.maximum(np.max(rows, axis=1) - mean, mean - np.min(rows, axis=1))
        sensitive = np.any(local < 0.05 * g[:, None], axis=1)
        sure = np.ones(i1 - i0, dtype=bool)
        near = np.flatnonzero(sensitive)
        if len(near):
            g[near], sure[near] = global_peaks(rows[near])
        safe = np.where(g > 0.0, g, 1.0)[:, None]
        intensity = np.where(local > safe, 1.0, local / safe)
        f0 = path_find(cand, np.arange(i1 - i0) * B, F, intensity, self.s)[:, C:]
        f0[g == 0.0] = 0.0                  # Praat returns no candidates for a silent sound
        self._f0[i0:i1] = f0
        known[:] = np.where(sure, 1, -1)
