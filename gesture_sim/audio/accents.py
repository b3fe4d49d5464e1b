"""Causal pitch-accent (stress) detection, phrase boundaries and vocal energy.

One detector shared by the body's synchrony (strokes on stressed syllables) and the face and
head signals (RUTH batons, brows, blinks). It reads the 10 ms frames of a
:class:`~gesture_sim.audio.prosody.ProsodyTracker` as they are analysed and decides frame by
frame, so it is exactly as causal as the tracker and its results do not depend on the audio
block size.

Running statistics (speaker-relative and gain-invariant; :class:`~gesture_sim.running.RunningStat`)
    * intensity ``I`` (dB) over non-silent frames: mean ``mu_I`` and SD ``sd_I``; the mean starts
      at the first speech frame (no absolute prior, so gain cannot matter), the SD from a prior
      of ``prior_sd_db`` worth ``prior_frames`` frames; afterwards an exponentially weighted
      average with a memory of ``memory_s`` seconds of speech;
    * F0 in semitones over voiced frames: ``mu_F``, ``sd_F`` in the same way (prior SD
      ``prior_sd_st``);
    * nucleus peak prominence: mean ``mu_P`` and SD ``sd_P`` of the prominence at every confirmed
      syllable-nucleus peak (prior ``prior_peak_mean`` ± ``prior_peak_sd``, worth
      ``prior_peaks`` peaks, memory ``peak_memory`` peaks).

Prominence of frame k (z units)
    ``p_k = zI + w_rise * zR + w_f0 * max(zF, 0)`` with ``zI = (I_k - mu_I) / sd_I``,
    ``zR = (I_k - max(trough, mu_I - 2 sd_I)) / sd_I`` (the rise from the last intensity trough,
    a pause counting as a trough at ``mu_I - 2 sd_I``) and ``zF = (F0_st - mu_F) / sd_F`` on
    voiced frames (0 when unvoiced). Statistics are those *before* frame k is absorbed.

Syllable nuclei
    Intensity peaks separated by dips of ``dip_db`` (hysteresis, as in the prosody tracker): a
    peak is confirmed once the intensity has fallen ``dip_db`` below it, or at silence; the
    next rise starts once it has risen ``dip_db`` above the trough.

Accents (emitted on the rising edge)
    While a nucleus is rising (intensity within ``edge_db`` of its running maximum), the first
    frame whose prominence reaches ``mu_P + threshold_sd * sd_P`` and whose
    ``zI >= min_z_intensity`` emits an :class:`~gesture_sim.contracts.Accent`; one per
    nucleus, none in the first ``warmup_s`` of speech of a stream (empty statistics).
    ``threshold_sd = -0.5`` (a nucleus about as prominent as this speaker's typical one or
    more) was chosen on BEAT2 take 1 as the setting of -1, -0.5, 0, 0.5 with the largest F1
    margin over chance against lexical stress; takes 2-4 are held out
    (BENCHMARKS.md, "Speech front end").
    ``t`` = that frame's centre plus ``peak_lead_s`` (the median remaining rise to the
    intensity peak, 20 ms on take 1), never later than ``t_emitted``; ``t_emitted`` = the time
    the frame became known (:meth:`ProsodyTracker.frames_since`); ``strength`` = ``p_k`` at
    the emitting frame (z units, at least the threshold; the excess grows with steeper rises
    and higher F0).

Boundaries
    ``"pause"``: speech followed by ``pause_s`` of silent frames; ``t`` = the end of the last
    speech frame, emitted when the pause has lasted ``pause_s``. A stretch between pauses that
    never reaches ``min_phrase_z`` (a breath, a noise) is no phrase and gets no boundary.
    ``"end"``: speech still running when :meth:`AccentDetector.finish` is called (the end of
    the stream).

Vocal energy (the style dial's input, Gesture Controllers style from the voice)
    Over speech frames only, exponential averages with time constant ``energy_window_s``
    ("short") and ``memory_s`` ("long", a cumulative mean until that much speech has been
    heard) of the intensity ``I``, of the squared F0 deviation from ``mu_F`` (voiced frames)
    and of the nucleus rate (nuclei per speech second). Then

    ``raw = (I_short - I_long) / energy_db_scale + log2(sqrt(varF_short / varF_long))
    + log2(rate_short / rate_long)`` and ``energy = tanh(raw / 2)`` in (-1, 1):
    louder, wider in pitch or faster than this speaker's usual gives a positive value, quieter,
    flatter or slower a negative one. It is 0 until ``energy_warmup_s`` of speech has been heard;
    in silence it is not updated and decays towards 0 with time constant ``energy_decay_s``
    (after the first ``pause_s``). Each term is clipped to ±3.

All times are seconds on the stream clock; intensities dB; F0 semitones (re 100 Hz).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.audio.prosody import ProsodyConfig, ProsodyFrames, ProsodyTracker
from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE, Accent, Boundary, Syllable
from gesture_sim.running import RunningStat
from gesture_sim.units import semitones

__all__ = ["AccentAnalysis", "AccentConfig", "AccentDetector", "analyze_accents",
           "detect_accents"]

DT = PROSODY_FRAME_STEP


@dataclass(frozen=True)
class AccentConfig:
    """Settings of :class:`AccentDetector` (s, dB, semitones, z units). See the module text.

    Attributes:
        w_rise, w_f0: weights of the rise and F0 terms of the prominence (intensity weight 1).
        threshold_sd: accent threshold in SDs of the nucleus peak prominence above its mean.
        min_z_intensity: an accent's frame must be at least this loud (z of intensity).
        dip_db: intensity dip that separates syllable nuclei.
        edge_db: a frame counts as the rising edge while within this of the nucleus maximum.
        peak_lead_s: added to the emitting frame's time for ``Accent.t`` (expected rise left).
        memory_s: memory of the running intensity/F0 statistics, seconds of speech.
        prior_frames: how many frames the prior SDs are worth.
        prior_sd_db, prior_sd_st: prior SDs of intensity (dB) and F0 (semitones).
        prior_peak_mean, prior_peak_sd, prior_peaks, peak_memory: nucleus peak statistics.
        pause_s: silence that makes a phrase boundary (and the ``speaking`` hang-over).
        min_phrase_z: a phrase needs a frame at least this loud (intensity z) to get a
            boundary; quieter stretches between pauses (breaths, noises) get none.
        energy_window_s: time constant of the short-term energy averages (s of speech).
        energy_warmup_s: speech heard before ``energy`` moves from 0.
        energy_decay_s: time constant of the energy's decay in silence.
        energy_db_scale: loudness change (dB) that counts as one unit of the energy sum.
        warmup_s: speech heard (s) before the first accent can be emitted.
    """

    w_rise: float = 0.5
    w_f0: float = 0.5
    threshold_sd: float = -0.5
    min_z_intensity: float = 0.0
    dip_db: float = 2.0
    edge_db: float = 1.0
    peak_lead_s: float = 0.02
    memory_s: float = 30.0
    prior_frames: float = 50.0
    prior_sd_db: float = 6.0
    prior_sd_st: float = 3.0
    prior_peak_mean: float = 2.3
    prior_peak_sd: float = 1.0
    prior_peaks: float = 5.0
    peak_memory: float = 100.0
    pause_s: float = 0.2
    min_phrase_z: float = -1.0
    energy_window_s: float = 2.0
    energy_warmup_s: float = 1.0
    energy_decay_s: float = 2.0
    energy_db_scale: float = 6.0
    warmup_s: float = 0.15


class _Ewmas:
    """Two exponential averages of the values they are fed, time constants ``tau_short`` and
    ``tau_long`` values: each a cumulative mean until its ``tau`` values, then weight
    ``1 / tau``; NaN until the first value. Each is the mean of ``RunningStat(mean=nan,
    min_weight=1 / tau, location="first")`` to the last bit, without the variance nobody reads
    (three pairs run per speech frame)."""

    __slots__ = ("floor_short", "floor_long", "short", "long", "n")

    def __init__(self, tau_short: float, tau_long: float) -> None:
        self.floor_short, self.floor_long = 1.0 / tau_short, 1.0 / tau_long
        self.short = self.long = math.nan
        self.n = 0

    def update(self, x: float) -> None:
        self.n += 1
        if self.n == 1:
            self.short = self.long = x
            return
        w = 1.0 / self.n
        ws = self.floor_short if self.floor_short > w else w
        wl = self.floor_long if self.floor_long > w else w
        self.short += ws * (x - self.short)
        self.long += wl * (x - self.long)


def _clip3(v: float) -> float:
    """``max(-3.0, min(3.0, v))`` (NaN gives 3.0, as that does)."""
    v = v if v < 3.0 else 3.0
    return v if v > -3.0 else -3.0


class AccentDetector:
    """Causal accent, boundary and energy detector over a :class:`ProsodyTracker`'s frames.

    Usage (once per audio block, after ``tracker.push(block)``)::

        det = AccentDetector()
        accents, boundaries = det.update(tracker)   # frames analysed since the last call
        det.speaking, det.silence_s, det.level, det.energy
        accents, boundaries = det.finish(tracker)   # after tracker.flush(): end of stream

    Attributes (read-only meaning; updated by :meth:`update`):
        speaking: voice activity at the latest analysed frame (silent for less than
            ``pause_s``; False before any speech).
        silence_s: seconds of consecutive silent frames up to the latest analysed frame
            (0 while the latest frame is speech).
        level: intensity z of the latest speech frame against the running statistics
            (gain-invariant; held through silence, 0 before speech); clipped to ±4.
        energy: vocal energy in (-1, 1) (see the module text); ``energy_terms`` its three terms.
        t_frame: centre time (s) of the latest analysed frame (NaN before any).
        accents, boundaries: everything emitted so far, in emission order.
    """

    def __init__(self, config: AccentConfig | None = None) -> None:
        self.cfg = config or AccentConfig()
        self.reset()

    def reset(self) -> None:
        """Forget everything (a new stream, a new speaker)."""
        c = self.cfg
        mem = c.memory_s / DT
        self._k = 0  # next frame index to consume
        # intensity (dB) and F0 (st): the mean from the first frame, the SD from a prior
        self._I = RunningStat(var=c.prior_sd_db**2, prior=c.prior_frames, min_weight=1.0 / mem,
                              location="first", var_floor=1e-6)
        self._F = RunningStat(var=c.prior_sd_st**2, prior=c.prior_frames, min_weight=1.0 / mem,
                              location="first", var_floor=1e-6)
        # nucleus peak prominence (z units): mean and SD from a prior
        self._P = RunningStat(mean=c.prior_peak_mean, var=c.prior_peak_sd**2,
                              prior=c.prior_peaks, min_weight=1.0 / c.peak_memory,
                              var_floor=1e-6)
        # energy: exponential averages (``mean``; NaN until the first value) over speech frames
        tau = c.energy_window_s / DT
        self._I_avg = _Ewmas(tau, mem)           # intensity (dB)
        self._varF_avg = _Ewmas(tau, mem)        # squared F0 deviation (st^2)
        self._rate_avg = _Ewmas(tau, mem)        # nuclei per speech second
        self._speech_frames = 0
        # nucleus state
        self._in_speech = False  # since the last pause boundary
        self._phrase_z = -math.inf  # loudest intensity z of the phrase so far
        self._silent_run = 0
        self._prev_silent = True
        self._falling = False
        self._peak = -math.inf
        self._peak_p = -math.inf
        self._trough = -math.inf
        self._armed = False
        self._nucleus_open = False
        self._speech_end = math.nan
        self._rate_events = 0
        self.level = 0.0
        self.energy = 0.0
        self.energy_terms: dict[str, float] = {"loudness": 0.0, "pitch_range": 0.0,
                                               "rate": 0.0}
        self._energy_speech = 0.0
        self.t_frame = math.nan
        self.accents: list[Accent] = []
        self.boundaries: list[Boundary] = []
        self._history: deque[tuple[float, bool, float, float]] = deque(maxlen=6000)
        self._state = (False, 0.0, 0.0)

    # ------------------------------------------------------------------ public API

    def state_at(self, t: float) -> tuple[bool, float, float]:
        """``(speaking, silence_s, energy)`` as known at stream time ``t`` (s): the state after
        the last frame whose ``t_known <= t`` — what a causal consumer stepping at ``t`` may use
        even when the audio has already been analysed further (a large block). Calls must come
        with non-decreasing ``t``."""
        h = self._history
        while h and h[0][0] <= t + 1e-9:
            _, speaking, silence, energy = h.popleft()
            self._state = (speaking, silence, energy)
        return self._state

    @property
    def speaking(self) -> bool:
        """Voice activity now: speech heard and silent for less than ``pause_s``."""
        return self._speech_frames > 0 and self._silent_run * DT < self.cfg.pause_s - 1e-9

    @property
    def silence_s(self) -> float:
        """Seconds of consecutive silent frames up to the latest analysed frame."""
        return self._silent_run * DT

    def update(self, tracker: ProsodyTracker) -> tuple[list[Accent], list[Boundary]]:
        """Consume the frames ``tracker`` has analysed since the last call.

        Returns:
            (accents, boundaries) emitted by those frames, in time order.
        """
        acc: list[Accent] = []
        bnd: list[Boundary] = []
        if tracker.n_frames <= self._k:
            return acc, bnd
        append, step, pause = self._history.append, self._step, self.cfg.pause_s - 1e-9
        for t, i_db, f0, silent, t_known in tracker.frame_rows(self._k):
            step(t, i_db, f0, silent, t_known, acc, bnd)
            silence = self._silent_run * DT           # (speaking and silence_s, inlined)
            append((t_known, self._speech_frames > 0 and silence < pause, silence,
                    self.energy))
        self._k = tracker.n_frames
        self.accents.extend(acc)
        self.boundaries.extend(bnd)
        return acc, bnd

    def finish(self, tracker: ProsodyTracker) -> tuple[list[Accent], list[Boundary]]:
        """End of stream (call after ``tracker.flush()``): consume the last frames and close
        an open phrase with an ``"end"`` boundary (``t_emitted`` = the last frame's known
        time)."""
        acc, bnd = self.update(tracker)
        if self._in_speech and self._phrase_z >= self.cfg.min_phrase_z:
            _, known = tracker.frames_since(max(self._k - 1, 0))
            t_em = float(known[-1]) if len(known) else self._speech_end
            b = Boundary(t=self._speech_end, t_emitted=max(t_em, self._speech_end), kind="end")
            bnd.append(b)
            self.boundaries.append(b)
            self._in_speech = False
        return acc, bnd

    # ------------------------------------------------------------------ internals

    def _confirm_peak(self) -> None:
        """A nucleus peak is confirmed: absorb its prominence, count the syllable."""
        if self._nucleus_open and math.isfinite(self._peak_p):
            self._P.update(self._peak_p)
            self._rate_events += 1
        self._nucleus_open = False

    def _step(self, t: float, i_db: float, f0_hz: float, silent: bool, known: float,
              acc: list[Accent], bnd: list[Boundary]) -> None:
        c = self.cfg
        self.t_frame = t
        self._rate_events = 0
        if silent or not math.isfinite(i_db):
            self._silent_run += 1
            if not self._prev_silent:
                self._confirm_peak()
                self._falling, self._armed = False, False
            self._prev_silent = True
            if self._in_speech and self._silent_run * DT >= c.pause_s - 1e-9:
                if self._phrase_z >= c.min_phrase_z:  # else a breath or a noise: no phrase
                    bnd.append(Boundary(t=self._speech_end, t_emitted=known, kind="pause"))
                self._in_speech = False
                self._phrase_z = -math.inf
            if self._silent_run * DT > c.pause_s:
                self.energy *= math.exp(-DT / c.energy_decay_s)
            return
        # ---- a speech frame (the running statistics' z and sd inlined: this runs per frame)
        I, F = self._I, self._F
        if I.n == 0:
            I.mean = i_db  # the speaker's level starts at the first speech frame
        if self._prev_silent:  # onset after silence: the pause is the trough
            self._trough, self._falling, self._armed = -math.inf, False, True
            self._peak, self._peak_p, self._nucleus_open = -math.inf, -math.inf, True
        self._prev_silent = False
        self._silent_run = 0
        self._in_speech = True
        self._speech_end = round(t + DT, 9)
        voiced = math.isfinite(f0_hz) and f0_hz > 0
        st = semitones(f0_hz, 100.0) if voiced else math.nan
        if voiced and F.n == 0:
            F.mean = st
        zf = (st - F.mean) / math.sqrt(max(F.var, F.var_floor)) if voiced and F.n > 0 else 0.0
        # prominence p: intensity z, the rise from the trough (z units) and the F0 z
        mu, sd = I.mean, math.sqrt(max(I.var, I.var_floor))
        zi = (i_db - mu) / sd
        zr = (i_db - max(self._trough, mu - 2.0 * sd)) / sd
        p = zi + c.w_rise * max(zr, 0.0) + c.w_f0 * max(zf, 0.0)
        self.level = max(-4.0, min(4.0, zi))
        if I.n > 0:
            self._phrase_z = max(self._phrase_z, zi)
        # nucleus peak / trough hysteresis
        if not self._falling:
            if i_db > self._peak:
                self._peak = i_db
            elif i_db <= self._peak - c.dip_db:
                self._confirm_peak()
                self._falling, self._trough, self._armed = True, i_db, False
        else:
            if i_db < self._trough:
                self._trough = i_db
            elif i_db >= self._trough + c.dip_db:
                self._falling, self._armed, self._nucleus_open = False, True, True
                self._peak, self._peak_p = i_db, -math.inf
        edge = not self._falling and i_db >= self._peak - c.edge_db and zi >= c.min_z_intensity
        if edge:  # the nucleus's prominence: its largest on the edge frames
            self._peak_p = max(self._peak_p, p)
        # accent on the rising edge
        if (self._armed and edge and p >= self._P.mean + c.threshold_sd * self._P.sd
                and self._speech_frames * DT >= c.warmup_s - 1e-9):
            t_acc = min(round(t + c.peak_lead_s, 9), known)
            acc.append(Accent(t=t_acc, t_emitted=known, strength=float(p), pitch_z=float(zf)))
            self._armed = False
        # statistics after the decision (causal: frame k is judged against frames < k)
        I.update(i_db)
        if voiced:
            F.update(st)
        self._speech_frames += 1
        self._update_energy(i_db, st)

    def _update_energy(self, i_db: float, st: float) -> None:
        c = self.cfg
        I, varF, rate = self._I_avg, self._varF_avg, self._rate_avg
        I.update(i_db)
        if math.isfinite(st):
            varF.update((st - self._F.mean) ** 2)
        rate.update(self._rate_events / DT)  # nuclei per speech second, this frame
        if self._speech_frames * DT < c.energy_warmup_s:
            self.energy = 0.0
            return
        zl = (I.short - I.long) / c.energy_db_scale
        vs, vl = varF.short, varF.long
        rp = (0.5 * math.log2(max(vs, 0.01) / max(vl, 0.01))
              if math.isfinite(vs) and math.isfinite(vl) else 0.0)
        rs, rl = rate.short, rate.long
        rr = math.log2(max(rs, 0.1) / max(rl, 0.1))
        zl, rp, rr = _clip3(zl), _clip3(rp), _clip3(rr)
        self.energy_terms = {"loudness": zl, "pitch_range": rp, "rate": rr}
        self.energy = math.tanh((0 + zl + rp + rr) / 2.0)      # as sum() adds them


# -------------------------------------------------------------------------------- offline


@dataclass
class AccentAnalysis:
    """Result of :func:`analyze_accents`.

    Attributes:
        accents, boundaries: in emission order.
        times: frame centres (s), shape (n,).
        energy, level: the detector's ``energy`` and ``level`` after each frame, shape (n,).
        speaking: the detector's ``speaking`` after each frame, bool (n,).
        syllables: the tracker's syllables, in emission order.
        frames: the tracker's frames.
    """

    accents: list[Accent]
    boundaries: list[Boundary]
    times: np.ndarray
    energy: np.ndarray
    level: np.ndarray
    speaking: np.ndarray
    syllables: list[Syllable] = field(default_factory=list)
    frames: ProsodyFrames | None = None


def analyze_accents(samples: np.ndarray, sample_rate: int = SAMPLE_RATE,
                    config: AccentConfig | None = None,
                    prosody_config: ProsodyConfig | None = None,
                    block_size: int | None = None) -> AccentAnalysis:
    """Run the tracker and the detector causally over a whole mono signal (n,).

    The signal is resampled to 16 kHz when ``sample_rate`` differs. ``block_size=None``
    pushes it as one block (results are the same for any block size).
    """
    from gesture_sim.audio.sources import iter_blocks, resample_to_16k

    x = np.asarray(samples, dtype=np.float32).reshape(-1)
    if sample_rate != SAMPLE_RATE:
        x = resample_to_16k(x, int(sample_rate)).astype(np.float32)
    tracker = ProsodyTracker(prosody_config)
    tracker.expect(x)
    det = AccentDetector(config)
    energy: list[float] = []
    level: list[float] = []
    speaking: list[bool] = []

    def run(final: bool) -> None:
        # frame-by-frame so that the per-frame traces are exact
        while det._k < tracker.n_frames:
            frames, known = tracker.frames_since(det._k)
            det._step(float(frames.times[0]), float(frames.intensity_db[0]),
                      float(frames.f0_hz[0]), bool(frames.silent[0]), float(known[0]),
                      det.accents, det.boundaries)
            det._k += 1
            energy.append(det.energy)
            level.append(det.level)
            speaking.append(det.speaking)
        if final:
            det.finish(tracker)

    syllables = []
    for block in iter_blocks(x, block_size):
        syllables.extend(tracker.push(block))
        run(False)
    syllables.extend(tracker.flush())
    run(True)
    frames = tracker.frames()
    return AccentAnalysis(list(det.accents), list(det.boundaries), frames.times,
                          np.array(energy), np.array(level), np.array(speaking, dtype=bool),
                          syllables, frames)


def detect_accents(samples: np.ndarray, sample_rate: int = SAMPLE_RATE,
                   config: AccentConfig | None = None,
                   prosody_config: ProsodyConfig | None = None,
                   ) -> tuple[list[Accent], list[Boundary]]:
    """The accents and boundaries :class:`AccentDetector` emits over a whole mono signal (n,)
    (the same causal code as streaming; see :func:`analyze_accents`)."""
    a = analyze_accents(samples, sample_rate, config, prosody_config)
    return a.accents, a.boundaries
