"""Words that are utterances of their own — "Hello?", "Hi!", "Thank you.", "Bye!", "Yes." —
recognised, not spotted.

Keyword spotting (:mod:`gesture_sim.audio.keywords`) cannot tell a short word from part of a
longer one ("hi" in "high", "bye" in "by"), so its table leaves short words out. Greetings,
thanks and answers, though, are mostly said as utterances of their own, between pauses. This
module listens for exactly those: the voice-activity detector (:mod:`gesture_sim.audio.vad`)
cuts the stream into utterances; every utterance no longer than ``max_utterance_s`` is decoded
by PocketSphinx's continuous recogniser with the US English language model and dictionary that
ship inside the ``pocketsphinx`` wheel; a word (or two-word phrase) of :data:`UTTERANCE_WORDS`
in the best path, with a word posterior of at least ``min_posterior``, is a
:class:`~gesture_sim.contracts.Keyword` hit with that word's label. Long utterances (ordinary
speech) are not decoded at all: no CPU spent, and no chance of a word misheard inside them.

Times: ``t_start``/``t_end`` are the word's frames in the decoded utterance; ``t_emitted`` is
the moment the detector closed the utterance (its last voice window plus the hangover), so a
greeting is answered just after it was said. ``confidence`` is the word posterior's log10.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.audio.vad import VadConfig, VoiceActivityDetector
from gesture_sim.contracts import SAMPLE_RATE, Keyword
from gesture_sim.errors import GestureSimError

#: Word or two-word phrase -> semantic label: greetings, thanks, farewells and "yes".
UTTERANCE_WORDS: dict[str, str] = {
    "hello": "wave", "hi": "wave", "hey": "wave",
    "thank you": "bow", "thanks": "bow",
    "bye": "bye", "goodbye": "bye",
    "yes": "respond", "okay": "respond",
}


@dataclass(frozen=True)
class UtteranceSettings:
    """How utterances are cut and what counts as recognised.

    Attributes:
        max_utterance_s: longest utterance decoded (s, including the detector's hangover).
        min_posterior: least word posterior (0..1) of a recognised word.
        pad_s: audio kept before the utterance's first voice window (s), for the decoder's
            silence model.
        vad: the utterance cutter (its hangover is the pause that ends an utterance).
    """

    max_utterance_s: float = 2.0
    min_posterior: float = 0.25
    pad_s: float = 0.15
    vad: VadConfig = field(default_factory=lambda: VadConfig(hangover_s=0.25))


def _new_lm_decoder():
    try:
        import pocketsphinx
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise GestureSimError("word recognition needs the pocketsphinx package") from exc
    return pocketsphinx.Decoder(pocketsphinx.Config(loglevel="FATAL", bestpath=True))


class UtteranceRecognizer:
    """Streaming: :meth:`push` float32 16 kHz samples with their stream time, get hits.

    Args:
        labels: the labels the motion library has; words whose label is missing are left out
            (``None``: keep all).
        settings: see :class:`UtteranceSettings`.
        words: word -> label (default :data:`UTTERANCE_WORDS`).
    """

    def __init__(self, labels: Iterable[str] | None = None,
                 settings: UtteranceSettings | None = None,
                 words: dict[str, str] | None = None) -> None:
        self.cfg = settings or UtteranceSettings()
        table = UTTERANCE_WORDS if words is None else words
        keep = None if labels is None else set(labels)
        self.words = {w: lab for w, lab in table.items() if keep is None or lab in keep}
        self._vad = VoiceActivityDetector(self.cfg.vad)
        self._decoder = _new_lm_decoder() if self.words else None
        win = self._vad.window
        self._keep = int((self.cfg.max_utterance_s + self.cfg.pad_s) * SAMPLE_RATE) + 2 * win
        self._audio: deque[np.ndarray] = deque()
        self._audio_start = 0  # stream sample index of the first kept sample
        self._audio_n = 0
        self._t0: float | None = None
        self._scanned = 0  # windows whose speech flag is final and looked at
        self._run_start = -1  # first window of the open utterance
        self.decoded_s = 0.0
        self.utterances = 0

    @property
    def active(self) -> bool:
        """Whether any word is listened for."""
        return self._decoder is not None

    def push(self, samples: np.ndarray, t_start: float) -> list[Keyword]:
        """Append the next contiguous samples (the first push sets the stream origin)."""
        if self._decoder is None:
            return []
        if self._t0 is None:
            self._t0 = float(t_start)
        x = np.asarray(samples, dtype=np.float32).reshape(-1)
        self._audio.append(x)
        self._audio_n += len(x)
        self._vad.push(x)
        while self._audio and self._audio_n - len(self._audio[0]) >= self._keep:
            self._audio_n -= len(self._audio[0])
            self._audio_start += len(self._audio.popleft())
        return self._scan()

    def finish(self) -> list[Keyword]:
        """End of stream: close an open utterance with silence."""
        if self._decoder is None:
            return []
        tail = np.zeros(int((self.cfg.vad.hangover_s + 0.2) * SAMPLE_RATE), np.float32)
        end = (self._audio_start + self._audio_n) / SAMPLE_RATE + (self._t0 or 0.0)
        return self.push(tail, end)

    # ------------------------------------------------------------------ internals

    def _scan(self) -> list[Keyword]:
        vad, w = self._vad, self._vad.window
        final = vad.n_windows - self.cfg.vad.onset_windows  # later ones may be back-filled
        hits: list[Keyword] = []
        if final <= self._scanned:
            return hits
        flags = vad.window_speech(self._scanned, final)
        for i, on in enumerate(flags):
            j = self._scanned + i
            if on and self._run_start < 0:
                self._run_start = j
            elif not on and self._run_start >= 0:
                a, b = self._run_start * w, j * w
                self._run_start = -1
                if (b - a) / SAMPLE_RATE <= self.cfg.max_utterance_s:
                    hits.extend(self._decode(a, b, emitted=(j + 1) * w))
        self._scanned = final
        return hits

    def _samples(self, a: int, b: int) -> np.ndarray:
        buf = np.concatenate(list(self._audio)) if self._audio else np.zeros(0, np.float32)
        lo, hi = a - self._audio_start, b - self._audio_start
        return buf[max(lo, 0):max(hi, 0)]

    def _decode(self, a: int, b: int, emitted: int) -> list[Keyword]:
        assert self._decoder is not None
        pad = int(self.cfg.pad_s * SAMPLE_RATE)
        a0 = max(a - pad, self._audio_start, 0)
        x = self._samples(a0, b)
        if len(x) == 0:
            return []
        pcm = np.clip(np.round(x.astype(np.float64) * 32767.0), -32768, 32767).astype("<i2")
        ps = self._decoder
        ps.start_utt()
        ps.process_raw(pcm.tobytes(), False, True)
        ps.end_utt()
        self.decoded_s += len(x) / SAMPLE_RATE
        self.utterances += 1
        segs = [(s.word.split("(")[0], int(s.start_frame), int(s.end_frame), float(s.prob))
                for s in (ps.seg() or ())]
        segs = [s for s in segs if not s[0].startswith(("<", "["))]
        t0 = (self._t0 or 0.0) + a0 / SAMPLE_RATE
        t_em = round((self._t0 or 0.0) + emitted / SAMPLE_RATE, 6)
        out: list[Keyword] = []
        i = 0
        while i < len(segs):
            for span in (2, 1):
                group = segs[i:i + span]
                if len(group) < span:
                    continue
                phrase = " ".join(g[0] for g in group)
                label = self.words.get(phrase)
                post = min(g[3] for g in group)
                if label and post >= self.cfg.min_posterior:
                    out.append(Keyword(phrase, round(t0 + group[0][1] / 100, 6),
                                       round(t0 + (group[-1][2] + 1) / 100, 6),
                                       math.log10(max(post, 1e-12)), max(t_em, t0), label))
                    i += span - 1
                    break
            i += 1
        return out


# --------------------------------------------------------------------------------------------
# Confirming a spotted phrase by recognising the audio around it
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ConfirmSettings:
    """How a spotted phrase is confirmed by the continuous recogniser.

    The keyword spotter scores a phrase against a free phone loop, so in noisy or fast speech
    it also "hears" phrases in other words (``"thank you very much"`` in ``"...in New Jersey
    now"``); its thresholds cannot separate those from real ones (measured on the four real
    takes and espeak-ng speech, BENCHMARKS.md "Speech front end"). The language-model
    recogniser decodes the audio around the hit instead, where every word competes with every
    other word.

    Attributes:
        pad_s: audio decoded before the hit's start and after its end (s); the hit is decided
            once ``pad_s`` of audio after its end has arrived (its added latency).
        nbest: hypotheses of the recogniser's lattice looked at (1: the best path only).
        min_word_fraction: least share (0..1) of the phrase's words that one hypothesis must
            contain.
    """

    pad_s: float = 0.6
    nbest: int = 10
    min_word_fraction: float = 0.5


def _words_of(hypstr: str) -> set[str]:
    return {w.split("(")[0] for w in hypstr.split() if not w.startswith(("<", "["))}


class PhraseConfirmer:
    """Decides whether a spotted phrase was said: decodes int16 16 kHz audio around it with
    PocketSphinx's continuous recogniser (US English LM and dictionary of the wheel) and looks
    for the phrase's words in the ``nbest`` best hypotheses.

    Args:
        settings: see :class:`ConfirmSettings`.
    """

    def __init__(self, settings: ConfirmSettings | None = None) -> None:
        self.cfg = settings or ConfirmSettings()
        self._decoder = _new_lm_decoder()
        self.decoded_s = 0.0
        self.decisions = 0

    def confirm(self, phrase: str, pcm: np.ndarray) -> bool:
        """Whether ``phrase`` (lower-case words) is heard in ``pcm`` (int16 (n,), 16 kHz)."""
        words = phrase.split()
        if not words or len(pcm) == 0:
            return False
        need = max(1, math.ceil(self.cfg.min_word_fraction * len(words) - 1e-9))
        ps = self._decoder
        ps.start_utt()
        ps.process_raw(np.ascontiguousarray(pcm, dtype="<i2").tobytes(), False, True)
        ps.end_utt()
        self.decoded_s += len(pcm) / SAMPLE_RATE
        self.decisions += 1
        hyps = []
        best = ps.hyp()
        if best is not None:
            hyps.append(best.hypstr)
        if self.cfg.nbest > 1:
            for i, nb in enumerate(ps.nbest()):
                if i >= self.cfg.nbest:
                    break
                hyps.append(nb.hypstr)
        return any(sum(w in _words_of(h) for w in words) >= need for h in hyps)
