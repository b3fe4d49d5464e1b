"""Okwechime 2011's audio-driven listener (thesis §4.5.3), small and causal.

**Front end** (:func:`mfcc`, :class:`MfccStream`; numpy/scipy only). HTK-style features of the
partner's voice at 16 kHz: frames of ``win_s`` = 20 ms (320 samples) every ``hop_s`` = 10 ms
(160 samples), 100 frames/s; frame ``k`` covers samples ``[160 k, 160 k + 320)``, centre time
``(160 k + 160) / 16000`` s, known once its last sample has arrived (``(160 k + 320) / 16000``
s). Per frame (shape (13,), :data:`FEATURES`):

* ``c1..c12``: pre-emphasis ``y[n] = x[n] - 0.97 x[n-1]`` (on the stream), a Hamming window,
  the power spectrum ``|FFT_512|^2``, a 26-band triangular mel filterbank (HTK mel
  ``2595 log10(1 + f / 700)``, 0..8000 Hz, band ``i`` peaking at the ``(i + 1)``-th of 28
  equally spaced mel points; :func:`mel_filterbank`), natural log (floor 1e-10), DCT-II
  (orthonormal) keeping coefficients 1..12, liftered ``1 + 11 sin(pi n / 22)`` (HTK's
  CEPLIFTER 22) (:func:`cepstra`);
* ``log_energy``: ``ln(sum x^2)`` of the frame's raw samples (before pre-emphasis and window,
  HTK's raw energy; floor 1e-10).

**Classes** (:class:`AudioCodebook`): k-means (scikit-learn, fit only) of z-scored features into
``n_classes`` = 25 classes, trained on speaker audio; classification is the nearest centre.

**Projection mapping** (:class:`ProjectionMapping`, thesis Eq. 4.5): ``P(state q | class r) =
|C_q ∩ E_r| / N_r`` over a paired corpus (the partner's audio class and the listener's motion
state at the same frame). Listener states (:data:`STATES`): ``rest``, ``nod``, ``posture``.
Without paired data (this repository has none) :meth:`ProjectionMapping.fallback` is a
documented stand-in from each class centre's energy only: classes more than ``silence_db``
(35 dB) below the loudest centre are silence (``rest`` 1); the others get ``nod`` from
``nod_lo`` (0.08, at ``span_db`` = 30 dB or more below the loudest) to ``nod_hi`` (0.25, the
loudest), linear in dB, ``posture`` 0.02, ``rest`` the rest. It cannot tell a phrase end
from the middle of a word: like the thesis's own model ("it nods whenever speech is
present"), it answers speech, not what the speaker does (the prosodic rule of
:mod:`gesture_sim.signals.listener` does that).

**The listener** (:class:`AudioListener`, the interface of
:class:`~gesture_sim.signals.listener.ListenerSignals`). Feed the partner's samples with
:meth:`AudioListener.push_audio` and call :meth:`AudioListener.step` once per control step. A
MIMiC-like segment loop: when the current segment ends (a "cut point") and the listener is not
speaking (nor within ``own_quiet_s`` after), the weights ``W`` are the mean of ``P(state |
class)`` over the classes of the last ``window_s`` (0.3 s) of frames known by ``t`` (no frame:
``rest``), scaled by the interest (``nod`` by the ``nod`` factor, ``posture`` by the
``activity`` factor of :class:`~gesture_sim.signals.sdm.ListenerTendencies`) and renormalised;
a nod within ``refractory_s`` of the previous one is not allowed, nor a second posture shift
while one lasts (their weights go to ``rest``). The drawn state becomes a
segment: ``rest`` for ``rest_s``; a nod (the rule listener's nod envelope, uninvited size,
``p_brow`` brows) until it ends; a posture shift (the rule listener's shift) until it ends.
The attentive tilt/lean ramps in while a speech class was heard within ``attend_hold_s``.

**Motion** (``AudioListener(motion=...)``, :data:`MOTIONS`). ``"graph"``: each drawn state
plays a real excerpt of the motion library (:mod:`gesture_sim.signals.listener_graph`: rests,
nods and posture shifts found in the shipped library's frames, on the neck, head and spine
joints), the projection mapping then choosing among real listener motion as in the thesis
(MIMiC, Eq. 4.6-4.7 with the three states as its clusters). The excerpt is drawn (seeded, its
own stream) among that state's excerpts whose start fits the current pose and velocity
(:meth:`~gesture_sim.signals.listener_graph.ListenerGraph.choose`) and plays frame by frame
(linear interpolation between frames) for its own length, which sets the next cut point (a
rest excerpt lasts the extraction's ``rest_s``, 0.5 s, in place of the model's); the
mismatch between the current pose and the excerpt's first frame is added to it and decays
with time constant ``settle_s`` (MIMiC's blend at a transition, so the pose stays continuous
and the real frames take over). A nod's backchannel is stamped at the excerpt's lowest head,
with the ``p_brow`` brows as before; a posture excerpt emits ``"shift"`` and no other shift
starts until ``shift_hold_min_s`` after it ends. The excerpts' motion is gated in (raised
cosine over ``attend_on_s``) while the listener does not speak and out (``attend_off_s``)
while it speaks, so a speaking listener adds nothing. The attentive tilt/lean and the brows
stay envelopes. ``"envelope"``: the envelopes above, as before the graph (bit for bit).
Default (``motion=None``): ``"graph"`` when the graph (default: the shipped library's,
:func:`~gesture_sim.signals.listener_graph.default_listener_graph`) has at least one excerpt
of each state, else ``"envelope"``.

**The partner's laughs.** The samples given to :meth:`AudioListener.push_audio` also feed the
laugh detector (:mod:`gesture_sim.audio.laughter`); a detected laugh gets the rule listener's
response (a smile, and with ``p_laugh_back`` a laugh back; :mod:`gesture_sim.signals.listener`,
"The partner's laughs"), with its own seeded draws, so without a laugh every output is as
before.
"""

