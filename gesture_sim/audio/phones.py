"""Phones and words with times: from a TextGrid, a force-aligned transcript, or live audio.

Three sources give the same :class:`Phone` / :class:`Word` records (seconds on the stream clock,
ARPAbet labels in upper case without stress digits, silence and noise as ``"SIL"``):

* :func:`phones_from_textgrid` / :func:`words_from_textgrid`: a Praat TextGrid with ``phones``
  (and ``words``) interval tiers (empty intervals are pauses: ``SIL``).
* :func:`align_transcript`: the transcript force-aligned to the audio by PocketSphinx 5
  (``Decoder.set_align_text``: a word-level Viterbi pass over the transcript's word chain with
  optional silences, then ``set_alignment`` + a second pass for the phones, read with
  ``Alignment.phones()``). The pronunciations come from the CMU dictionary that ships in the
  ``pocketsphinx`` wheel (134k words; alternative pronunciations are chosen by the decoder).
  Out-of-dictionary words: punctuation is stripped and hyphenated or possessive forms are looked
  up by parts (``well-known`` → ``well known``, ``scott's`` → ``scott`` + ``Z``); integers are
  read as words (:func:`number_words`: ``5`` → ``five``, ``1984`` → ``nineteen eighty four``);
  what is still missing gets a *letter-rule* pronunciation (:func:`letter_pronunciation`:
  English grapheme rules, about right for consonants, rough for vowels) added to the decoder
  and listed in :attr:`Transcript.fallback`; a token without letters or digits (``"%"``,
  ``"--"``) is skipped and listed in :attr:`Transcript.skipped`. Both are reported with one
  :mod:`warnings` line, never a crash. A transcript that does not fit the audio (words not
  spoken, audio cut inside a word) has no alignment path: a one-line error.
* :class:`PhoneRecogniser`: live phones from the audio alone, fed chunks of 16 kHz samples as
  they arrive. Two modes:

  - ``"allphone"`` (default): PocketSphinx phone-loop decoding (``allphone`` search) with the
    phonetic trigram LM that ships in the wheel (``en-us-phone.lm.bin``). A phone of the running
    partial hypothesis is emitted once it is not the last one and ended at least ``hold_s``
    before the newest decoded frame (so later frames rarely revise it); emitted phones are never
    retracted.
  - ``"words"``: continuous word decoding with the shipped word trigram LM and dictionary; a
    word of the partial hypothesis is emitted under the same rule and expanded to its dictionary
    phones, which share the word's span in proportion to typical phone durations (vowels 2x).
    It also yields the words (:attr:`PhoneRecogniser.words`) for users that need words.

  ``tools/phone_sources.py`` measures both on the four BEAT2 TextGrid takes (4.4 min of real
  speech, against the takes' TextGrid phones): ``allphone`` phone error rate 0.64 (viseme-class
  error 0.46), latency (emission - phone end) median 110 ms, p90 140 ms, max about 300 ms,
  0.06 s CPU per s of audio; ``words`` phone error rate 0.39 (class error 0.29), latency median
  260 ms, p90 460 ms, max about 850 ms, 0.27 s CPU per s. ``allphone`` is the default for its
  delay, though 110-140 ms of face behind voice is still above the roughly 90 ms at which sound
  leading picture is judged unacceptable (ITU-R BT.1359), so a live output should delay the
  audio by about that much where it can; ``words`` is the more accurate choice where half a
  second of delay is acceptable.

Errors are :class:`~gesture_sim.errors.GestureSimError` with one-line messages.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.errors import GestureSimError

__all__ = ["ARPABET", "SIL", "Phone", "PhoneEmission", "PhoneRecogniser", "Transcript", "Word",
           "align_transcript", "letter_pronunciation", "normalise_label", "number_words",
           "phones_from_textgrid", "recognise_phones", "words_from_textgrid"]

#: The silence label.
SIL = "SIL"
#: The 39 ARPAbet phones of the CMU dictionary (no stress digits), and SIL.
ARPABET: tuple[str, ...] = (
    "AA", "AE", "AH", "AO", "AW", "AY", "B", "CH", "D", "DH", "EH", "ER", "EY", "F", "G", "HH",
    "IH", "IY", "JH", "K", "L", "M", "N", "NG", "OW", "OY", "P", "R", "S", "SH", "T", "TH",
    "UH", "UW", "V", "W", "Y", "Z", "ZH", SIL)
_ARPA = frozenset(ARPABET)
_VOWELS = frozenset(("AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW",
                     "OY", "UH", "UW"))
#: Decoder frame rate (frames/s): PocketSphinx's 10 ms frames.
FRAME_RATE = 100


@dataclass(frozen=True)
class Phone:
    """One phone segment.

    Attributes:
        start_s, end_s: its span (s on the stream clock), ``end_s >= start_s``.
        label: ARPAbet in upper case without stress digit (``"AY"``), or ``"SIL"``.
    """

    start_s: float
    end_s: float
    label: str

    @property
    def centre_s(self) -> float:
        """Midpoint (s)."""
        return 0.5 * (self.start_s + self.end_s)

    @property
    def duration_s(self) -> float:
        """Length (s)."""
        return self.end_s - self.start_s


@dataclass(frozen=True)
class Word:
    """One word with its span (s) and its phones (in order, inside the span)."""

    start_s: float
    end_s: float
    text: str
    phones: tuple[Phone, ...] = ()


@dataclass(frozen=True)
class PhoneEmission:
    """A phone as a live recogniser gives it: the phone and when it became known.

    Attributes:
        phone: the phone (times on the stream clock).
        emitted_s: the end of the audio decoded when it was emitted (s, stream clock); it does
            not depend on thread timing, only on the audio fed.
    """

    phone: Phone
    emitted_s: float

    @property
    def latency_s(self) -> float:
        """Emission time minus the phone's end (s)."""
        return self.emitted_s - self.phone.end_s


