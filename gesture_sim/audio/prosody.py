"""Causal prosody tracking: F0 and intensity per 10 ms frame, online syllable segmentation.

Follows Levine 2009 §3.2–3.3 (digest §2.1–2.2) and Gesture Controllers §5.2:

* **Frames.** Frame ``k`` is centred at ``t_k = k * PROSODY_FRAME_STEP`` (s). Its F0 comes from
  Praat's autocorrelation pitch (Boersma 1993; ``parselmouth`` ``Sound.to_pitch_ac``, floor
  75 Hz, ceiling 500 Hz, window 3 periods of the floor = 40 ms) and its intensity from Praat's
  squared-signal Gaussian-window intensity (``Sound.to_intensity``, minimum pitch 100 Hz, i.e. a
  64 ms window; dB re 2e-5, full-scale sine = 91 dB). Audio before the stream start counts as
  silence.
* **Causal batches.** Frames are analysed in fixed batches of ``batch_frames`` frames aligned to
  absolute frame indices (batch ``j`` = frames ``j*B .. j*B+B-1``), each from one audio window
  that reaches ``context_frames`` frames back (history for Praat's pitch path finder) and half
  an analysis window past the batch's last frame. A frame's value therefore depends only on the
  audio, never on how it was cut into blocks: streaming with any block size and whole-file
  analysis give identical frames and syllables. A batch is computed as soon as its window has
  arrived, so the frame look-ahead is half the 64 ms intensity window plus the batch length.
  When the whole stream is known ahead (a file: :meth:`ProsodyTracker.expect`), each frame's
  pitch candidates are analysed once and the batches' path finding runs over them
  (:mod:`gesture_sim.audio.praat_pitch`), the intensity comes from two long Praat calls
  (:mod:`gesture_sim.audio.praat_intensity`), the high-pass filter runs once over the file and
  the voice detector's network over many windows at once: the same frames and syllables, bit
  for bit, at the same times, for half the work of the live path.
* **Syllables.** Intensity peaks separated by troughs: the previous peak is confirmed once the
  intensity has fallen ``min_dip_db`` below it; the trough after it is confirmed (and the
  syllable ending there emitted) once the intensity has risen ``min_dip_db`` above the trough's
  minimum. Syllables shorter than ``min_syllable_s`` are not split off (the peaks merge, the
  thesis's minimum peak distance). A frame is silent when its intensity is below
  ``max(level - silence_rel_db, noise + noise_margin_db, silence_floor_db)``, where ``level``
  is a running speech level (peak follower decaying at ``level_decay_db_per_s``) and ``noise``
  a running noise floor (minimum statistics: a minimum follower, rising at
  ``noise_rise_db_per_s``, of the mean intensity over the last ``noise_window_s``, so that the
  pauses of a noisy recording are silence too, while a stop closure or the trough between two
  syllables is too short to set it). The noise term counts only once the loudest frame heard
  lies ``noise_min_range_db`` or more above the floor, so a signal without any pause has no
  noise floor; silence closes a syllable.
  A syllable needs a peak at least ``min_dip_db`` above the silence threshold. F0 is defined
  only on non-silent frames.
* **Per syllable**: mean F0 (Hz) over voiced frames (``None`` when fewer than
  ``min_voiced_share`` of its frames are voiced), mean intensity (dB) over its frames, length.

``t_emitted`` is the stream time of the last audio sample the decision needed (the end of the
window of the batch that confirmed it): the algorithm's own latency, the same for any block size.
A live source adds at most one block of buffering on top.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.audio.praat_intensity import IntensityAhead, praat_intensity
from gesture_sim.audio.praat_pitch import HOP, PitchAhead, PitchSettings, batch_f0
from gesture_sim.audio.praat_pitch import PAD as _PAD
from gesture_sim.audio.vad import VadConfig, VoiceActivityDetector
from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE, AudioBlock, Syllable
from gesture_sim.errors import GestureSimError


@dataclass(frozen=True)
class ProsodyConfig:
    """Settings of the tracker (Hz, dB, seconds, frames).

    Attributes:
        pitch_floor_hz, pitch_ceiling_hz: Praat AC pitch search range.
        intensity_min_pitch_hz: Praat intensity "minimum pitch"; window = 6.4 / this (s).
        voicing_threshold: Praat's voicing threshold (0.45 default).
        batch_frames: frames analysed per Praat call (latency vs. speed).
        context_frames: history frames analysed with each batch (pitch path continuity).
        highpass_hz: causal 2nd-order Butterworth high-pass that removes DC and rumble (0: off).
        min_dip_db: peak-to-trough and trough-to-peak depth that separates syllables.
        min_syllable_s: shortest syllable split off at a trough.
        silence_rel_db: silence is this far below the running speech level.
        silence_floor_db: absolute silence floor (dB re 2e-5; full-scale sine = 91 dB).
        noise_margin_db: silence is also anything less than this above the running noise floor
            (the lowest recent ``noise_window_s`` mean intensity); in clean recordings the floor
            lies far below ``level - silence_rel_db`` and changes nothing.
        noise_rise_db_per_s: how fast the noise floor may rise (it falls at once).
        noise_window_s: the noise floor follows the mean intensity over this window (s).
        noise_min_range_db: the noise floor counts once the loudest frame heard is at least
            this far above it (a pause-free signal's troughs are no noise floor).
        level_decay_db_per_s: how fast the running speech level forgets a loud passage.
        min_voiced_share: share of voiced frames for a syllable to get an F0.
        vad: the voice-activity detector whose "no voice" makes a frame silent whatever its
            level (:mod:`gesture_sim.audio.vad`; ``VadConfig(engine="off")``: energy alone).
        voice_needs_f0: a run of frames the detector calls voice counts only from its first
            frame with an F0 on (frames of the same 50 ms batch before it are counted too): a
            breath or a click, which a detector can take for a voice, has no pitch.
    """

    pitch_floor_hz: float = 75.0
    pitch_ceiling_hz: float = 500.0
    intensity_min_pitch_hz: float = 100.0
    voicing_threshold: float = 0.45
    batch_frames: int = 5
    context_frames: int = 6
    highpass_hz: float = 40.0
    min_dip_db: float = 2.0
    min_syllable_s: float = 0.08
    silence_rel_db: float = 25.0
    silence_floor_db: float = 30.0
    noise_margin_db: float = 5.0
    noise_rise_db_per_s: float = 1.0
    noise_window_s: float = 0.2
    noise_min_range_db: float = 20.0
    level_decay_db_per_s: float = 1.0
    min_voiced_share: float = 0.3
    vad: VadConfig = field(default_factory=VadConfig)
    voice_needs_f0: bool = True

    @property
    def pitch_window(self) -> int:
        """Praat AC pitch analysis window (samples): 3 periods of the floor."""
        return int(round(3.0 / self.pitch_floor_hz * SAMPLE_RATE))

    @property
    def intensity_window(self) -> int:
        """Praat intensity physical window (samples): 6.4 / minimum pitch."""
        return int(round(6.4 / self.intensity_min_pitch_hz * SAMPLE_RATE))

    @property
    def lookahead(self) -> int:
        """Samples needed past a frame centre before the frame can be computed."""
        return max(self.pitch_window, self.intensity_window) // 2 + _PAD

    @property
    def pitch(self) -> PitchSettings:
        """The pitch analysis's own settings."""
        return PitchSettings(self.pitch_floor_hz, self.pitch_ceiling_hz, self.voicing_threshold)


class _Highpass:
    """Stateful second-order-sections filter of a stream (float64): the same arithmetic as
    ``scipy.signal.sosfilt(sos, x, zi=zi)`` block after block (it calls scipy's own kernel),
    without that function's per-call argument checks and array-namespace dispatch, which cost
    more than filtering a 10 ms block."""

    def __init__(self, sos: np.ndarray) -> None:
        self.sos = np.ascontiguousarray(sos, dtype=np.float64)
        self.zi = np.zeros((1, len(self.sos), 2))     # the kernel's (batch, sections, 2) state
        try:
            from scipy.signal._sosfilt import _sosfilt
        except ImportError:  # pragma: no cover - scipy moved its kernel: the public function
            _sosfilt = None
        self._kernel = _sosfilt

    def __call__(self, x: np.ndarray, own: bool = False) -> np.ndarray:
        """Filter the next samples ``x`` (n,); with ``own`` the caller's array may be
        overwritten."""
        if self._kernel is None:  # pragma: no cover
            from scipy.signal import sosfilt

            y, zf = sosfilt(self.sos, x, zi=self.zi[0])
            self.zi[0] = zf
            return y
        y = (np.asarray if own else np.array)(x, dtype=np.float64, order="C").reshape(1, -1)
        self._kernel(self.sos, y, self.zi)
        return y.reshape(-1)


@dataclass(frozen=True)
class ProsodyFrames:
    """Per-frame prosody curves, all shape (n,).

    Attributes:
        times: frame centres (s).
        f0_hz: F0 (Hz), NaN where unvoiced or silent.
        intensity_db: intensity (dB re 2e-5).
        silent: whether the frame was below the running silence threshold or had no voice.
        voice: whether the voice-activity detector heard a voice (all True with it off;
            ``None`` where not recorded).
    """

    times: np.ndarray
    f0_hz: np.ndarray
    intensity_db: np.ndarray
    silent: np.ndarray
    voice: np.ndarray | None = None

    @property
    def voiced(self) -> np.ndarray:
        """Bool (n,): frames with a defined F0."""
        return np.isfinite(self.f0_hz)


@dataclass
class _Segmenter:
    """Online intensity peak/trough syllable segmenter (state machine over frames)."""

    cfg: ProsodyConfig
    level: float = -np.inf
    loudest: float = -np.inf
    noise: float = np.inf
    recent: deque = field(init=False)  # the last noise_window_s of intensities (dB)
    in_speech: bool = False
    falling: bool = False  # a peak is confirmed; now tracking the trough after it
    start: int = 0
    peak: float = -np.inf
    trough: float = np.inf
    trough_idx: int = 0
    max_since_trough: float = -np.inf
    peak_threshold: float = -np.inf  # silence threshold when the syllable's peak was set

    def __post_init__(self) -> None:
        c = self.cfg
        n = max(1, int(round(c.noise_window_s / PROSODY_FRAME_STEP)))
        self.recent = deque(maxlen=n)
        # per-frame constants of the (frozen) configuration
        self._decay = c.level_decay_db_per_s * PROSODY_FRAME_STEP
        self._rise = c.noise_rise_db_per_s * PROSODY_FRAME_STEP
        self._min_len = int(round(c.min_syllable_s / PROSODY_FRAME_STEP))

    def threshold(self) -> float:
        c = self.cfg
        noise = (self.noise + c.noise_margin_db
                 if self.loudest - self.noise >= c.noise_min_range_db else -np.inf)
        return max(self.level - c.silence_rel_db, noise, c.silence_floor_db)

    def step(self, k: int, i_db: float, voice: bool = True
             ) -> tuple[bool, list[tuple[int, int]]]:
        """Consume frame ``k`` (intensity dB; ``voice``: the voice-activity detector's
        decision, False makes the frame silent). Returns (silent, closed syllables as
        (start_frame, end_frame_exclusive))."""
        cfg = self.cfg
        if math.isfinite(i_db):
            self.level = max(i_db, self.level - self._decay)
            self.loudest = max(i_db, self.loudest)
            recent = self.recent
            recent.append(i_db)
            if len(recent) == recent.maxlen:
                self.noise = min(sum(recent) / len(recent), self.noise + self._rise)
        thr = self.threshold()
        silent = not (voice and i_db >= thr)
        closed: list[tuple[int, int]] = []
        min_len = self._min_len
        if silent:
            if self.in_speech:
                if k - self.start >= min_len and self.peak >= self.peak_threshold + cfg.min_dip_db:
                    closed.append((self.start, k))
                self.in_speech = False
            return True, closed
        if not self.in_speech:
            self.in_speech, self.falling, self.start = True, False, k
            self.peak, self.peak_threshold = i_db, thr
            return False, closed
        if not self.falling:
            if i_db > self.peak:
                self.peak, self.peak_threshold = i_db, thr
            elif self.peak - i_db >= cfg.min_dip_db:
                self.falling, self.trough, self.trough_idx = True, i_db, k
                self.max_since_trough = i_db
            return False, closed
        # falling: follow the trough, confirm it on a rise of min_dip_db
        if i_db < self.trough:
            self.trough, self.trough_idx, self.max_since_trough = i_db, k, i_db
            return False, closed
        self.max_since_trough = max(self.max_since_trough, i_db)
        if i_db - self.trough >= cfg.min_dip_db:
            if (self.trough_idx - self.start >= min_len
                    and self.peak >= self.peak_threshold + cfg.min_dip_db):
                closed.append((self.start, self.trough_idx))
                self.start = self.trough_idx
                self.peak, self.peak_threshold = self.max_since_trough, thr
            else:  # too short: merge with what follows (minimum peak distance)
                self.peak = max(self.peak, self.max_since_trough)
            self.falling = False
        return False, closed


class ProsodyTracker:
    """Streaming prosody tracker: push :class:`AudioBlock` s, get newly emitted syllables.

    Usage::

        tracker = ProsodyTracker()
        for block in source:
            for syl in tracker.push(block):
                ...
        tail = tracker.flush()           # at end of stream
        times, f0, intensity = tracker.frames().times, ...

    Blocks must be contiguous (each starts where the previous ended); the first may start at
    any time, which becomes the tracker's time origin offset.
    """

    def __init__(self, config: ProsodyConfig | None = None) -> None:
        self.cfg = config or ProsodyConfig()
        c = self.cfg
        if c.batch_frames < 1 or c.context_frames < 0:
            raise GestureSimError("batch_frames must be >= 1 and context_frames >= 0")
        self._t0: float | None = None
        # Audio buffer in absolute samples relative to the stream origin; before 0 is silence.
        self._lookahead = c.lookahead  # (a property of the frozen config: read once)
        self._back = c.context_frames * HOP + self._lookahead + HOP
        self._buf = np.zeros(self._back, dtype=np.float64)
        self._buf_start = -self._back
        self._n_in = 0  # samples received
        self._pending: list[np.ndarray] = []  # received, not yet filtered into _buf
        self._next_batch = 0
        self._seg = _Segmenter(c)
        self._vad = VoiceActivityDetector(c.vad)
        self._voiced_run = False  # the detector's current voice run has had a frame with F0
        self._n_frames = 0
        self._f0_all = np.zeros(0)
        self._int_all = np.zeros(0)
        self._known_all = np.zeros(0)  # per frame: stream time (s) it became known
        self._silent_all = np.zeros(0)  # per frame: 1.0 silent, 0.0 not (NaN: not yet)
        self._voice_all = np.zeros(0)  # per frame: 1.0 voice heard, 0.0 not
        self._syllables: list[Syllable] = []
        self._hp = self._highpass()
        self._pitch = c.pitch
        self._ahead: PitchAhead | None = None
        self._intensity_ahead: IntensityAhead | None = None
        self._expected: tuple[np.ndarray, np.ndarray] | None = None   # raw, high-passed
        self._n_absorbed = 0            # samples moved into the analysis buffer
        self._flushed = False

    def _highpass(self) -> _Highpass | None:
        """A new high-pass filter at rest (None with ``highpass_hz`` 0)."""
        if self.cfg.highpass_hz <= 0:
            return None
        from scipy.signal import butter

        return _Highpass(butter(2, self.cfg.highpass_hz, btype="highpass", fs=SAMPLE_RATE,
                                output="sos"))

    # ---------------------------------------------------------------- public API

    @property
    def syllables(self) -> list[Syllable]:
        """All syllables emitted so far."""
        return list(self._syllables)

    def expect(self, samples: np.ndarray) -> None:
        """The whole stream's samples (float, 16 kHz, from its first sample), known ahead, as
        from a file: each frame's pitch candidates are then analysed once
        (:class:`~gesture_sim.audio.praat_pitch.PitchAhead`), its intensity by two long Praat
        calls (:class:`~gesture_sim.audio.praat_intensity.IntensityAhead`), the high-pass
        filter runs once, and the voice detector's network runs over many windows at once
        (:meth:`VoiceActivityDetector.expect`). Nothing the tracker emits changes, nor when:
        each batch is still decided from the audio pushed so far, and audio pushed that
        differs from these samples is analysed on its own."""
        c = self.cfg
        raw = np.array(samples).reshape(-1)          # a copy: the caller's array may change
        before = c.context_frames * HOP + self._lookahead + HOP
        after = (c.batch_frames + c.context_frames + 2) * HOP + self._lookahead
        audio = np.zeros(before + len(raw) + after)
        y = audio[before: before + len(raw)]
        y[:] = raw                                   # float64, as push converts a block
        hp = self._highpass()
        if hp is not None:
            filtered = hp(y, own=True)               # in place (scipy's kernel)
            if not np.shares_memory(filtered, y):    # pragma: no cover - the public sosfilt
                y[:] = filtered
        self._ahead = PitchAhead(audio, before, c.batch_frames, c.context_frames, self._pitch)
        self._intensity_ahead = IntensityAhead(
            audio, before, c.batch_frames, c.context_frames, c.intensity_window // 2 + _PAD,
            c.intensity_min_pitch_hz)
        self._vad.expect(audio[before:])          # the stream and the zeros a flush pads
        if self._n_in == 0:
            self._expected = (raw, y)

    def push(self, block: AudioBlock) -> list[Syllable]:
        """Feed the next block; return the syllables it completed (may be empty)."""
        if self._flushed:
            raise GestureSimError("prosody tracker already flushed; create a new one")
        x = np.asarray(block.samples, dtype=np.float64).reshape(-1)
        if self._t0 is None:
            self._t0 = float(block.t_start)
        if len(x) == 0:
            return []
        self._pending.append(x)
        self._n_in += len(x)
        B = self.cfg.batch_frames
        if (self._next_batch * B + B - 1) * HOP + self._lookahead > self._n_in:
            return []  # no batch complete yet: keep the (cheap) pending list
        return self._run_batches(self._n_in)

    def _absorb_pending(self) -> None:
        """Move pending raw blocks into the analysis buffer, high-pass filtered (stateful,
        so the result does not depend on how the audio was split). Blocks equal to the
        audio known ahead take its filtered samples (the same filter over the same samples
        from rest: the same numbers)."""
        if not self._pending:
            return
        own = len(self._pending) > 1                  # a fresh array: filtered in place
        x = np.concatenate(self._pending) if own else self._pending[0]
        self._pending = []
        n0, n1 = self._n_absorbed, self._n_absorbed + len(x)
        self._n_absorbed = n1
        if self._expected is not None:
            raw, filtered = self._expected
            if np.array_equal(x, raw[n0:n1]):
                x = filtered[n0:n1]
            else:                       # the stream leaves the audio known ahead: the filter
                self._expected = None   # takes up from its state after the samples so far
                if self._hp is not None:
                    self._hp(raw[:n0])
        if self._expected is None and self._hp is not None:
            x = self._hp(x, own=own)
        self._vad.push(x, expected=self._expected is not None)
        self._buf = np.concatenate([self._buf, x])

    def flush(self) -> list[Syllable]:
        """End of stream: analyse the remaining frames (silence after the end) and close the
        open syllable. Returns the syllables this emitted."""
        if self._flushed:
            return []
        self._flushed = True
        self._absorb_pending()
        end = self._n_in
        last_frame = (end - 1) // HOP if end else -1  # frames whose centre lies in the audio
        need = (last_frame + 1 + self.cfg.batch_frames) * HOP + self.cfg.lookahead + HOP
        pad = np.zeros(max(need - end, 0))
        self._vad.push(pad, expected=self._as_expected())
        self._buf = np.concatenate([self._buf, pad])
        out = self._run_batches(end + max(need - end, 0), frame_limit=last_frame + 1,
                                emit_time=end)
        seg = self._seg
        if seg.in_speech:
            min_len = int(round(self.cfg.min_syllable_s / PROSODY_FRAME_STEP))
            k = self._n_frames
            if k - seg.start >= min_len and seg.peak >= seg.peak_threshold + self.cfg.min_dip_db:
                last = self._make_syllable(seg.start, k, end)
                out.append(last)
                self._syllables.append(last)
            seg.in_speech = False
        return out

    def release(self) -> None:
        """This tracker's stream is over and nothing more is pushed (its frames and syllables
        stay readable): its voice-activity engine is handed back for the next tracker."""
        self._vad.release()

    @property
    def n_frames(self) -> int:
        """Number of frames analysed so far (frames ``0 .. n_frames - 1`` are final)."""
        return self._n_frames

    def frames_since(self, k: int) -> tuple[ProsodyFrames, np.ndarray]:
        """Frames ``k .. n_frames - 1`` (incremental access, O(new frames)).

        Returns:
            (frames, t_known): the frames as :class:`ProsodyFrames` (the same values
            :meth:`frames` gives for them) and, shape (n,), the stream time (s) at which each
            became known: the end of the audio window of the batch that computed it, i.e.
            the ``t_emitted`` of a decision that uses it.
        """
        k, n, times, known = self._since(k)
        return (ProsodyFrames(times, self._f0_all[k:n].copy(), self._int_all[k:n].copy(),
                              self._silent_all[k:n] > 0.5, self._voice_all[k:n] > 0.5), known)

    def frame_rows(self, k: int) -> zip:
        """Frames ``k .. n_frames - 1`` as rows ``(time s, intensity dB, F0 Hz or NaN, silent,
        t_known s)``: the values of :meth:`frames_since`, for a per-frame consumer."""
        k, n, times, known = self._since(k)
        return zip(times.tolist(), self._int_all[k:n].tolist(), self._f0_all[k:n].tolist(),
                   (self._silent_all[k:n] > 0.5).tolist(), known.tolist(), strict=True)

    def _since(self, k: int) -> tuple[int, int, np.ndarray, np.ndarray]:
        """``(k, n, times, t_known)`` of frames ``k .. n - 1`` (k clipped to the frames)."""
        n = self._n_frames
        k = min(max(int(k), 0), n)
        t0 = self._t0 or 0.0
        return (k, n, t0 + np.arange(k, n) * PROSODY_FRAME_STEP,
                np.round(t0 + self._known_all[k:n] / SAMPLE_RATE, 9))

    def frames(self) -> ProsodyFrames:
        """Per-frame curves analysed so far (see :class:`ProsodyFrames`)."""
        n = self._n_frames
        t0 = self._t0 or 0.0
        times = t0 + np.arange(n) * PROSODY_FRAME_STEP
        return ProsodyFrames(times, self._f0_all[:n].copy(), self._int_all[:n].copy(),
                             self._silent_all[:n] > 0.5, self._voice_all[:n] > 0.5)

    # ---------------------------------------------------------------- internals

    def _time(self, sample_or_frame: float, frames: bool = False) -> float:
        t = sample_or_frame * (PROSODY_FRAME_STEP if frames else 1.0 / SAMPLE_RATE)
        return round((self._t0 or 0.0) + t, 9)

    def _run_batches(self, available: int, frame_limit: int | None = None,
                     emit_time: int | None = None) -> list[Syllable]:
        c = self.cfg
        self._absorb_pending()
        out: list[Syllable] = []
        B = c.batch_frames
        while True:
            k0 = self._next_batch * B
            k1 = k0 + B - 1
            if frame_limit is not None and k0 >= frame_limit:
                break
            need = k1 * HOP + self._lookahead  # exclusive end sample of the widest window
            if need > available:
                break
            f0 = self._batch_pitch(k0, k1)
            inten = self._intensity(k0 - c.context_frames, k1)[c.context_frames:]
            n_keep = B if frame_limit is None else min(B, frame_limit - k0)
            t_known = need if emit_time is None else max(min(need, emit_time), 0)
            out.extend(self._consume(k0, f0[:n_keep], inten[:n_keep], t_known, need))
            self._next_batch += 1
            # drop audio no future batch needs
            keep_from = (self._next_batch * B - c.context_frames) * HOP - self._lookahead - HOP
            drop = keep_from - self._buf_start
            if drop > 0:
                self._buf = self._buf[drop:]
                self._buf_start += drop
        self._syllables.extend(out)
        return out

    def _as_expected(self) -> bool:
        """Whether every sample this tracker holds is the audio known ahead (:meth:`expect`):
        each block absorbed was, and a flush pads zeros only after all of it."""
        return self._expected is not None and (
            not self._flushed or self._n_absorbed == len(self._expected[0]))

    def _segment(self, a: int, b: int) -> np.ndarray:
        """Audio samples [a, b) in absolute indices (before the origin: zeros)."""
        lo = a - self._buf_start
        if lo < 0:
            raise AssertionError("prosody buffer trimmed too early")
        return self._buf[lo : b - self._buf_start]

    def _batch_pitch(self, k0: int, k1: int) -> np.ndarray:
        """Praat F0 (Hz, 0 unvoiced) of the batch's frames k0..k1, path-found over them and
        the context frames before them."""
        kc = k0 - self.cfg.context_frames
        half = self._pitch.half
        seg = self._segment(kc * HOP - half, k1 * HOP + half)
        if self._ahead is not None:
            f0 = self._ahead.f0(k0 // self.cfg.batch_frames,
                                None if self._as_expected() else seg)
            if f0 is not None:
                return f0
        return batch_f0(seg, kc, self._pitch)[k0 - kc:]

    def _intensity(self, k0: int, k1: int) -> np.ndarray:
        """Praat intensity (dB; -inf where Praat has none) of frames k0..k1 inclusive."""
        c = self.cfg
        half = c.intensity_window // 2 + _PAD
        a, b = k0 * HOP - half, k1 * HOP + half
        seg = self._segment(a, b)
        if self._intensity_ahead is not None and k1 - k0 + 1 == c.batch_frames + c.context_frames:
            vals = self._intensity_ahead.values((k0 + c.context_frames) // c.batch_frames,
                                                None if self._as_expected() else seg)
            if vals is not None:
                return vals
        inten = praat_intensity(seg, a, c.intensity_min_pitch_hz)
        if len(inten) != k1 - k0 + 1:  # pragma: no cover - guarded by the window arithmetic
            raise AssertionError(f"Praat returned {len(inten)} frames, expected {k1 - k0 + 1}")
        return inten

    def _consume(self, k0: int, f0: np.ndarray, inten: np.ndarray,
                 t_known: int, heard: int) -> list[Syllable]:
        """Frames ``k0 ..`` of one batch (F0, intensity) through the segmenter, with the voice
        decisions known once ``heard`` samples (the batch's analysis window) have arrived.
        (Per frame: Python lists, not numpy, for five frames at a time.)"""
        n = len(f0)
        self._grow(k0 + n)
        hz = f0.tolist()
        pitched = [v > 0 and math.isfinite(v) for v in hz]
        self._int_all[k0 : k0 + n] = inten
        voice = self._vad.frame_speech(k0, k0 + n, heard).tolist()
        if self.cfg.voice_needs_f0 and self._vad.enabled:
            voice = self._confirm_voicing(voice, pitched)
        self._voice_all[k0 : k0 + n] = voice
        silent: list[bool] = []
        out = []
        step = self._seg.step
        for i, (i_db, v) in enumerate(zip(inten.tolist(), voice, strict=True)):
            s, closed = step(k0 + i, i_db, v)
            silent.append(s)
            for a, b in closed:
                # syllables are closed by frames already stored
                self._f0_all[k0 : k0 + i + 1] = self._shown_f0(hz, silent)
                out.append(self._make_syllable(a, b, t_known))
        self._f0_all[k0 : k0 + n] = self._shown_f0(hz, silent)
        self._silent_all[k0 : k0 + n] = silent
        self._known_all[k0 : k0 + n] = t_known
        self._n_frames = k0 + n
        return out

    @staticmethod
    def _shown_f0(hz: list[float], silent: list[bool]) -> list[float]:
        """F0 (Hz) of the frames ``silent`` covers: NaN where unvoiced (0) or silent."""
        return [v if v > 0 and not s else math.nan for v, s in zip(hz, silent, strict=False)]

    def _confirm_voicing(self, voice: list[bool], pitched: list[bool]) -> list[bool]:
        """``voice`` (one batch) with each detector run counted only from its first pitched
        frame on, back to the start of the run within this batch."""
        n = len(voice)
        out = [False] * n
        i = 0
        while i < n:
            if not voice[i]:
                self._voiced_run = False
                i += 1
                continue
            j = i
            while j < n and voice[j]:
                j += 1
            if self._voiced_run or any(pitched[i:j]):
                out[i:j] = [True] * (j - i)
                self._voiced_run = True
            i = j
        return out

    def _grow(self, n: int) -> None:
        if n > len(self._f0_all):
            size = max(n, 2 * len(self._f0_all), 1024)
            for name in ("_f0_all", "_int_all", "_known_all", "_silent_all", "_voice_all"):
                old = getattr(self, name)
                new = np.full(size, np.nan)
                new[: len(old)] = old
                setattr(self, name, new)

    def _make_syllable(self, a: int, b: int, t_known: int) -> Syllable:
        f0 = self._f0_all[a:b]
        inten = self._int_all[a:b]
        voiced = np.isfinite(f0)
        is_voiced = bool(voiced.sum() >= max(2, self.cfg.min_voiced_share * (b - a)))
        fin = inten[np.isfinite(inten)]
        return Syllable(
            t_start=self._time(a, frames=True), t_end=self._time(b, frames=True),
            t_emitted=self._time(t_known),
            f0_hz=float(np.mean(f0[voiced])) if is_voiced else None,
            intensity_db=float(np.mean(fin)) if len(fin) else float("-inf"),
            voiced=is_voiced,
        )


# -------------------------------------------------------------------------------- analysis


@dataclass
class ProsodyAnalysis:
    """Result of :func:`analyze_file` / :func:`analyze_samples`.

    Attributes:
        syllables: in emission order.
        frames: per-frame curves.
        summary: see :func:`summarize`.
        samples: the analysed float32 16 kHz mono audio, shape (n,).
        info: source file facts (``None`` for in-memory audio).
    """

    syllables: list[Syllable]
    frames: ProsodyFrames
    summary: dict[str, Any]
    samples: np.ndarray
    info: Any = None
    config: ProsodyConfig = field(default_factory=ProsodyConfig)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: summary, syllables and config (frames left out)."""
        return {
            "summary": self.summary,
            "syllables": [asdict(s) | {"length": s.length} for s in self.syllables],
            "config": asdict(self.config),
            "source": asdict(self.info) if self.info is not None else None,
        }


def summarize(syllables: list[Syllable], frames: ProsodyFrames, duration_s: float) -> dict:
    """Summary figures of an analysis.

    Keys: ``duration_s``; ``speech_s`` (non-silent frames × 10 ms); ``n_syllables``;
    ``n_voiced_syllables``; ``syllable_rate`` (syllables per second of speech);
    ``voiced_share`` (voiced / non-silent frames); ``f0_p5_hz``, ``f0_p50_hz``, ``f0_p95_hz``
    (over voiced frames, NaN when none); ``mean_syllable_s``; ``latency_mean_s``,
    ``latency_median_s``, ``latency_p95_s`` (``t_emitted - t_end``, NaN without syllables).
    """
    nonsilent = ~frames.silent
    speech_s = float(nonsilent.sum() * PROSODY_FRAME_STEP)
    f0 = frames.f0_hz[np.isfinite(frames.f0_hz)]
    lat = np.array([s.t_emitted - s.t_end for s in syllables])
    nan = float("nan")

    def pct(a: np.ndarray, q: float) -> float:
        return float(np.percentile(a, q)) if len(a) else nan

    return {
        "duration_s": float(duration_s),
        "speech_s": speech_s,
        "n_syllables": len(syllables),
        "n_voiced_syllables": int(sum(s.voiced for s in syllables)),
        "syllable_rate": len(syllables) / speech_s if speech_s > 0 else 0.0,
        "voiced_share": float(np.isfinite(frames.f0_hz[nonsilent]).mean()) if speech_s else 0.0,
        "f0_p5_hz": pct(f0, 5), "f0_p50_hz": pct(f0, 50), "f0_p95_hz": pct(f0, 95),
        "mean_syllable_s": float(np.mean([s.length for s in syllables])) if syllables else nan,
        "latency_mean_s": float(lat.mean()) if len(lat) else nan,
        "latency_median_s": pct(lat, 50), "latency_p95_s": pct(lat, 95),
    }


def analyze_samples(
    samples: np.ndarray, block_size: int | None = None, config: ProsodyConfig | None = None,
    info: Any = None, ahead: bool = True,
) -> ProsodyAnalysis:
    """Run the streaming tracker over float32 16 kHz mono samples (n,).

    ``block_size=None`` pushes everything as one block; any block size gives the same result.
    The samples are known ahead (:meth:`ProsodyTracker.expect`); ``ahead=False`` analyses them
    as a live source would, block by block (the same result, for about twice the work).
    """
    from gesture_sim.audio.sources import iter_blocks

    samples = np.asarray(samples, dtype=np.float32)
    tracker = ProsodyTracker(config)
    if ahead:
        tracker.expect(samples)
    syllables: list[Syllable] = []
    for block in iter_blocks(samples, block_size):
        syllables.extend(tracker.push(block))
    syllables.extend(tracker.flush())
    frames = tracker.frames()
    summary = summarize(syllables, frames, len(samples) / SAMPLE_RATE)
    return ProsodyAnalysis(syllables, frames, summary, np.asarray(samples), info, tracker.cfg)


def analyze_file(
    path: str | Path, block_size: int | None = None, config: ProsodyConfig | None = None,
) -> ProsodyAnalysis:
    """Load an audio file (any format :func:`~gesture_sim.audio.sources.load_audio` reads)
    and analyse it with the streaming tracker (see :func:`analyze_samples`)."""
    from gesture_sim.audio.sources import load_audio

    samples, info = load_audio(path)
    return analyze_samples(samples, block_size, config, info)