from __future__ import annotations

import json
import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.fft import dct, rfft

from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.errors import GestureSimError
from gesture_sim.signals.listener import (
    _J,
    LISTENER_JOINTS,
    Backchannel,
    Cue,
    ListenerBase,
    ListenerConfig,
)
from gesture_sim.signals.ruth import Action, rise

__all__ = [
    "FEATURES", "MOTIONS", "N_CLASSES", "STATES", "AudioCodebook", "AudioListener",
    "AudioListenerModel", "MfccStream", "ProjectionMapping", "cepstra", "default_audio_model",
    "hz_to_mel", "mel_filterbank", "mel_to_hz", "mfcc", "states_from_table",
]

WIN = 320            # samples (20 ms at 16 kHz)
HOP = 160            # samples (10 ms)
N_FFT = 512
N_MELS = 26
N_MFCC = 12
LIFTER = 22
PREEMPH = 0.97
_FLOOR = 1e-10
#: Feature columns of :func:`mfcc`.
FEATURES: tuple[str, ...] = tuple(f"c{i}" for i in range(1, N_MFCC + 1)) + ("log_energy",)
#: The thesis's number of audio classes.
N_CLASSES = 25
#: Listener motion states of the projection mapping.
STATES: tuple[str, ...] = ("rest", "nod", "posture")
#: Where the listener's state motion comes from (:class:`AudioListener`'s ``motion``).
MOTIONS: tuple[str, ...] = ("graph", "envelope")


def hz_to_mel(f: np.ndarray | float) -> np.ndarray:
    """HTK mel: ``2595 log10(1 + f / 700)`` (f in Hz)."""
    return 2595.0 * np.log10(1.0 + np.asarray(f, float) / 700.0)


def mel_to_hz(m: np.ndarray | float) -> np.ndarray:
    """Inverse of :func:`hz_to_mel` (Hz)."""
    return 700.0 * (10.0 ** (np.asarray(m, float) / 2595.0) - 1.0)