@dataclass(frozen=True)
class Transcript:
    """A force-aligned transcript.

    Attributes:
        words: the transcript's words that were aligned, in order, with their phones.
        phones: all phones in order, with ``SIL`` for the pauses (contiguous from 0 to the end
            of the audio).
        fallback: words given a letter-rule pronunciation (not in the dictionary).
        skipped: tokens left out (no letters).
    """

    words: tuple[Word, ...]
    phones: tuple[Phone, ...]
    fallback: tuple[str, ...] = ()
    skipped: tuple[str, ...] = ()


_STRESS = re.compile(r"[0-9]+$")


def normalise_label(label: str) -> str:
    """An aligner's or a TextGrid's phone label as this module's label.

    Upper case, stress digits stripped (``"ay1"`` → ``"AY"``); empty, ``sil``, ``sp``, ``spn``,
    ``<sil>`` and PocketSphinx's noise phones (``+NSN+``) → ``"SIL"``. An unknown label raises.
    """
    s = label.strip().upper()
    if not s or s in ("SIL", "SP", "SPN", "<SIL>", "<S>", "</S>", "NSN") or s.startswith("+"):
        return SIL
    s = _STRESS.sub("", s)
    if s not in _ARPA:
        raise GestureSimError(f"unknown phone label {label!r} (expected ARPAbet, e.g. AY1)")
    return s


def _merge_sil(phones: Iterable[Phone]) -> list[Phone]:
    out: list[Phone] = []
    for p in phones:
        if out and p.label == SIL and out[-1].label == SIL:
            out[-1] = Phone(out[-1].start_s, max(out[-1].end_s, p.end_s), SIL)
        else:
            out.append(p)
    return out


# --------------------------------------------------------------------------------------------
# (a) TextGrid
# --------------------------------------------------------------------------------------------


