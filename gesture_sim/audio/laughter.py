"""Laughter from the audio, causal: Okwechime 2011's per-frame laugh signal [L] of a speaker.

The thesis labels laughing [L] from *video* (Viola-Jones face, an AdaBoost classifier on the lip
region, §5.1.3); this project's avatars hear their partner, so the signal is detected from the
partner's voice instead. The rule follows the acoustics of laughter as the literature describes
it: a laugh bout is a train of short "ha" calls (Provine 1996, 2000: ~0.2 s calls about 4-6 per
second, rarely a single one; Bachorowski, Smoski & Owren 2001: calls of ~0.1-0.2 s, a bout of 3-4
calls on average, often unvoiced or breathy, /h/-like aspiration between the voiced bursts;
Truong & van Leeuwen 2007: the energy modulation and spectral features carry most of the
discrimination from speech). What separates a call train from ordinary syllables, which also
come 3-5 a second, is (1) the *regularity* of the rhythm, (2) the deep energy dip between calls
(the /h/ or a breath, not a consonant that is part of a running vowel stream) and (3) the *lack
of spectral change* from call to call (the same vowel repeated; speech changes vowel and
consonant at every syllable).

**Frames** (:class:`LaughterDetector`; numpy only). The 16 kHz stream is cut into frames of
``WIN`` = 400 samples (25 ms, Hann window) every ``HOP`` = 160 samples (10 ms, the prosody frame
step :data:`~gesture_sim.contracts.PROSODY_FRAME_STEP`): frame ``k`` covers samples
``[160 k, 160 k + 400)``, centre time ``(160 k + 200) / 16000`` s, known once its last sample has
arrived. Per frame: the level (dB re full scale, the windowed mean square) and the log power
(dB) in seven bands (80-300, 300-700, 700-1200, 1200-2000, 2000-3000, 3000-4500, 4500-8000 Hz)
of a 512-point FFT. These are recomputed here rather than taken from the prosody tracker: the
listener side of a conversation holds only the partner's samples (the audio-driven listener) or
its prosody frames without any spectrum (the rule listener), and the tracker's Praat intensity
(a 64 ms window) blurs a 5 Hz call rhythm; F0 is not used (see the limits).

**Calls.** Peaks of the level separated by troughs (as the prosody tracker's syllables): a peak
is confirmed once the level has fallen ``dip_db`` (6 dB) below it, the trough after it once the
level has risen ``dip_db`` above the trough's minimum, or once ``ioi_max_s`` has passed since
the peak (a call followed by silence). A call has a peak frame, the troughs before and after,
its span (the frames within ``call_db`` = 12 dB of the peak between the troughs), its depth
(the smaller of the peak's heights above the two troughs, dB) and its spectral shape (the mean
band dB over the frames within 3 dB of the peak, minus its own mean: a level-free vowel colour).
A call counts when its peak lies above ``floor_db`` (-55 dBFS) and within ``rel_db`` (30 dB)
of the stream's loud level (a peak follower decaying ``loud_decay_db_per_s``), its span lasts
``dur_min_s``..``dur_max_s`` (0.04..0.30 s), its depth is at least ``depth_db`` (9 dB) and at
most ``high_share`` (half) of its power lies above 3 kHz (a sibilant /s/ is no call; an /h/ or a
breathy call has the vowel's formants below 3 kHz).

**A laugh** is a run of at least ``min_calls`` (3) consecutive counting calls whose peak-to-peak
intervals all lie in ``ioi_min_s``..``ioi_max_s`` (0.12..0.33 s: 3-8 calls/s) and whose last
``min_calls`` calls are (1) regular: every interval within ``ioi_tol`` (15 %) of their median;
(2) spectrally constant: every call's shape within ``spec_db`` (2.5 dB RMS over the bands) of the
calls' mean shape; (3) even: peaks within ``level_spread_db`` (12 dB). The laugh spans from
the first call's onset to the last call's end; each further call that continues the run (same
tests on the last ``min_calls``) extends it. It is detected when its last call is confirmed:
``t_detected`` is the stream time of the sample that confirmed it (a causal decision about
0.05-0.35 s after the call's peak).

**Outputs.** :meth:`LaughterDetector.push` returns the per-frame decisions that became final:
a frame's decision is final ``delay_s`` (1.5 s) after its centre, long enough for the calls that
may still mark it (a span begins at most about ``min_calls * ioi_max_s`` before its detection),
so the decisions are exact and causal with that fixed latency (a frame already decided is
never changed); :attr:`LaughterDetector.laughs`
(and :meth:`LaughterDetector.take_new`) list the :class:`Laugh` spans with their detection time,
for a consumer that wants the earliest news. Whole-file (:func:`detect_laughter`) and streamed
analysis in any block sizes give identical frames and spans.

**Limits.** The rule has been measured only on real speech (false alarms) and on synthetic
laughter made with espeak-ng and sox (hits); no real laughter recording was available, so the hit
rate on real laughs is unknown (``tools/laughter_eval.py``; docs/OKWECHIME.md has the figures:
no false alarm on 6.1 min of real speech nor on 5.1 min of the espeak test dialogue, 85 % of
164 synthetic laughs found, none of 72 synthetic non-laughs taken for one).
It will miss what real laughter often is: a single exhaled call, a snort, giggling faster than
8 calls/s, a slow or irregular bout, or laughter superimposed on speech ("speech-laughs"), and
voiced-only laughs with shallow dips. It will fire on anything that repeats one syllable 3-8
times a second with deep dips (stuttered syllables, "no no no", counting "ha" deliberately, a
regular mechanical noise). F0 (laughs are often high and variable) is not used: synthetic
laughter does not have it, and a speaker's high F0 alone is no laugh; it is a natural extra test
where a tracker's F0 is at hand.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE

__all__ = ["BANDS_HZ", "HOP", "WIN", "Laugh", "LaughterConfig", "LaughterDetector",
           "detect_laughter"]

#: Samples per frame step (160 at 16 kHz, the prosody frame step).
HOP = int(round(PROSODY_FRAME_STEP * SAMPLE_RATE))
#: Samples per analysis window (25 ms).
WIN = 400
N_FFT = 512
#: Band edges (Hz) of the spectral shape.
BANDS_HZ: tuple[float, ...] = (80.0, 300.0, 700.0, 1200.0, 2000.0, 3000.0, 4500.0, 8000.0)
_FLOOR = 1e-12
_WINDOW = np.hanning(WIN + 2)[1:-1]
_WPOW = float(np.sum(_WINDOW ** 2))
_FREQS = np.arange(N_FFT // 2 + 1) * SAMPLE_RATE / N_FFT
_BAND = np.zeros((len(BANDS_HZ) - 1, len(_FREQS)))
for _i in range(len(BANDS_HZ) - 1):
    _BAND[_i] = (_FREQS >= BANDS_HZ[_i]) & (_FREQS < BANDS_HZ[_i + 1])


@dataclass(frozen=True)
class LaughterConfig:
    """Settings of the detector (dB, s, fractions; module docstring).

    Attributes:
        dip_db: fall after a peak / rise after a trough that confirms it (dB).
        call_db: a call's span: frames within this of its peak (dB).
        depth_db: least height of a call's peak above both neighbouring troughs (dB).
        floor_db: a call's peak must exceed this (dB re full scale).
        rel_db: ... and lie within this of the loud level (dB).
        loud_decay_db_per_s: how fast the loud level (a peak follower) forgets (dB/s).
        dur_min_s, dur_max_s: a call's span (s).
        ioi_min_s, ioi_max_s: peak-to-peak interval of consecutive calls in a laugh (s).
        ioi_tol: every interval of the judged calls within this fraction of their median.
        spec_db: every call's spectral shape within this RMS distance (dB) of the mean shape.
        level_spread_db: the judged calls' peaks within this range (dB).
        high_share: a call's power above 3 kHz must be at most this share (a sibilant is no
            "ha"; an /h/ or a breathy call has the vowel's formants below 3 kHz).
        min_calls: calls judged (and the fewest that make a laugh).
        delay_s: latency of the per-frame decisions (s).
    """

    dip_db: float = 6.0
    call_db: float = 12.0
    depth_db: float = 9.0
    floor_db: float = -55.0
    rel_db: float = 30.0
    loud_decay_db_per_s: float = 2.0
    dur_min_s: float = 0.04
    dur_max_s: float = 0.30
    ioi_min_s: float = 0.12
    ioi_max_s: float = 0.33
    ioi_tol: float = 0.15
    spec_db: float = 2.5
    level_spread_db: float = 12.0
    high_share: float = 0.5
    min_calls: int = 3
    delay_s: float = 1.5


@dataclass(frozen=True)
class Laugh:
    """One detected laugh (times s on the stream clock).

    Attributes:
        start, end: first call's onset, last call's end (frame edges).
        t_detected: the stream time at which it was detected (its first ``min_calls`` calls).
        n_calls: calls in the bout so far; rate_hz: calls per second (1 / median interval).
    """

    start: float
    end: float
    t_detected: float
    n_calls: int
    rate_hz: float


@dataclass
class _Call:
    k_peak: int
    peak_db: float
    k_on: int
    k_off: int
    depth_db: float
    shape: np.ndarray
    ok: bool
    t_known: float = field(default=0.0)


def _frame_features(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frames (n, WIN) -> (level dB re full scale (n,), band power dB (n, 7))."""
    xw = frames * _WINDOW
    level = 10.0 * np.log10(np.maximum(np.sum(xw * xw, axis=1) / _WPOW, _FLOOR))
    spec = np.abs(np.fft.rfft(xw, n=N_FFT, axis=1)) ** 2
    bands = 10.0 * np.log10(np.maximum(spec @ _BAND.T, _FLOOR))
    return level, bands