def mel_filterbank(n_mels: int = N_MELS, n_fft: int = N_FFT, sr: int = SAMPLE_RATE,
                   fmin: float = 0.0, fmax: float | None = None) -> np.ndarray:
    """Triangular mel filters, shape (n_mels, n_fft // 2 + 1): band ``i`` rises from mel point
    ``i`` to 1 at point ``i + 1`` and falls to 0 at point ``i + 2`` (``n_mels + 2`` points
    equally spaced in mel from ``fmin`` to ``fmax`` (default sr / 2) Hz), evaluated at the
    FFT bin frequencies ``k sr / n_fft``."""
    fmax = sr / 2.0 if fmax is None else float(fmax)
    pts = mel_to_hz(np.linspace(hz_to_mel(fmin), hz_to_mel(fmax), n_mels + 2))
    freqs = np.arange(n_fft // 2 + 1) * sr / n_fft
    fb = np.zeros((n_mels, len(freqs)))
    for i in range(n_mels):
        lo, c, hi = pts[i], pts[i + 1], pts[i + 2]
        up = (freqs - lo) / (c - lo)
        down = (hi - freqs) / (hi - c)
        fb[i] = np.clip(np.minimum(up, down), 0.0, None)
    return fb


_FB = mel_filterbank()
_WINDOW = np.hamming(WIN)
_LIFT = 1.0 + (LIFTER / 2.0) * np.sin(np.pi * np.arange(1, N_MFCC + 1) / LIFTER)


def cepstra(log_mel: np.ndarray) -> np.ndarray:
    """Liftered cepstra c1..c12 of log mel energies (..., n_mels) -> (..., 12): orthonormal
    DCT-II over the bands, coefficients 1..12, times ``1 + 11 sin(pi n / 22)``."""
    c = dct(np.asarray(log_mel, float), type=2, norm="ortho", axis=-1)[..., 1:N_MFCC + 1]
    return c * _LIFT


def _features(raw: np.ndarray, pre: np.ndarray) -> np.ndarray:
    """Frames (n, 320) of raw and pre-emphasised samples -> features (n, 13)."""
    energy = np.log(np.maximum(np.sum(raw * raw, axis=1), _FLOOR))
    spec = np.abs(rfft(pre * _WINDOW, n=N_FFT, axis=1)) ** 2
    log_mel = np.log(np.maximum(spec @ _FB.T, _FLOOR))
    return np.column_stack([cepstra(log_mel), energy])


class MfccStream:
    """Causal MFCC + energy of a 16 kHz stream (module docstring): :meth:`push` samples, get
    the frames they complete."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._raw = np.zeros(0)
        self._pre = np.zeros(0)
        self._start = 0          # absolute index of _raw[0]
        self._last = 0.0         # the sample before the stream's next one (pre-emphasis)
        self.k = 0               # next frame index
        self.n_in = 0            # samples received

    def push(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples (n,) float at 16 kHz -> (frame centre times (m,) s, features (m, 13))."""
        x = np.asarray(samples, float).reshape(-1)
        if len(x):
            prev = np.concatenate([[self._last], x[:-1]])
            self._last = float(x[-1])
            self._raw = np.concatenate([self._raw, x])
            self._pre = np.concatenate([self._pre, x - PREEMPH * prev])
            self.n_in += len(x)
        n_done = (self.n_in - WIN) // HOP + 1 if self.n_in >= WIN else 0
        ks = np.arange(self.k, max(n_done, self.k))
        if not len(ks):
            return np.zeros(0), np.zeros((0, len(FEATURES)))
        idx = (ks[:, None] * HOP - self._start) + np.arange(WIN)[None, :]
        feats = _features(self._raw[idx], self._pre[idx])
        times = (ks * HOP + WIN / 2) / SAMPLE_RATE
        self.k = int(ks[-1]) + 1
        drop = self.k * HOP - self._start
        self._raw, self._pre = self._raw[drop:], self._pre[drop:]
        self._start += drop
        return times, feats


def mfcc(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MFCC + energy of a whole 16 kHz signal (n,): (frame centre times (m,) s, features
    (m, 13) as :data:`FEATURES`), m = 1 + (n - 320) // 160 (0 if n < 320)."""
    return MfccStream().push(x)


# ---------------------------------------------------------------------- classes, mapping

@dataclass
class AudioCodebook:
    """k-means classes of z-scored features.

    Attributes:
        mean, std: (13,) feature normalisation; centres: (n_classes, 13) in z units.
    """

    mean: np.ndarray
    std: np.ndarray
    centres: np.ndarray

    @property
    def n_classes(self) -> int:
        return int(len(self.centres))

    @classmethod
    def fit(cls, features: np.ndarray, n_classes: int = N_CLASSES, seed: int = 0
            ) -> AudioCodebook:
        """k-means (scikit-learn, ``n_init`` 4, seeded) of ``features`` (n, 13) into
        ``n_classes`` classes.

        Raises:
            GestureSimError: fewer frames than classes.
        """
        from sklearn.cluster import KMeans

        f = np.asarray(features, float)
        if len(f) < n_classes:
            raise GestureSimError(f"k-means into {n_classes} classes needs at least that many "
                                  f"frames (got {len(f)})")
        mean, std = f.mean(axis=0), np.maximum(f.std(axis=0), 1e-6)
        km = KMeans(n_clusters=n_classes, n_init=4, random_state=seed).fit((f - mean) / std)
        return cls(mean, std, np.asarray(km.cluster_centers_, float))

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Class (int (n,)) of each feature row (n, 13): the nearest centre."""
        z = (np.atleast_2d(np.asarray(features, float)) - self.mean) / self.std
        d = ((z[:, None, :] - self.centres[None, :, :]) ** 2).sum(axis=2)
        return np.argmin(d, axis=1)

    def centre_energy(self) -> np.ndarray:
        """Log energy (ln, raw units) of each centre, (n_classes,)."""
        j = FEATURES.index("log_energy")
        return self.centres[:, j] * self.std[j] + self.mean[j]


@dataclass
class ProjectionMapping:
    """``P(state | class)``: p (n_classes, len(STATES)), rows summing to 1.

    Attributes:
        p: the conditional; speech: bool (n_classes,): the class counts as partner speech
            (attention); source: ``"paired"`` or ``"fallback"``.
    """

    p: np.ndarray
    speech: np.ndarray
    source: str = "paired"

    @classmethod
    def fit(cls, classes: np.ndarray, states: np.ndarray, n_classes: int = N_CLASSES,
            speech: np.ndarray | None = None) -> ProjectionMapping:
        """Eq. 4.5 from a paired corpus: classes (n,) of the partner's audio and the listener's
        states (n,) (indices of STATES) at the same frames. A class never seen maps to the
        corpus's state prior. ``speech``: which classes count as partner speech for the
        attentive posture (bool (n_classes,); default every class)."""
        c = np.asarray(classes, int)
        s = np.asarray(states, int)
        if c.shape != s.shape or not len(c):
            raise GestureSimError("the projection mapping needs equally long, non-empty class "
                                  "and state sequences")
        if s.min() < 0 or s.max() >= len(STATES) or c.min() < 0 or c.max() >= n_classes:
            raise GestureSimError("class or state index out of range")
        counts = np.zeros((n_classes, len(STATES)))
        np.add.at(counts, (c, s), 1.0)
        prior = np.bincount(s, minlength=len(STATES)) / len(s)
        n_r = counts.sum(axis=1, keepdims=True)
        p = np.where(n_r > 0, counts / np.maximum(n_r, 1.0), prior[None, :])
        sp = np.ones(n_classes, bool) if speech is None else np.asarray(speech, bool)
        return cls(p, sp, "paired")

    @classmethod
    def fallback(cls, codebook: AudioCodebook, silence_db: float = 35.0,
                 span_db: float = 30.0, nod_lo: float = 0.08, nod_hi: float = 0.25,
                 posture: float = 0.02) -> ProjectionMapping:
        """No paired corpus: from each centre's log energy only (module docstring)."""
        e = codebook.centre_energy()
        drop_db = (e.max() - e) * 10.0 / math.log(10.0)       # ln power -> dB
        speech = drop_db <= silence_db
        loud = np.clip(1.0 - drop_db / span_db, 0.0, 1.0)
        p = np.zeros((len(e), len(STATES)))
        p[:, 0] = 1.0
        nod = nod_lo + (nod_hi - nod_lo) * loud
        p[speech, 1] = nod[speech]
        p[speech, 2] = posture
        p[speech, 0] = 1.0 - nod[speech] - posture
        return cls(p, speech, "fallback")


def states_from_table(table, listener: str, times: np.ndarray) -> np.ndarray:
    """Listener states (indices of STATES, (n,)) at ``times`` (s) from an SDM
    :class:`~gesture_sim.signals.sdm.SignalTable`: ``nod`` where the listener nods, else
    ``posture`` where it is active, else ``rest`` (a paired corpus for
    :meth:`ProjectionMapping.fit`)."""
    k = np.clip((np.asarray(times, float) * table.fps).astype(int), 0, table.n_frames - 1)
    nod = table.signal(listener, "nod")[k]
    act = table.signal(listener, "activity")[k]
    return np.where(nod, 1, np.where(act, 2, 0))


@dataclass
class AudioListenerModel:
    """A codebook and a projection mapping, with the segment timing (s).

    Attributes:
        codebook, mapping: as above. window_s: the classes averaged at a cut point (s).
        rest_s: a rest segment (s).
    """

    codebook: AudioCodebook
    mapping: ProjectionMapping
    window_s: float = 0.3
    rest_s: float = 0.5

    @classmethod
    def train(cls, speaker_audio: list[np.ndarray], listener_states: list[np.ndarray] | None
              = None, n_classes: int = N_CLASSES, seed: int = 0) -> AudioListenerModel:
        """Codebook on the speaker's 16 kHz audio (a list of (n,) signals); the mapping from
        the listener states aligned to each signal's MFCC frames (a list of (m_i,) state
        indices), or the fallback when ``listener_states`` is None."""
        feats = [mfcc(x)[1] for x in speaker_audio]
        if not feats or not sum(len(f) for f in feats):
            raise GestureSimError("no speaker audio to train the audio listener on")
        book = AudioCodebook.fit(np.concatenate(feats), n_classes, seed)
        fb = ProjectionMapping.fallback(book)
        if listener_states is None:
            return cls(book, fb)
        if len(listener_states) != len(feats) or any(
                len(s) != len(f) for s, f in zip(listener_states, feats, strict=True)):
            raise GestureSimError("give one listener state per MFCC frame of each recording")
        classes = np.concatenate([book.predict(f) for f in feats])
        mapping = ProjectionMapping.fit(classes, np.concatenate(listener_states), n_classes,
                                        speech=fb.speech)
        return cls(book, mapping)

    def save(self, path: str | Path) -> None:
        """Write as JSON."""
        doc = {"format": "gesture_sim.audio_listener/1", "window_s": self.window_s,
               "rest_s": self.rest_s, "mean": self.codebook.mean.tolist(),
               "std": self.codebook.std.tolist(), "centres": self.codebook.centres.tolist(),
               "p": self.mapping.p.tolist(), "speech": self.mapping.speech.tolist(),
               "source": self.mapping.source}
        try:
            Path(path).write_text(json.dumps(doc) + "\n", encoding="utf-8")
        except OSError as exc:
            raise GestureSimError(f"cannot write audio listener {path}: {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> AudioListenerModel:
        """Read :meth:`save`'s JSON.

        Raises:
            GestureSimError: unreadable or not such a file.
        """
        try:
            d = json.loads(Path(path).read_text(encoding="utf-8"))
            if d.get("format") != "gesture_sim.audio_listener/1":
                raise ValueError("not a gesture_sim audio listener file")
            book = AudioCodebook(np.asarray(d["mean"], float), np.asarray(d["std"], float),
                                 np.asarray(d["centres"], float))
            mp = ProjectionMapping(np.asarray(d["p"], float), np.asarray(d["speech"], bool),
                                   str(d["source"]))
            return cls(book, mp, float(d["window_s"]), float(d["rest_s"]))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise GestureSimError(f"cannot read audio listener {path}: {exc}") from None


_DEFAULT: AudioListenerModel | None = None


def default_audio_model() -> AudioListenerModel:
    """The fallback model with a codebook trained on the shipped speech
    (``assets/audio/jfk.wav``, 11 s of one public-domain speaker); cached per process."""
    global _DEFAULT
    if _DEFAULT is None:
        from gesture_sim import EXAMPLE_SPEECH
        from gesture_sim.audio.sources import load_audio

        x, _ = load_audio(EXAMPLE_SPEECH)
        _DEFAULT = AudioListenerModel.train([x])
    return _DEFAULT


# ---------------------------------------------------------------------- the listener

class AudioListener(ListenerBase):
    """The audio-driven listener (module docstring), with the interface of
    :class:`~gesture_sim.signals.listener.ListenerSignals`.

    Args:
        model: :class:`AudioListenerModel` (default :func:`default_audio_model`).
        seed: seeds the state draws, nod variants and shifts.
        interest: None or 0..1 (scales ``nod`` and ``posture``; None and 0.5 are the same).
        config: a :class:`~gesture_sim.signals.listener.ListenerConfig` for the motion (nod,
            brow, shift, attention, ``refractory_s``, ``own_quiet_s``).
        tendencies: the interest tables (default: Table 5.4 around the rule's base rates).
        motion: ``"graph"``, ``"envelope"`` or None (module docstring, :data:`MOTIONS`).
        graph: the :class:`~gesture_sim.signals.listener_graph.ListenerGraph` (default: the
            shipped library's); used in ``"graph"`` motion only.
        settle_s: time constant (s) of the blend into an excerpt (``"graph"`` motion).

    Raises:
        GestureSimError: an unknown ``motion``, or ``"graph"`` with a graph that lacks a state.
    """

    NEUTRAL_SCALE = {"nod": 1.0, "activity": 1.0}

    def __init__(self, model: AudioListenerModel | None = None, seed: int = 0,
                 interest: float | None = None, config: ListenerConfig | None = None,
                 tendencies=None, *, motion: str | None = None, graph=None,
                 settle_s: float = 1.0) -> None:
        self.model = model or default_audio_model()
        self._setup(config, seed, interest, tendencies)
        if motion not in (None, *MOTIONS):
            raise GestureSimError(f"unknown listener motion {motion!r} (choose from "
                                  f"{', '.join(MOTIONS)})")
        self.graph = None
        if motion != "envelope":
            from gesture_sim.signals.listener_graph import default_listener_graph

            if graph is None:
                try:
                    graph = default_listener_graph()
                except GestureSimError:
                    if motion == "graph":
                        raise
                    graph = None
            if graph is not None and graph.complete:
                self.graph = graph
            elif motion == "graph":
                raise GestureSimError("the listener graph needs at least one excerpt of each "
                                      f"state (it has {graph.counts() if graph else 'none'})")
        self.motion = "graph" if self.graph is not None else "envelope"
        self.settle_s = float(settle_s)
        if self.graph is not None:
            from gesture_sim.signals.listener_graph import GRAPH_JOINTS

            self._gidx = np.array([_J[n] for n in GRAPH_JOINTS], int)
        self.reset()

    def reset(self) -> None:
        """A new stream at t = 0."""
        c = self.cfg
        self._rng = np.random.default_rng([self.seed, 10])
        self._stream = MfccStream()
        self._pending: deque[tuple[float, float, int]] = deque()   # (t_known, t, class)
        self._window: deque[tuple[float, int]] = deque()
        self.backchannels: list[Backchannel] = []
        self.cues: list[Cue] = []
        self.events: list[tuple[float, str]] = []
        self.states: list[tuple[float, str]] = []
        self._new: list[tuple[float, str]] = []
        self._seg_end = 0.0
        self._last_nod = -math.inf
        self._own_last = -math.inf
        self._last_speech = -math.inf
        self._actions: list[Action] = []
        self._shift: Action | None = None
        side = 1.0 if self._rng.random() < 0.5 else -1.0
        self._attend_goal = side * c.attend_tilt_rad * self._tilt_unit
        self._attend_goal[_J["lower_spine_flex"]] += c.attend_lean_rad
        self._attend_x = 0.0
        self._t_last: float | None = None
        # graph motion
        self._rng_graph = np.random.default_rng([self.seed, 11])
        self.plays: list[tuple[float, int, float, np.ndarray]] = []   # (t0, excerpt, fps, R0)
        self._play: tuple[float, int, np.ndarray] | None = None       # (t0, excerpt, R0)
        self._gpose = np.zeros(len(self._gidx)) if self.graph is not None else None
        self._gvel = np.zeros_like(self._gpose) if self.graph is not None else None
        self._gate_x = 0.0
        self._posture_free = -math.inf
        self._reset_laugh(12)

    # ------------------------------------------------------------------ inputs
    def push_audio(self, samples: np.ndarray, latency_s: float = 0.0) -> None:
        """The partner's next samples (float, 16 kHz, contiguous from t = 0). A frame is used
        from ``latency_s`` after its last sample. The same samples feed the laugh detector
        (:mod:`gesture_sim.audio.laughter`; a laugh is known ``latency_s`` after its
        detection)."""
        self._hear_laughs(samples, latency_s)
        times, feats = self._stream.push(samples)
        if not len(times):
            return
        classes = self.model.codebook.predict(feats)
        known = times + (WIN / 2) / SAMPLE_RATE + latency_s
        self._pending.extend(zip(known.tolist(), times.tolist(), classes.tolist(),
                                 strict=True))

    def push_frames(self, times, intensity_db, silent, t_known, f0_hz=None) -> None:
        """The partner's prosody frames (the rule listener's input): accepted and not used
        (this model hears MFCC classes only, :meth:`push_audio`)."""

    # ------------------------------------------------------------------ step
    def step(self, t: float, own_speaking: bool) -> tuple[np.ndarray, list[tuple[float, str]]]:
        """Advance to control step ``t`` (s); returns (offsets (len(LISTENER_JOINTS),) rad/m,
        the events ``(t, text)`` of this step)."""
        c, m = self.cfg, self.model
        self._new = []
        dt = 0.0 if self._t_last is None else min(max(t - self._t_last, 0.0), 0.25)
        self._t_last = t
        while self._pending and self._pending[0][0] <= t + 1e-9:
            _, tc, cls_ = self._pending.popleft()
            self._window.append((tc, cls_))
            if m.mapping.speech[cls_]:
                self._last_speech = tc
        while self._window and self._window[0][0] < t - m.window_s:
            self._window.popleft()
        if own_speaking:
            self._own_last = t
            if self._shift is not None:
                self._shift.close(t, c.shift_decay_s)
            self._actions = [a for a in self._actions if a.start <= t]
        self._laugh_step(t, bool(own_speaking))
        if self.graph is not None:
            return self._step_graph(t, dt, bool(own_speaking))
        if t >= self._seg_end - 1e-9:
            self._cut(t, bool(own_speaking))
        listening = (not own_speaking) and self._last_speech >= t - c.attend_hold_s
        return self._motion(t, dt, listening)

    def weights(self) -> np.ndarray:
        """``W`` (len(STATES),) now: the mean mapping of the window's classes, interest-scaled
        and renormalised (``rest`` 1 with no frame)."""
        if not self._window:
            w = np.zeros(len(STATES))
            w[0] = 1.0
            return w
        cls_ = np.fromiter((k for _, k in self._window), int)
        w = self.model.mapping.p[cls_].mean(axis=0)
        w = w * np.array([1.0, self._scale.get("nod", 1.0), self._scale.get("activity", 1.0)])
        return w / max(float(w.sum()), 1e-12)

    def _cut(self, t: float, own: bool) -> None:
        """A cut point at ``t``: draw the next segment."""
        c, m = self.cfg, self.model
        u, u_size, u_brow = self._rng.random(3)       # drawn at every cut point
        w = self.weights()
        if own or t - self._own_last < c.own_quiet_s - 1e-9:
            w = np.array([1.0, 0.0, 0.0])
        if self._shift is not None:                   # one posture shift at a time
            w = np.array([w[0] + w[2], w[1], 0.0])
        if t - self._last_nod < c.refractory_s - 1e-9:
            w = np.array([w[0] + w[1], 0.0, w[2]])
        state = int(np.searchsorted(np.cumsum(w), u * w.sum(), side="right"))
        state = min(state, len(STATES) - 1)
        self.states.append((round(t, 4), STATES[state]))
        if state == 1:
            size = c.nod_rad * c.uninvited_scale * (1.0 + c.nod_jitter * (2.0 * u_size - 1.0))
            s1 = t + c.react_s
            p1 = s1 + c.nod_attack_s
            self._actions.append(Action("baton", "D*", size * self._nod_unit, 1.0, s1, p1, p1,
                                        c.nod_decay_s))
            kind = "nod"
            if u_brow < c.p_brow:
                kind = "nod+brow"
                self._actions.append(Action("baton", "1+2*", self._brow, 1.0, s1, p1,
                                            p1 + c.brow_hold_s, c.brow_decay_s))
            self._last_nod = t
            self._seg_end = p1 + c.nod_decay_s
            self.backchannels.append(Backchannel(t, t, p1, kind, False))
            self._emit(p1, f"backchannel {kind}")
        elif state == 2:
            r = self._rng
            side = 1.0 if r.random() < 0.5 else -1.0
            bend = side * c.shift_bend_rad * float(r.uniform(0.5, 1.0))
            goal = np.zeros(len(LISTENER_JOINTS))
            goal[_J["lower_spine_bend"]] = 0.6 * bend
            goal[_J["upper_spine_bend"]] = 0.4 * bend
            goal[_J["lower_spine_flex"]] = c.shift_flex_rad * float(r.uniform(-1.0, 1.0))
            hold = float(r.uniform(c.shift_hold_min_s, max(c.shift_hold_max_s,
                                                           c.shift_hold_min_s)))
            peak = t + c.shift_attack_s
            self._shift = Action("underliner", "shift", goal, 1.0, t, peak, peak + hold,
                                 c.shift_decay_s)
            self._seg_end = t + m.rest_s
            self._emit(t, "shift")
        else:
            self._seg_end = t + m.rest_s

    # ------------------------------------------------------------------ graph motion
    def _graph_value(self, t: float) -> np.ndarray:
        """The graph joints' pose (rad, :data:`~gesture_sim.signals.listener_graph.
        GRAPH_JOINTS`) of the playing excerpt at ``t`` (held at its last frame past its end),
        with the decaying blend; zeros before the first excerpt."""
        if self._play is None:
            return np.zeros(len(self._gidx))
        t0, k, r0 = self._play
        f = self.graph.excerpts[k].frames
        u = min(max((t - t0) * self.graph.fps, 0.0), len(f) - 1.0)
        i = min(int(u), len(f) - 2) if len(f) > 1 else 0
        a = u - i
        x = f[i] if len(f) == 1 else (1.0 - a) * f[i] + a * f[i + 1]
        return x + r0 * math.exp(-max(t - t0, 0.0) / max(self.settle_s, 1e-9))

    def _step_graph(self, t: float, dt: float, own: bool
                    ) -> tuple[np.ndarray, list[tuple[float, str]]]:
        c = self.cfg
        if t >= self._seg_end - 1e-9:
            self._cut_graph(t, own)
        x = self._graph_value(t)
        if dt > 0:
            self._gvel = (x - self._gpose) / dt
        self._gpose = x
        if own:
            self._gate_x = max(self._gate_x - dt / max(c.attend_off_s, 1e-6), 0.0)
        else:
            self._gate_x = min(self._gate_x + dt / max(c.attend_on_s, 1e-6), 1.0)
        listening = (not own) and self._last_speech >= t - c.attend_hold_s
        out, ev = self._motion(t, dt, listening)
        gate = rise(self._gate_x)
        if gate > 0.0:
            out = out.copy()
            out[self._gidx] += gate * x
        return out, ev

    def _cut_graph(self, t: float, own: bool) -> None:
        """A cut point at ``t`` in graph motion: draw the state, then its excerpt."""
        c, g = self.cfg, self.graph
        u, u_brow = self._rng.random(2)               # drawn at every cut point
        w = self.weights()
        if own or t - self._own_last < c.own_quiet_s - 1e-9:
            w = np.array([1.0, 0.0, 0.0])
        if t < self._posture_free - 1e-9:             # one posture shift at a time
            w = np.array([w[0] + w[2], w[1], 0.0])
        if t - self._last_nod < c.refractory_s - 1e-9:
            w = np.array([w[0] + w[1], 0.0, w[2]])
        state = int(np.searchsorted(np.cumsum(w), u * w.sum(), side="right"))
        state = min(state, len(STATES) - 1)
        self.states.append((round(t, 4), STATES[state]))
        x = self._graph_value(t)
        k = g.choose(STATES[state], x, self._gvel, self._rng_graph)
        ex = g.excerpts[k]
        r0 = x - ex.frames[0]
        self._play = (t, k, r0)
        self.plays.append((round(t, 4), k, g.fps, r0))
        self._seg_end = t + max(ex.n_frames - 1, 1) / g.fps
        if state == 1:
            peak = t + ex.peak / g.fps
            kind = "nod"
            if u_brow < c.p_brow:
                kind = "nod+brow"
                self._actions.append(Action("baton", "1+2*", self._brow, 1.0, t, peak,
                                            peak + c.brow_hold_s, c.brow_decay_s))
            self._last_nod = t
            self.backchannels.append(Backchannel(t, t, peak, kind, False))
            self._emit(peak, f"backchannel {kind}")
        elif state == 2:
            self._posture_free = self._seg_end + c.shift_hold_min_s
            self._emit(t, "shift")

    def _emit(self, t: float, text: str) -> None:
        self._new.append((round(float(t), 4), text))