def phones_from_textgrid(path: str | os.PathLike[str], tier: str = "phones") -> list[Phone]:
    """The phones of a TextGrid's phone tier, in time order (pauses as ``SIL``, merged).

    Raises:
        GestureSimError: unreadable file, no such tier, an unknown phone label.
    """
    from gesture_sim.audio.textgrid import read_textgrid

    grid = read_textgrid(path)
    try:
        phones = [Phone(iv.xmin, iv.xmax, normalise_label(iv.text))
                  for iv in grid.tier(tier) if iv.xmax > iv.xmin]
    except GestureSimError as exc:
        raise GestureSimError(f"{path}: {exc}") from None
    return _merge_sil(sorted(phones, key=lambda p: p.start_s))


def _words_with_phones(spans: Sequence[tuple[float, float, str]],
                       phones: Sequence[Phone]) -> list[Word]:
    """Words (s, s, text) given the non-SIL phones whose midpoint falls inside them."""
    out: list[Word] = []
    mids = np.array([p.centre_s for p in phones]) if phones else np.zeros(0)
    for a, b, text in spans:
        i0, i1 = np.searchsorted(mids, [a, b])
        inside = tuple(p for p in phones[int(i0):int(i1)] if p.label != SIL)
        out.append(Word(a, b, text, inside))
    return out


def words_from_textgrid(path: str | os.PathLike[str], word_tier: str = "words",
                        phone_tier: str = "phones") -> list[Word]:
    """The words of a TextGrid (lower case; pauses left out), each with its phones.

    Raises:
        GestureSimError: unreadable file, a tier missing, an unknown phone label.
    """
    from gesture_sim.audio.textgrid import read_textgrid

    grid = read_textgrid(path)
    spans = [(iv.xmin, iv.xmax, iv.text.strip().lower()) for iv in grid.tier(word_tier)
             if iv.text.strip()]
    return _words_with_phones(spans, phones_from_textgrid(path, phone_tier))


# --------------------------------------------------------------------------------------------
# Decoder helpers
# --------------------------------------------------------------------------------------------


def _pocketsphinx():
    try:
        import pocketsphinx
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise GestureSimError("phone timing needs the pocketsphinx package "
                              "(pip install pocketsphinx)") from exc
    return pocketsphinx


def _to_pcm16(samples: np.ndarray, sr: int) -> np.ndarray:
    """float (n,) at ``sr`` Hz → int16 (m,) at 16 kHz."""
    from gesture_sim.audio.sources import resample_to_16k

    x = np.asarray(samples)
    if x.ndim != 1:
        raise GestureSimError(f"audio must be mono (n,), got shape {x.shape}")
    if not np.issubdtype(x.dtype, np.floating):
        from gesture_sim.audio.sources import to_float_mono

        x = to_float_mono(x)
    if int(sr) <= 0:
        raise GestureSimError(f"bad sample rate {sr}")
    x = resample_to_16k(np.nan_to_num(x.astype(np.float32)), int(sr))
    return (np.clip(x, -1.0, 1.0) * 32767.0).astype(np.int16)


def _base_word(name: str) -> str:
    """``"to(3)"`` → ``"to"``."""
    return re.sub(r"\(\d+\)$", "", name)


def _is_filler(name: str) -> bool:
    return name in ("<s>", "</s>", "<sil>", "[NOISE]") or name.startswith(("+", "["))


# Letter rules: (grapheme, phones), longest first; vowels get a rough default quality.
_LETTER_RULES: tuple[tuple[str, str], ...] = (
    ("tch", "CH"), ("igh", "AY"), ("ough", "AO"), ("tion", "SH AH N"), ("sion", "ZH AH N"),
    ("ch", "CH"), ("sh", "SH"), ("th", "TH"), ("ph", "F"), ("ng", "NG"), ("ck", "K"),
    ("qu", "K W"), ("wh", "W"), ("gh", "G"), ("kn", "N"), ("wr", "R"),
    ("ee", "IY"), ("ea", "IY"), ("oo", "UW"), ("ou", "AW"), ("ow", "OW"), ("oa", "OW"),
    ("ai", "EY"), ("ay", "EY"), ("ei", "EY"), ("ey", "EY"), ("oi", "OY"), ("oy", "OY"),
    ("au", "AO"), ("aw", "AO"), ("ie", "IY"), ("ue", "UW"), ("er", "ER"), ("ir", "ER"),
    ("ur", "ER"), ("ar", "AA R"), ("or", "AO R"),
    ("a", "AE"), ("e", "EH"), ("i", "IH"), ("o", "AA"), ("u", "AH"), ("y", "IY"),
    ("b", "B"), ("c", "K"), ("d", "D"), ("f", "F"), ("g", "G"), ("h", "HH"), ("j", "JH"),
    ("k", "K"), ("l", "L"), ("m", "M"), ("n", "N"), ("p", "P"), ("r", "R"), ("s", "S"),
    ("t", "T"), ("v", "V"), ("w", "W"), ("x", "K S"), ("z", "Z"),
)