class LaughterDetector:
    """The causal laugh detector (module docstring): :meth:`push` 16 kHz samples, get the
    per-frame decisions that became final; :attr:`laughs` the laughs so far."""

    def __init__(self, config: LaughterConfig | None = None) -> None:
        self.cfg = config or LaughterConfig()
        self.reset()

    def reset(self) -> None:
        """A new stream at t = 0."""
        self._buf = np.zeros(0)
        self._buf_start = 0        # absolute sample index of _buf[0]
        self.n_in = 0              # samples received
        self.k = 0                 # next frame to compute
        self._level: deque[float] = deque()   # per frame from _k0
        self._bands: deque[np.ndarray] = deque()
        self._flag: deque[bool] = deque()
        self._k0 = 0               # absolute frame index of the deques' first entry
        self._k_out = 0            # next frame whose decision is emitted
        self._loud = -math.inf
        # peak/trough picker
        self._mode = "peak"
        self._ext_k, self._ext_db = -1, -math.inf   # running max (peak mode) / min (trough)
        self._trough_k, self._trough_db = 0, math.inf  # the trough before the pending peak
        self._peak_k, self._peak_db = -1, -math.inf
        self._calls: list[_Call] = []
        self.laughs: list[Laugh] = []
        self._new: list[Laugh] = []
        self._active = False       # the last call continued the current laugh

    # ------------------------------------------------------------------ input
    def push(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples (n,) float at 16 kHz -> (centre times (m,) s, laugh flags (m,) bool) of the
        frames whose decisions became final (``delay_s`` after their centre)."""
        x = np.asarray(samples, float).reshape(-1)
        if len(x):
            self._buf = np.concatenate([self._buf, x])
            self.n_in += len(x)
        n_done = (self.n_in - WIN) // HOP + 1 if self.n_in >= WIN else 0
        if n_done > self.k:
            ks = np.arange(self.k, n_done)
            idx = (ks[:, None] * HOP - self._buf_start) + np.arange(WIN)[None, :]
            level, bands = _frame_features(self._buf[idx])
            for j, kk in enumerate(ks.tolist()):
                self._frame(kk, float(level[j]), bands[j])
            self.k = n_done
            drop = self.k * HOP - self._buf_start
            self._buf = self._buf[drop:]
            self._buf_start += drop
        return self._emit(self.k - 1 - int(round(self.cfg.delay_s / PROSODY_FRAME_STEP)))

    def flush(self) -> tuple[np.ndarray, np.ndarray]:
        """End of stream: close a pending call and return every remaining frame decision."""
        if self._mode == "trough" and self._peak_k >= 0:
            self._close_call(self._ext_k, self._ext_db, self.k - 1)
        self._mode = "peak"
        self._peak_k = -1
        return self._emit(self.k - 1)

    def take_new(self) -> list[Laugh]:
        """The laughs detected (or extended) since the previous call."""
        out, self._new = self._new, []
        return out

    # ------------------------------------------------------------------ frames
    @staticmethod
    def time_of(k: int) -> float:
        """Centre time (s) of frame ``k``."""
        return (k * HOP + WIN / 2) / SAMPLE_RATE

    @staticmethod
    def known_of(k: int) -> float:
        """Stream time (s) at which frame ``k`` is known (its last sample)."""
        return (k * HOP + WIN) / SAMPLE_RATE

    def _frame(self, k: int, level: float, bands: np.ndarray) -> None:
        c = self.cfg
        self._level.append(level)
        self._bands.append(bands)
        self._flag.append(False)
        self._loud = max(self._loud - c.loud_decay_db_per_s * PROSODY_FRAME_STEP, level)
        if self._mode == "peak":
            if level < self._trough_db:          # a deeper trough before the next peak
                self._trough_k, self._trough_db = k, level
                self._ext_k, self._ext_db = k, level
            elif level > self._ext_db:
                self._ext_k, self._ext_db = k, level
            if level <= self._ext_db - c.dip_db:
                self._peak_k, self._peak_db = self._ext_k, self._ext_db
                self._mode = "trough"
                self._ext_k, self._ext_db = k, level
        else:
            if level < self._ext_db:
                self._ext_k, self._ext_db = k, level
            timeout = (k - self._peak_k) * PROSODY_FRAME_STEP > c.ioi_max_s
            if level >= self._ext_db + c.dip_db or timeout:
                tk, tdb = self._ext_k, self._ext_db
                self._close_call(tk, tdb, k)
                self._mode = "peak"
                self._peak_k = -1
                self._trough_k, self._trough_db = tk, tdb
                hi = max(range(tk, k + 1), key=lambda j: self._level[j - self._k0])
                self._ext_k, self._ext_db = hi, self._level[hi - self._k0]
        # keep about 3 s of frames behind the oldest undecided one
        keep_from = min(self._k_out, k - 300)
        while self._k0 < keep_from:
            self._level.popleft()
            self._bands.popleft()
            self._flag.popleft()
            self._k0 += 1

    def _lvl(self, k: int) -> float:
        return self._level[k - self._k0]

    def _close_call(self, k_trough: int, trough_db: float, k_now: int) -> None:
        """The pending peak is a call between ``self._trough_k`` and ``k_trough``."""
        c = self.cfg
        kp, pdb = self._peak_k, self._peak_db
        k_before = max(self._trough_k, self._k0)
        k_after = max(k_trough, kp)
        depth = min(pdb - self._lvl(k_before) if k_before < kp else 0.0,
                    pdb - trough_db if k_after > kp else 0.0)
        on = kp
        while on - 1 > k_before and self._lvl(on - 1) >= pdb - c.call_db:
            on -= 1
        off = kp
        while off + 1 < k_after and self._lvl(off + 1) >= pdb - c.call_db:
            off += 1
        top = [j for j in range(on, off + 1) if self._lvl(j) >= pdb - 3.0]
        b = np.mean([self._bands[j - self._k0] for j in top], axis=0)
        shape = b - b.mean()
        pw = 10.0 ** (b / 10.0)
        high = float(pw[5:].sum() / max(pw.sum(), _FLOOR))     # bands above 3 kHz
        dur = (off - on + 1) * PROSODY_FRAME_STEP
        ok = (pdb > c.floor_db and pdb >= self._loud - c.rel_db
              and c.dur_min_s - 1e-9 <= dur <= c.dur_max_s + 1e-9 and depth >= c.depth_db
              and high <= c.high_share)
        call = _Call(kp, pdb, on, off, depth, shape, ok, self.known_of(k_now))
        self._calls.append(call)
        if len(self._calls) > 32:
            del self._calls[:16]
        self._judge()

    def _judge(self) -> None:
        """Whether the newest call makes (or continues) a laugh."""
        c = self.cfg
        calls = self._calls
        run = 0
        for i in range(len(calls) - 1, -1, -1):
            if not calls[i].ok:
                break
            if i < len(calls) - 1:
                ioi = (calls[i + 1].k_peak - calls[i].k_peak) * PROSODY_FRAME_STEP
                if not (c.ioi_min_s - 1e-9 <= ioi <= c.ioi_max_s + 1e-9):
                    break
            run += 1
        n = max(int(c.min_calls), 2)
        if run < n:
            self._active = False
            return
        last = calls[-n:]
        iois = np.diff([x.k_peak for x in last]) * PROSODY_FRAME_STEP
        med = float(np.median(iois))
        regular = bool(np.all(np.abs(iois - med) <= c.ioi_tol * med + 1e-9))
        shapes = np.array([x.shape for x in last])
        dist = np.sqrt(np.mean((shapes - shapes.mean(axis=0)) ** 2, axis=1))
        constant = bool(np.all(dist <= c.spec_db))
        peaks = [x.peak_db for x in last]
        even = max(peaks) - min(peaks) <= c.level_spread_db
        if not (regular and constant and even):
            self._active = False
            return
        new = last[-1]
        if self._active and self.laughs:
            old = self.laughs[-1]
            lg = Laugh(old.start, self.time_of(new.k_off) + 0.5 * PROSODY_FRAME_STEP,
                       old.t_detected, old.n_calls + 1, old.rate_hz)
            self.laughs[-1] = lg
            marks = (last[-2].k_off, new.k_off)
        else:
            first = last[0]
            lg = Laugh(self.time_of(first.k_on) - 0.5 * PROSODY_FRAME_STEP,
                       self.time_of(new.k_off) + 0.5 * PROSODY_FRAME_STEP, new.t_known, n,
                       1.0 / med)
            self.laughs.append(lg)
            marks = (first.k_on, new.k_off)
        self._active = True
        self._new.append(lg)
        for j in range(max(marks[0], self._k_out, self._k0), marks[1] + 1):
            self._flag[j - self._k0] = True

    def _emit(self, k_last: int) -> tuple[np.ndarray, np.ndarray]:
        """Decisions of frames ``_k_out .. k_last``."""
        if k_last < self._k_out:
            return np.zeros(0), np.zeros(0, bool)
        ks = np.arange(self._k_out, k_last + 1)
        flags = np.array([self._flag[j - self._k0] for j in ks.tolist()], bool)
        self._k_out = k_last + 1
        return (ks * HOP + WIN / 2) / SAMPLE_RATE, flags


def detect_laughter(x: np.ndarray, config: LaughterConfig | None = None
                    ) -> tuple[np.ndarray, np.ndarray, list[Laugh]]:
    """Whole 16 kHz signal (n,) -> (frame centre times (m,) s, laugh flags (m,), laughs):
    the streaming detector fed everything at once (identical to any streaming)."""
    det = LaughterDetector(config)
    t1, f1 = det.push(x)
    t2, f2 = det.flush()
    return np.concatenate([t1, t2]), np.concatenate([f1, f2]), list(det.laughs)
