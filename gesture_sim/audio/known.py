"""Speech known ahead (a file, a text-to-speech voice with its word timings, a transcript): the
targets a planner aims strokes at, found once over the whole audio before it plays (issue 51).

:func:`analyse_known` runs the project's own causal analysis — the prosody tracker and the
accent detector (:func:`~gesture_sim.audio.accents.analyze_accents`, the same code and settings
as the live path, pushed over the whole file at once) — and reads, where they are given:

* **stressed syllables** from explicit times (``stress``), else from timed phones whose labels
  carry ARPAbet stress digits (``AY1``: the centre of each primary-stressed vowel; a TextGrid's
  phone tier, an aligner's or a TTS voice's phones), else from timed words: for each content
  word (not in :data:`~gesture_sim.audio.textgrid.FUNCTION_WORDS`) its first vowel when its
  phones are given without stress (most English content words stress their first syllable),
  or 40 % into the word without phones (a monosyllable's vowel sits near its middle) — both
  stated approximations;
* the **accents** the detector emits (their nucleus times and strengths);
* the **speech spans** (the detector's voice activity, frame by frame), the **voice energy** and
  the tracker's **syllables** (for the inference layer's belief ahead).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, Syllable

_VOWEL = re.compile(r"^(AA|AE|AH|AO|AW|AY|EH|ER|EY|IH|IY|OW|OY|UH|UW)([012])?$")


@dataclass(frozen=True)
class KnownSpeech:
    """The speech of one stream, analysed ahead (times in s on the stream clock).

    Attributes:
        duration_s: the audio's length.
        stress: (M,) centres of the stressed syllables (empty when no text was given).
        accents: (N,) the accent detector's nucleus times; accent_strength: (N,) their
            strengths (z).
        spans: (start, end) of each run of voice activity.
        times: (F,) the analysis frames' centres; energy: (F,) the voice's energy in [-1, 1]
            after each frame.
        syllables: the tracker's syllables, in emission order.
        source: where the stress came from ("stress", "phones", "words", "" none).
    """

    duration_s: float
    stress: np.ndarray
    accents: np.ndarray
    accent_strength: np.ndarray
    spans: list[tuple[float, float]]
    times: np.ndarray
    energy: np.ndarray
    syllables: tuple[Syllable, ...] = ()
    source: str = ""

    def energy_at(self, t: np.ndarray) -> np.ndarray:
        """The energy (-1..1) at times ``t`` (s), held from the last frame before each."""
        if self.times.size == 0:
            return np.zeros(len(t))
        i = np.clip(np.searchsorted(self.times, np.asarray(t, float), side="right") - 1, 0,
                    len(self.times) - 1)
        return self.energy[i]


def _span(x) -> tuple[float, float, str]:
    """(start, end, text) of a word or phone given as a tuple or with ``start_s``/``end_s``."""
    if hasattr(x, "start_s"):
        text = getattr(x, "text", None)
        return float(x.start_s), float(x.end_s), str(text if text is not None else x.label)
    a, b, text = x
    return float(a), float(b), str(text)


def stress_from_phones(phones: Sequence) -> np.ndarray:
    """(M,) centres (s) of the primary-stressed vowels (stress digit 1) of timed phones
    (``(start_s, end_s, label)`` or :class:`~gesture_sim.audio.phones.Phone`-like)."""
    out = []
    for p in phones:
        a, b, lab = _span(p)
        m = _VOWEL.match(lab.strip().upper())
        if m and m.group(2) == "1":
            out.append(0.5 * (a + b))
    return np.sort(np.asarray(out, dtype=float))


def stress_from_words(words: Sequence, phones: Sequence | None = None) -> np.ndarray:
    """(M,) stressed-syllable estimates (s) for timed content words (see the module
    docstring): the first vowel of each among ``phones`` (s), else 40 % into the word."""
    from gesture_sim.audio.textgrid import FUNCTION_WORDS

    vowels = []
    for p in phones or ():
        a, b, lab = _span(p)
        if _VOWEL.match(lab.strip().upper()):
            vowels.append((a, b))
    vowels.sort()
    starts = np.array([v[0] for v in vowels])
    out = []
    for w in words:
        a, b, text = _span(w)
        word = re.sub(r"[^a-z']", "", text.lower())
        if not word or word in FUNCTION_WORDS or b <= a:
            continue
        if vowels:
            i = int(np.searchsorted(starts, a - 1e-6))
            if i < len(vowels) and vowels[i][0] < b:
                out.append(0.5 * (vowels[i][0] + vowels[i][1]))
                continue
        out.append(a + 0.4 * (b - a))
    return np.sort(np.asarray(out, dtype=float))


def voice_spans(times: np.ndarray, speaking: np.ndarray, step_s: float = 0.01
                ) -> list[tuple[float, float]]:
    """(start, end) (s) of each run of ``speaking`` (F,) bool at frame centres ``times``."""
    sp = np.asarray(speaking, dtype=bool)
    if sp.size == 0:
        return []
    d = np.diff(np.concatenate([[0], sp.astype(int), [0]]))
    on, off = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    t = np.asarray(times, dtype=float)
    return [(float(t[a]), float(t[b - 1] + step_s)) for a, b in zip(on, off, strict=True)]


def analyse_known(samples: np.ndarray, words: Sequence | None = None,
                  phones: Sequence | None = None, stress: Sequence[float] | None = None,
                  analysis=None) -> KnownSpeech:
    """The speech of ``samples`` (n,) float 16 kHz known ahead (see the module docstring).

    ``words``, ``phones``: timed words / phones (``(start_s, end_s, text)`` or the
    :mod:`~gesture_sim.audio.phones` types); ``stress``: stressed-syllable times (s) given
    outright. ``analysis``: an :class:`~gesture_sim.audio.accents.AccentAnalysis` of the same
    samples already made (else it is run here)."""
    from gesture_sim.audio.accents import analyze_accents

    x = np.asarray(samples, dtype=np.float32).reshape(-1)
    an = analysis if analysis is not None else analyze_accents(x)
    source = ""
    if stress is not None:
        st, source = np.sort(np.asarray(stress, dtype=float)), "stress"
    else:
        st = stress_from_phones(phones) if phones is not None else np.zeros(0)
        source = "phones" if st.size else ""
        if st.size == 0 and words is not None:
            st, source = stress_from_words(words, phones), "words"
    acc = np.array([a.t for a in an.accents], dtype=float)
    strength = np.array([a.strength for a in an.accents], dtype=float)
    return KnownSpeech(len(x) / SAMPLE_RATE, st, acc, strength,
                       voice_spans(an.times, an.speaking), np.asarray(an.times, float),
                       np.asarray(an.energy, float), tuple(an.syllables), source)