def letter_pronunciation(word: str) -> list[str]:
    """A rough ARPAbet pronunciation of an English word from letter rules (no dictionary).

    Greedy longest-match over :data:`_LETTER_RULES`; doubled consonants count once, a final
    silent ``e`` after a consonant is dropped, ``y`` before a vowel is the glide ``Y``.
    Non-letters are ignored; ``[]`` for a word without letters.
    """
    w = re.sub(r"[^a-z]", "", word.lower())
    if len(w) > 2 and w.endswith("e") and w[-2] not in "aeiouy":
        w = w[:-1]
    out: list[str] = []
    i = 0
    while i < len(w):
        if i > 0 and w[i] == w[i - 1] and w[i] not in "aeiou":
            i += 1
            continue
        if w[i] == "y" and i + 1 < len(w) and w[i + 1] in "aeiou":
            out.append("Y")
            i += 1
            continue
        for g, ph in _LETTER_RULES:
            if w.startswith(g, i):
                out.extend(ph.split())
                i += len(g)
                break
        else:  # pragma: no cover - every letter has a rule
            i += 1
    return out


_ONES = ("zero one two three four five six seven eight nine ten eleven twelve thirteen "
         "fourteen fifteen sixteen seventeen eighteen nineteen").split()
_TENS = "_ _ twenty thirty forty fifty sixty seventy eighty ninety".split()


def number_words(n: int) -> list[str]:
    """An integer 0..999999 in English words (``105`` → ``one hundred five``); 4-digit
    numbers 1100..1999 and 2010..2099 read as years (``1984`` → ``nineteen eighty four``)."""
    if n < 20:
        return [_ONES[n]]
    if n < 100:
        return [_TENS[n // 10]] + ([_ONES[n % 10]] if n % 10 else [])
    if 1100 <= n < 2000 or 2010 <= n < 2100:
        hi, lo = divmod(n, 100)
        return number_words(hi) + (["hundred"] if lo == 0 else
                                   (["oh"] if lo < 10 else []) + number_words(lo))
    if n < 1000:
        hi, lo = divmod(n, 100)
        return [_ONES[hi], "hundred"] + (number_words(lo) if lo else [])
    hi, lo = divmod(n, 1000)
    return number_words(hi) + ["thousand"] + (number_words(lo) if lo else [])


def _prepare_words(decoder, text: str) -> tuple[list[str], list[str], list[str]]:
    """Tokens of ``text`` as dictionary words; words given letter rules; tokens skipped."""
    words: list[str] = []
    fallback: list[str] = []
    skipped: list[str] = []
    for raw in text.split():
        digits = re.sub(r"[,.!?;:]+$", "", raw)
        if digits.isdigit() and int(digits) < 1_000_000:
            words.extend(number_words(int(digits)))
            continue
        tok = re.sub(r"[^a-z'\-]", "", raw.lower()).strip("'-")
        if not re.search(r"[a-z]", tok):
            skipped.append(raw)
            continue
        if decoder.lookup_word(tok) is not None:
            words.append(tok)
            continue
        parts = [p for p in re.split(r"-+", tok) if p]
        if len(parts) > 1 and all(decoder.lookup_word(p) is not None for p in parts):
            words.extend(parts)
            continue
        if tok.endswith("'s") and decoder.lookup_word(tok[:-2]) is not None:
            pron = decoder.lookup_word(tok[:-2]) + " Z"
            decoder.add_word(tok, pron, False)
            words.append(tok)
            continue
        pron = letter_pronunciation(tok)
        name = re.sub(r"[^a-z']", "", tok)
        if not pron or not name:
            skipped.append(raw)
            continue
        if decoder.lookup_word(name) is None:
            decoder.add_word(name, " ".join(pron), False)
        fallback.append(name)
        words.append(name)
    return words, fallback, skipped


# --------------------------------------------------------------------------------------------
# (b) Forced alignment
# --------------------------------------------------------------------------------------------


#: Beams of the second alignment attempt (PocketSphinx config keys).
_WIDE_BEAMS: dict[str, object] = {"beam": 1e-80, "wbeam": 1e-60, "pbeam": 1e-80}


def _align_decoder(ps, text: str, extra: dict[str, object]):
    """A decoder for alignment and the transcript's words prepared for it."""
    # bestpath off: the lattice best path can give a phone a 1-frame duration that the
    # second (state) pass cannot align ("impossible duration"), failing the whole alignment
    kw: dict[str, object] = {"loglevel": "FATAL", "bestpath": False}
    kw.update(extra)
    decoder = ps.Decoder(ps.Config(**kw))
    words, fallback, skipped = _prepare_words(decoder, text)
    return decoder, words, fallback, skipped


def _warn_oov(fallback: list[str], skipped: list[str]) -> None:
    if not (fallback or skipped):
        return
    what = []
    if fallback:
        what.append(f"{len(fallback)} not in the dictionary, given letter-rule "
                    f"pronunciations ({', '.join(sorted(set(fallback))[:8])})")
    if skipped:
        what.append(f"{len(skipped)} without letters skipped ({', '.join(skipped[:8])})")
    warnings.warn("align_transcript: transcript words " + "; ".join(what), stacklevel=3)


def _run_alignment(decoder, raw: bytes, words: list[str]
                   ) -> tuple[list[tuple[str, int, int]], list[tuple[str, int, int]]]:
    """Word pass then phone pass: word segments (word, first, last frame) and phones
    (name, start frame, frames). RuntimeError when there is no path."""
    decoder.set_align_text(" ".join(words))
    decoder.start_utt()
    decoder.process_raw(raw, full_utt=True)
    decoder.end_utt()
    if decoder.hyp() is None:
        raise RuntimeError("no path through the transcript")
    segs = [(_base_word(s.word), int(s.start_frame), int(s.end_frame)) for s in decoder.seg()]
    decoder.set_alignment()
    decoder.start_utt()
    decoder.process_raw(raw, full_utt=True)
    decoder.end_utt()
    al = decoder.get_alignment()
    # Flat iteration only: iterating an AlignmentEntry's children crashes PocketSphinx 5.0.
    return segs, [(p.name, int(p.start), int(p.duration)) for p in al.phones()]


def align_transcript(samples: np.ndarray, sr: int, text: str, *,
                     settings: dict[str, object] | None = None) -> Transcript:
    """Force-align ``text`` to the audio: words and phones with times (s from the first sample).

    Args:
        samples: mono audio (n,), float in [-1, 1] (or integer PCM).
        sr: its sample rate (Hz); resampled to 16 kHz when different.
        text: the words spoken, in order (punctuation and case ignored; see the module
            docstring for words missing from the dictionary).
        settings: extra PocketSphinx config keys (e.g. ``{"beam": 1e-60}``); ``None``: the
            default beams, and when they find no path (synthetic or noisy speech) a second
            attempt with wide ones (:data:`_WIDE_BEAMS`).

    Returns:
        A :class:`Transcript`; its ``phones`` cover the audio contiguously (pauses ``SIL``).

    Raises:
        GestureSimError: no words to align, audio too short for the words, or the decoder
            found no path through the transcript (one line).
    """
    ps = _pocketsphinx()
    pcm = _to_pcm16(samples, sr)
    n_frames = len(pcm) * FRAME_RATE // SAMPLE_RATE
    attempts = [dict(settings or {})]
    if settings is None:  # the default beams first (fast); wide beams when they prune the path
        attempts.append(dict(_WIDE_BEAMS))
    for k, extra in enumerate(attempts):
        decoder, words, fallback, skipped = _align_decoder(ps, text, extra)
        if k == 0:
            _warn_oov(fallback, skipped)
            if not words:
                raise GestureSimError("align_transcript: the transcript has no words to align")
            if n_frames < 3 * len(words):
                raise GestureSimError(f"align_transcript: {len(pcm) / SAMPLE_RATE:.2f} s of "
                                      f"audio is too short for {len(words)} words")
        try:
            segs, aphones = _run_alignment(decoder, pcm.tobytes(), words)
            break
        except RuntimeError as exc:
            if k == len(attempts) - 1:
                raise GestureSimError(f"align_transcript: PocketSphinx could not align the "
                                      f"transcript ({exc}); is it the text of this audio?"
                                      ) from None
    phones: list[Phone] = []
    for name, start, dur in aphones:
        a, b = start / FRAME_RATE, (start + dur) / FRAME_RATE
        if b > a:
            phones.append(Phone(a, b, normalise_label(name)))
    end_s = len(pcm) / SAMPLE_RATE
    if phones and phones[-1].end_s < end_s:
        phones.append(Phone(phones[-1].end_s, end_s, SIL))
    phones = _merge_sil(phones)
    spans = [(a / FRAME_RATE, (b + 1) / FRAME_RATE, w) for w, a, b in segs if not _is_filler(w)]
    return Transcript(tuple(_words_with_phones(spans, phones)), tuple(phones), tuple(fallback),
                      tuple(skipped))


# --------------------------------------------------------------------------------------------
# (c) Live phones
# --------------------------------------------------------------------------------------------

#: Typical relative phone durations for spreading a recognised word's span over its phones.
_REL_DUR_VOWEL = 2.0
_REL_DUR_CONS = 1.0


@dataclass
class RecogniserStats:
    """Counters of a :class:`PhoneRecogniser` (s of audio, counts)."""

    fed_s: float = 0.0
    utterances: int = 0
    emitted: int = 0


class PhoneRecogniser:
    """Live phones from audio alone, incrementally (see the module docstring for the modes).

    Args:
        mode: ``"allphone"`` (phone loop with the shipped phonetic LM) or ``"words"``
            (continuous word decoding with the shipped LM, words expanded to phones).
        sr: the rate (Hz) of the samples that will be pushed (resampled causally to 16 kHz).
        hold_s: a segment is emitted once the decoded audio reaches ``hold_s`` past its end
            (and it is not the last of the partial hypothesis); larger: steadier, later.
        poll_s: how often (s of audio) the partial hypothesis is read.
        max_utt_s: after this much audio in one decoder utterance, the utterance is ended at
            the next pause of the hypothesis (``SIL`` of 0.15 s or more); at twice this, it is
            ended anyway (bounded memory for endless streams).
        settings: extra PocketSphinx config keys (they replace the mode's defaults).

    Use: ``push(samples)`` with consecutive chunks (any length) returns the phones that
    became known, each with its emission time (:class:`PhoneEmission`); ``finish()`` ends the
    stream and returns the rest. Times are on the stream clock that starts at ``t0``.
    """

    #: Default decoder settings per mode (the phone-loop LM weight and insertion penalty are
    #: PocketSphinx's allphone defaults; beams widened a little).
    MODE_SETTINGS: dict[str, dict[str, object]] = {
        "allphone": {"beam": 1e-20, "pbeam": 1e-20, "lw": 2.0, "pip": 1.0},
        "words": {},
    }

    def __init__(self, mode: str = "allphone", *, sr: int = SAMPLE_RATE, hold_s: float = 0.05,
                 poll_s: float = 0.05, max_utt_s: float = 10.0, t0: float = 0.0,
                 settings: dict[str, object] | None = None) -> None:
        if mode not in self.MODE_SETTINGS:
            raise GestureSimError(f"phone recogniser: unknown mode {mode!r} "
                                  f"(expected one of {', '.join(self.MODE_SETTINGS)})")
        ps = _pocketsphinx()
        self.mode = mode
        kw: dict[str, object] = {"loglevel": "FATAL"}
        kw.update(self.MODE_SETTINGS[mode] if settings is None else settings)
        if mode == "allphone":
            path = Path(ps.get_model_path()) / "en-us" / "en-us-phone.lm.bin"
            if not path.is_file():
                raise GestureSimError(f"phone recogniser: the phonetic LM {path} is missing "
                                      "from the pocketsphinx package")
            kw["allphone"] = str(path)
            kw["lm"] = None
        self._ps = ps.Decoder(ps.Config(**kw))
        self._resampler = None
        if int(sr) != SAMPLE_RATE:
            from gesture_sim.audio.sources import StreamingResampler

            self._resampler = StreamingResampler(int(sr))
        self.hold_frames = max(0, round(hold_s * FRAME_RATE))
        self.poll_samples = max(160, round(poll_s * SAMPLE_RATE))
        self.max_utt_frames = max(100, round(max_utt_s * FRAME_RATE))
        self.stats = RecogniserStats()
        #: Words emitted so far (``"words"`` mode), with their emission times (s).
        self.words: list[tuple[Word, float]] = []
        self._t_utt = float(t0)  # stream time of the current utterance's frame 0
        self._fed = 0  # 16 kHz samples fed in total
        self._since_poll = 0
        self._in_utt = False
        self._done_frame = 0  # utterance frames already covered by emitted phones
        self._last_end_s = float(t0)
        self._t0 = float(t0)
        self._finished = False

    @property
    def t_fed(self) -> float:
        """Stream time (s) of the end of the audio fed so far."""
        return self._t0 + self._fed / SAMPLE_RATE

    def push(self, samples: np.ndarray) -> list[PhoneEmission]:
        """Feed the next chunk (float (n,) at the constructor's ``sr``); phones now known."""
        if self._finished:
            raise GestureSimError("phone recogniser: push after finish")
        x = np.asarray(samples, dtype=np.float32)
        if x.ndim != 1:
            raise GestureSimError(f"phone recogniser: audio must be mono (n,), got {x.shape}")
        if self._resampler is not None:
            x = self._resampler.process(x)
        out: list[PhoneEmission] = []
        pcm = (np.clip(np.nan_to_num(x), -1.0, 1.0) * 32767.0).astype(np.int16)
        i = 0
        while i < len(pcm):
            n = min(len(pcm) - i, self.poll_samples - self._since_poll)
            if not self._in_utt:
                self._ps.start_utt()
                self._in_utt = True
                self.stats.utterances += 1
            self._ps.process_raw(pcm[i:i + n].tobytes(), False, False)
            self._fed += n
            self._since_poll += n
            i += n
            if self._since_poll >= self.poll_samples:
                self._since_poll = 0
                out.extend(self._poll(final=False))
        self.stats.fed_s = self._fed / SAMPLE_RATE
        return out

    def finish(self) -> list[PhoneEmission]:
        """End of stream: the phones not yet emitted (emission time: the end of the stream)."""
        if self._finished:
            return []
        self._finished = True
        return self._end_utt()

    # -- internals ------------------------------------------------------------------------

    def _segments(self) -> list[tuple[str, int, int]]:
        """The current hypothesis as (label, first frame, last frame), utterance frames."""
        return [(s.word, int(s.start_frame), int(s.end_frame)) for s in self._ps.seg() or ()]

    def _end_utt(self) -> list[PhoneEmission]:
        if not self._in_utt:
            return []
        self._ps.end_utt()
        self._in_utt = False
        out = self._emit(self._segments(), final=True)
        if out and out[-1].phone.end_s < self.t_fed:  # the last partial frame: no gap
            last = out[-1]
            out[-1] = PhoneEmission(Phone(last.phone.start_s, self.t_fed, last.phone.label),
                                    last.emitted_s)
            self._last_end_s = self.t_fed
        self._t_utt = self.t_fed
        self._done_frame = 0
        return out

    def _poll(self, final: bool) -> list[PhoneEmission]:
        segs = self._segments()
        out = self._emit(segs, final=final)
        frames = int(self._ps.n_frames())
        if frames >= self.max_utt_frames:
            pause = bool(segs) and segs[-1][0] in ("SIL", "<sil>") and \
                segs[-1][2] - segs[-1][1] >= 15
            if pause or frames >= 2 * self.max_utt_frames:
                out.extend(self._end_utt())
        return out

    def _emit(self, segs: list[tuple[str, int, int]], final: bool) -> list[PhoneEmission]:
        if not segs:
            return []
        n_frames = int(self._ps.n_frames())
        ready = segs if final else [s for s in segs[:-1]
                                    if s[2] + 1 + self.hold_frames <= n_frames]
        t_now = self.t_fed
        out: list[PhoneEmission] = []
        for name, sf, ef in ready:
            if ef + 1 <= self._done_frame:
                continue
            if sf < self._done_frame:
                # a revision of a segment already (partly) emitted: a remainder shorter than
                # half of it is absorbed by the next phone (which starts where the last ended)
                if (ef + 1 - self._done_frame) < 0.5 * (ef + 1 - sf):
                    continue
            if self.mode == "allphone":
                phones = [(normalise_label(name), max(sf, self._done_frame), ef + 1)]
            else:
                phones = [(lab, max(a, self._done_frame), b)
                          for lab, a, b in self._word_phones(name, sf, ef + 1, t_now)
                          if b > self._done_frame]
            for label, a, b in phones:
                if b <= a:
                    continue
                # contiguous: the hypothesis covers every frame, so a phone starts where the
                # last emitted one ended (revisions of boundaries are absorbed here)
                start = self._last_end_s if self._last_end_s >= self._t_utt else \
                    self._t_utt + a / FRAME_RATE
                end = max(start, self._t_utt + b / FRAME_RATE)
                if out and label == SIL and out[-1].phone.label == SIL:
                    prev = out.pop()
                    start = prev.phone.start_s
                out.append(PhoneEmission(Phone(start, end, label), t_now))
                self._last_end_s = end
            self._done_frame = ef + 1
        self.stats.emitted += len(out)
        return out

    def _word_phones(self, name: str, a: int, b: int, t_now: float
                     ) -> list[tuple[str, int, int]]:
        """A recognised word's frames [a, b) shared among its dictionary phones."""
        base = _base_word(name)
        if _is_filler(base):
            return [(SIL, a, b)]
        pron = self._ps.lookup_word(name) or self._ps.lookup_word(base) or ""
        labels = [normalise_label(p) for p in pron.split()]
        if not labels:
            return [(SIL, a, b)]
        self.words.append((Word(self._t_utt + a / FRAME_RATE, self._t_utt + b / FRAME_RATE,
                                base), t_now))
        w = np.array([_REL_DUR_VOWEL if lab in _VOWELS else _REL_DUR_CONS for lab in labels])
        edges = a + np.concatenate([[0.0], np.cumsum(w)]) / w.sum() * (b - a)
        out = []
        for k, lab in enumerate(labels):
            out.append((lab, int(round(edges[k])), int(round(edges[k + 1]))))
        return out


def recognise_phones(samples: np.ndarray, sr: int = SAMPLE_RATE, *, chunk_s: float = 0.01,
                     mode: str = "allphone", **kwargs: object) -> list[PhoneEmission]:
    """Run a :class:`PhoneRecogniser` over a recording, fed ``chunk_s`` chunks as a live
    stream would be (deterministic); all emissions in order. ``kwargs`` go to the recogniser."""
    rec = PhoneRecogniser(mode, sr=sr, **kwargs)  # type: ignore[arg-type]
    n = max(1, round(chunk_s * sr))
    x = np.asarray(samples, dtype=np.float32)
    out: list[PhoneEmission] = []
    for i in range(0, len(x), n):
        out.extend(rec.push(x[i:i + n]))
    out.extend(rec.finish())
    return out

