"""Words that call for gestures: keyword spotting with PocketSphinx, and transcripts.

A :class:`KeywordTable` maps words and phrases (``"thank you"``) to the motion library's semantic
labels (``"bow"``), each with a detection threshold. Two sources turn speech into
:class:`~gesture_sim.contracts.Keyword` hits with that table:

* :class:`KeywordSpotter`: PocketSphinx keyword-list search (``kws`` mode: each phrase's HMM
  chain against a free phone loop) over the same 16 kHz float32 :class:`AudioBlock` stream the
  prosody tracker sees. ``push`` only appends to a bounded queue; a worker thread decodes. A
  recogniser that falls behind lags, and past ``max_queue_s`` of backlog drops whole blocks
  (counted in :attr:`KeywordSpotter.stats`); the caller is never stalled. :func:`spot_file` runs
  the same code over a whole recording, deterministically.
* :func:`transcript_keywords`: the same table applied to a Praat TextGrid word tier or a plain
  ``start end word`` list, for users with aligned text.

Scores. PocketSphinx reports a detection when the phrase's path beats the best phone-loop path
over the same frames by the phrase's threshold (a likelihood ratio, ``1e-20``: the format of a
PocketSphinx keyword list). :attr:`Keyword.confidence` is that ratio's log10 (``-20.0``), so the
table's thresholds and the hits' confidences are on one scale; short words need higher
thresholds (fewer frames, fewer chances to lose against the phone loop) than long phrases.

Confirmation. Against a free phone loop, noisy or fast real speech also "spots" phrases inside
other words (``"thank you very much"`` in ``"...in New Jersey now"``), with scores no threshold
separates from real ones. So a spotted phrase is emitted only when PocketSphinx's continuous
recogniser (language model and dictionary of the wheel), decoding the audio from ``pad_s``
before the hit to ``pad_s`` after it, has at least half the phrase's words in one of its 10 best
hypotheses (:class:`~gesture_sim.audio.utterances.PhraseConfirmer`); the decision waits for
``pad_s`` (0.6 s) of audio after the phrase, which is the latency it adds. Rejected hits are
counted in :attr:`SpotterStats.rejected`.

Times. The decoder works in 10 ms frames from the start of its utterance; a hit's ``t_start`` /
``t_end`` come from its segment frames. The decoder confirms a hit ``kws_delay`` frames after its
last frame (it waits for a better-scoring end); ``t_emitted`` is the end of the audio that had
been decoded when the hit was decided (confirmed), so it does not depend on thread timing, only
on the blocks pushed. The decoder model (acoustic model, dictionary) is the US English one
inside the ``pocketsphinx`` wheel; nothing is downloaded.

Table files (``--keywords FILE``): JSON (``{"keywords": [{"phrase": "thank you", "label": "bow",
"threshold": 1e-20}, ...]}``, see ``keywords_default.json``) or text, one entry per line::

    bow   thank you   /1e-20/      # label, phrase, optional threshold (default 1e-20)

Every word must be in the PocketSphinx dictionary; an entry whose label the motion library
lacks is left out by :meth:`KeywordTable.for_labels` (the spotter does that itself).
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
import tempfile
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gesture_sim.audio.decoder_worker import DecoderWorker, WorkerStats
from gesture_sim.audio.utterances import (
    UTTERANCE_WORDS,
    ConfirmSettings,
    PhraseConfirmer,
    UtteranceRecognizer,
)
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock, Keyword
from gesture_sim.errors import GestureSimError

__all__ = [
    "DEFAULT_TABLE", "KeywordEntry", "KeywordSpotter", "KeywordTable", "SpotterStats",
    "check_keyword_labels",
    "keywords_from_words", "read_word_list", "spot_file", "transcript_keywords",
]

#: The default table, shipped inside the package.
DEFAULT_TABLE = Path(__file__).with_name("keywords_default.json")
#: How spotted phrases are confirmed by default (pad 0.6 s, 10 best hypotheses, half the words).
DEFAULT_CONFIRM = ConfirmSettings()
#: Threshold of an entry that gives none (likelihood ratio).
DEFAULT_THRESHOLD = 1e-20
#: Decoder frame rate (frames/s): PocketSphinx's 10 ms frames.
FRAME_RATE = 100
#: PocketSphinx's constant offset of a kws detection's "prob" (KWS_MAX in kws_search.c), in
#: scaled log units; see :func:`_score_from_prob`.
_KWS_MAX = 1500
#: Scaled log units: logmath base (1.0001) and the senone score shift (SENSCR_SHIFT = 10).
_LOG_BASE = 1.0001
_SENSCR_SHIFT = 10
#: Samples per decoder call (10 ms): short calls bound the time the decoder holds the GIL.
_CHUNK = SAMPLE_RATE // FRAME_RATE
#: Silence appended by :meth:`KeywordSpotter.finish` so that a hit at the very end is confirmed
#: (more than ``kws_delay`` frames plus the feature look-ahead), s.
_FLUSH_S = 0.3

_WORD = re.compile(r"^[a-z][a-z'\-.]*$")


# --------------------------------------------------------------------------------------------
# The table
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class KeywordEntry:
    """One row of a keyword table.

    Attributes:
        phrase: lower-case words separated by single spaces (``"thank you"``).
        label: the motion library's semantic label it asks for (``"bow"``).
        threshold: detection threshold as a likelihood ratio (``1e-20``; smaller finds more).
    """

    phrase: str
    label: str
    threshold: float = DEFAULT_THRESHOLD

    @property
    def log10_threshold(self) -> float:
        """The threshold on the :attr:`Keyword.confidence` scale (log10)."""
        return math.log10(self.threshold)


def _decoder_dictionary():
    """A PocketSphinx decoder with the default model, for dictionary look-ups (cached)."""
    global _LOOKUP
    if _LOOKUP is None:
        _LOOKUP = _new_decoder()
    return _LOOKUP


_LOOKUP = None


#: Decoder settings (PocketSphinx config keys) of the spotter: a beam wide enough that one
#: keyphrase's partial paths are not pruned by another's good score (the default 1e-48 makes a
#: phrase's score depend on the rest of the table), and a phone-loop entry probability.
DECODER_SETTINGS: dict[str, float] = {"beam": 1e-80, "kws_plp": 0.1}


def _new_decoder(kws_file: str | None = None, delay: int | None = None,
                 settings: dict[str, float] | None = None):
    try:
        import pocketsphinx
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise GestureSimError("keyword spotting needs the pocketsphinx package "
                              "(pip install pocketsphinx)") from exc
    kwargs: dict[str, object] = {"loglevel": "FATAL"}
    if kws_file is not None:
        kwargs["kws"] = kws_file
        kwargs.update(DECODER_SETTINGS if settings is None else settings)
    if delay is not None:
        kwargs["kws_delay"] = int(delay)
    config = pocketsphinx.Config(**kwargs)
    if kws_file is None:  # dictionary only: no search to build
        config["lm"] = None
    return pocketsphinx.Decoder(config)


def in_dictionary(word: str) -> bool:
    """Whether ``word`` (lower case) has a pronunciation in the PocketSphinx dictionary."""
    return _decoder_dictionary().lookup_word(word) is not None


@dataclass(frozen=True)
class KeywordTable:
    """Phrases -> semantic labels, with per-phrase thresholds.

    Attributes:
        entries: the rows, in file order; phrases are unique.
        source: where the table came from (a path, or ``"default"``).
    """

    entries: tuple[KeywordEntry, ...]
    source: str = "default"

    @classmethod
    def load(cls, path: str | os.PathLike[str] | None = None) -> KeywordTable:
        """Read a table (JSON or text, see the module docstring); ``None``: the default one.

        Raises:
            GestureSimError: unreadable or malformed file, a bad threshold, a duplicate phrase,
                a word missing from the PocketSphinx dictionary (one line, naming the file).
        """
        p = DEFAULT_TABLE if path is None else Path(path)
        name = "default keyword table" if path is None else str(p)
        try:
            text = p.read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError) as exc:
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise GestureSimError(f"{name}: cannot read keyword table ({why})") from None
        stripped = text.lstrip()
        if stripped.startswith(("{", "[")):
            rows = _parse_json(text, name)
        else:
            rows = _parse_text(text, name)
        if not rows:
            raise GestureSimError(f"{name}: keyword table has no entries")
        return cls.from_rows(rows, source="default" if path is None else str(p))

    @classmethod
    def from_rows(cls, rows: Iterable[tuple[str, str, float]], source: str = "table",
                  check_dictionary: bool = True) -> KeywordTable:
        """Build a table from ``(phrase, label, threshold)`` rows, checking each one."""
        entries: list[KeywordEntry] = []
        seen: dict[str, str] = {}
        for phrase, label, threshold in rows:
            words = str(phrase).lower().split()
            phrase_n = " ".join(words)
            where = f"{source}: keyword {phrase!r}"
            if not words:
                raise GestureSimError(f"{source}: empty keyword phrase")
            if not label or not re.match(r"^[A-Za-z_][\w\-]*$", str(label)):
                raise GestureSimError(f"{where}: bad label {label!r}")
            try:
                thr = float(threshold)
            except (TypeError, ValueError):
                raise GestureSimError(f"{where}: threshold {threshold!r} is not a number") \
                    from None
            if not (math.isfinite(thr) and 0.0 < thr <= 1e10):
                raise GestureSimError(f"{where}: threshold {threshold!r} must be a likelihood "
                                      "ratio > 0 such as 1e-20")
            for w in words:
                if not _WORD.match(w):
                    raise GestureSimError(f"{where}: {w!r} is not a word (letters, "
                                          "apostrophes, hyphens)")
                if check_dictionary and not in_dictionary(w):
                    raise GestureSimError(f"{where}: {w!r} is not in the PocketSphinx "
                                          "dictionary (cmudict-en-us); use a word it knows")
            if phrase_n in seen:
                raise GestureSimError(f"{where}: listed twice")
            seen[phrase_n] = str(label)
            entries.append(KeywordEntry(phrase_n, str(label), thr))
        return cls(tuple(entries), source)

    def for_labels(self, labels: Iterable[str] | None) -> KeywordTable:
        """Only the entries whose label is in ``labels`` (``None``: all)."""
        if labels is None:
            return self
        keep = set(labels)
        return KeywordTable(tuple(e for e in self.entries if e.label in keep), self.source)

    def scaled(self, offset_decades: float) -> KeywordTable:
        """Every threshold multiplied by ``10**offset_decades`` (positive: stricter)."""
        return KeywordTable(tuple(KeywordEntry(e.phrase, e.label,
                                               e.threshold * 10.0 ** offset_decades)
                                  for e in self.entries), self.source)

    @property
    def phrases(self) -> tuple[str, ...]:
        return tuple(e.phrase for e in self.entries)

    def entry(self, phrase: str) -> KeywordEntry:
        """The entry of ``phrase`` (KeyError when absent)."""
        for e in self.entries:
            if e.phrase == phrase:
                return e
        raise KeyError(phrase)

    def with_utterance_words(self) -> KeywordTable:
        """The table plus the words recognised as utterances of their own
        (:data:`~gesture_sim.audio.utterances.UTTERANCE_WORDS`) that it does not list: what a
        transcript, which knows every word, is matched against."""
        have = set(self.phrases)
        extra = tuple(KeywordEntry(w, lab, 1.0) for w, lab in UTTERANCE_WORDS.items()
                      if w not in have)
        return KeywordTable(self.entries + extra, self.source)

    def kws_list(self) -> str:
        """The table as a PocketSphinx keyword-list file (``phrase /threshold/`` lines)."""
        return "".join(f"{e.phrase} /{e.threshold:.6g}/\n" for e in self.entries)


def check_keyword_labels(table: KeywordTable, labels: Sequence[str], explicit: bool,
                         none: str | None = None) -> list[str]:
    """The labels of a keyword table's rows that the run cannot play (sorted).

    Such rows can never request a gesture (the spotter skips them). For a table the user gave
    (``explicit``, ``--keywords FILE``) that is a one-line GestureSimError, as an unknown
    ``--label`` is; for the shipped table one warning line on stderr, and the run goes on.
    ``none``: why the run serves no labels at all (:func:`gesture_sim.methods.no_labels_note`),
    said instead of "the library lacks them".
    """
    missing = sorted({e.label for e in table.entries} - set(labels))
    if missing:
        name = "the shipped keyword table" if table.source == "default" else \
            f"keyword table {table.source}"
        msg = (f"{name} asks for label(s) {', '.join(missing)}, but {none}" if none else
               f"{name} asks for label(s) {', '.join(missing)} that this motion library lacks "
               f"(it has: {', '.join(labels) or 'none'})")
        if explicit:
            raise GestureSimError(f"{msg}; remove those rows or use a library with them")
        print(f"gesture-sim: warning: {msg}; those keywords are ignored", file=sys.stderr)
    return missing


def _parse_json(text: str, name: str) -> list[tuple[str, str, float]]:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise GestureSimError(f"{name}: not valid JSON ({exc.msg}, line {exc.lineno})") \
            from None
    items = data.get("keywords") if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise GestureSimError(f'{name}: expected {{"keywords": [...]}} or a list of entries')
    rows = []
    for i, item in enumerate(items):
        if not isinstance(item, dict) or "phrase" not in item or "label" not in item:
            raise GestureSimError(f'{name}: entry {i} needs "phrase" and "label"')
        rows.append((str(item["phrase"]), str(item["label"]),
                     item.get("threshold", DEFAULT_THRESHOLD)))
    return rows


def _parse_text(text: str, name: str) -> list[tuple[str, str, float]]:
    rows = []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        thr: object = DEFAULT_THRESHOLD
        m = re.search(r"/([^/]*)/\s*$", line)
        if m:
            thr = m.group(1).strip()
            line = line[: m.start()].strip()
        parts = line.split()
        if len(parts) < 2:
            raise GestureSimError(f"{name}: line {n}: expected 'LABEL PHRASE [/THRESHOLD/]', "
                                  f"got {raw.strip()!r}")
        rows.append((" ".join(parts[1:]), parts[0], thr))
    return rows


# --------------------------------------------------------------------------------------------
# The spotter
# --------------------------------------------------------------------------------------------


def _score_from_prob(prob: float) -> float:
    """A kws segment's ``prob`` (logmath.exp of ``ratio - KWS_MAX`` in scaled log units) back
    to the log10 likelihood ratio that the thresholds are compared with."""
    if prob <= 0.0:
        return -math.inf
    scaled = math.log(prob) / math.log(_LOG_BASE) + _KWS_MAX
    return scaled * (1 << _SENSCR_SHIFT) * math.log10(_LOG_BASE)


@dataclass
class SpotterStats(WorkerStats):
    """Counters of a :class:`KeywordSpotter` (those of :class:`WorkerStats`, and:).

    Attributes:
        hits: keywords emitted.
        rejected: spotted phrases the recogniser did not confirm (not emitted).
    """

    hits: int = 0
    rejected: int = 0

    def to_dict(self) -> dict[str, float | int]:
        return {**self._common_dict(), "hits": self.hits, "rejected": self.rejected,
                **self._lag_dict()}


class _Decoder:
    """The PocketSphinx kws search over a stream: feeds 10 ms chunks, reports new hits.

    Single-threaded (the spotter's worker owns it). Stream time of decoder frame ``f`` is
    ``self._t0 + f / FRAME_RATE``; a gap in the stream (dropped blocks) restarts the utterance
    at the new block's time.
    """

    def __init__(self, table: KeywordTable, delay: int | None,
                 confirm: ConfirmSettings | None = None) -> None:
        from gesture_sim.fileio import temp_dir_prefix

        fd, self._kws_path = tempfile.mkstemp(prefix=temp_dir_prefix("kws"), suffix=".list")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(table.kws_list())
        try:
            self._ps = _new_decoder(self._kws_path, delay)
        finally:
            os.unlink(self._kws_path)
        self._table = {e.phrase: e for e in table.entries}
        self._t0: float | None = None  # stream time of the utterance's first sample
        self._n = 0  # samples fed in this utterance
        self._hyp_len = -1
        self._emitted: list[tuple[str, int, int]] = []  # (phrase, sf, ef) this utterance
        self._pcm = np.zeros(0, dtype="<i2")
        self._in_utt = False
        self._confirmer = None if confirm is None else PhraseConfirmer(confirm)
        # Audio of this utterance kept for confirming hits: int16 chunks from sample
        # ``self._ring_start`` on; longest phrase plus twice the pad plus the kws delay.
        longest = max((len(e.phrase.split()) for e in table.entries), default=1)
        pad = 0.0 if confirm is None else confirm.pad_s
        self._ring_keep = int((0.6 * longest + 2 * pad + 1.0) * SAMPLE_RATE)
        self._ring: deque[np.ndarray] = deque()
        self._ring_start = 0
        self._ring_n = 0
        self._pending: list[tuple[Keyword, int]] = []  # (hit, sample its decision waits for)
        self.rejected = 0

    @property
    def t_fed(self) -> float:
        """Stream time just after the last sample decoded (s)."""
        return (self._t0 or 0.0) + self._n / SAMPLE_RATE

    def _start(self, t0: float) -> None:
        if self._in_utt:
            self._ps.end_utt()
        self._ps.start_utt()
        self._in_utt = True
        self._t0, self._n, self._hyp_len, self._emitted = t0, 0, -1, []
        self._pcm = np.zeros(0, dtype="<i2")
        self._ring.clear()
        self._ring_start = self._ring_n = 0

    def feed(self, samples: np.ndarray, t_start: float) -> tuple[list[Keyword], bool]:
        """Decode float32 (n,) samples that start at stream time ``t_start`` (s).

        Returns the hits confirmed by this audio and whether the utterance was restarted (a
        gap before ``t_start``).
        """
        restarted = False
        hits: list[Keyword] = []
        t_next = (self._t0 or 0.0) + (self._n + len(self._pcm)) / SAMPLE_RATE
        if self._t0 is None or abs(t_start - t_next) > 0.5 / SAMPLE_RATE + 1e-9:
            restarted = self._t0 is not None
            hits.extend(self.flush())  # pending hits decided on the audio there is
            self._start(t_start)
        pcm = np.clip(np.round(np.asarray(samples, dtype=np.float64) * 32767.0),
                      -32768, 32767).astype("<i2")
        pcm = np.concatenate([self._pcm, pcm]) if len(self._pcm) else pcm
        i = 0
        while len(pcm) - i >= _CHUNK:
            chunk = pcm[i : i + _CHUNK]
            self._ps.process_raw(chunk.tobytes(), False, False)
            i += _CHUNK
            self._n += _CHUNK
            new = self._new_hits()
            if self._confirmer is None:
                hits.extend(new)
                continue
            self._keep(chunk)
            pad = int(self._confirmer.cfg.pad_s * SAMPLE_RATE)
            self._pending.extend((k, self._sample(k.t_end) + pad) for k in new)
            if self._pending and self._pending[0][1] <= self._n:
                hits.extend(self._decide(lambda due: due <= self._n))
        self._pcm = pcm[i:].copy()
        return hits, restarted

    def flush(self) -> list[Keyword]:
        """Decide every pending hit on the audio kept so far (end of stream, or a gap)."""
        return self._decide(lambda due: True)

    def _sample(self, t: float) -> int:
        """Utterance sample index of stream time ``t`` (s)."""
        return int(round((t - (self._t0 or 0.0)) * SAMPLE_RATE))

    def _keep(self, chunk: np.ndarray) -> None:
        self._ring.append(chunk.copy())
        self._ring_n += len(chunk)
        while self._ring and self._ring_n - len(self._ring[0]) >= self._ring_keep:
            self._ring_n -= len(self._ring[0])
            self._ring_start += len(self._ring.popleft())

    def _decide(self, ready) -> list[Keyword]:
        """Confirm or reject the pending hits whose due sample satisfies ``ready``; the
        confirmed ones are emitted now (``t_emitted``: the audio decoded so far)."""
        assert self._confirmer is not None or not self._pending
        out: list[Keyword] = []
        keep: list[tuple[Keyword, int]] = []
        for k, due in self._pending:
            if not ready(due):
                keep.append((k, due))
                continue
            pad = int(self._confirmer.cfg.pad_s * SAMPLE_RATE)
            buf = np.concatenate(list(self._ring)) if self._ring else np.zeros(0, "<i2")
            lo = max(self._sample(k.t_start) - pad - self._ring_start, 0)
            hi = max(self._sample(k.t_end) + pad - self._ring_start, 0)
            if self._confirmer.confirm(k.word, buf[lo:hi]):
                out.append(Keyword(k.word, k.t_start, k.t_end, k.confidence,
                                   max(k.t_emitted, self.t_fed), k.label))
            else:
                self.rejected += 1
        self._pending = keep
        return out

    def _new_hits(self) -> list[Keyword]:
        hyp = self._ps.hyp()
        n = len(hyp.hypstr) if hyp is not None else 0
        if n == self._hyp_len:
            return []
        self._hyp_len = n
        out: list[Keyword] = []
        t0 = self._t0 or 0.0
        for seg in self._ps.seg() or ():
            phrase = " ".join(seg.word.split())
            sf, ef = int(seg.start_frame), int(seg.end_frame)
            if any(p == phrase and a <= ef and sf <= b for p, a, b in self._emitted):
                continue  # the same detection (possibly re-scored), already emitted
            entry = self._table.get(phrase)
            if entry is None:
                continue
            self._emitted.append((phrase, sf, ef))
            out.append(Keyword(phrase, t0 + sf / FRAME_RATE, t0 + (ef + 1) / FRAME_RATE,
                               _score_from_prob(float(seg.prob)), self.t_fed, entry.label))
        out.sort(key=lambda k: (k.t_end, k.word))
        return out

    def close(self) -> None:
        if self._in_utt:
            self._ps.end_utt()
            self._in_utt = False


class KeywordSpotter(DecoderWorker[Keyword]):
    """Streaming keyword spotter: ``push`` blocks, ``poll`` hits; a worker thread decodes.

    Args:
        table: the keyword table (entries whose label is not in ``labels`` are left out).
        labels: the labels the motion library has (``pipeline.labels``); ``None``: keep all.
        max_queue_s: backlog (s of audio) past which pushed blocks are dropped (counted). A
            file pushed faster than real time needs a backlog as long as the file (or
            ``threaded=False``, or :func:`spot_file`); a live stream keeps the default.
        delay_frames: PocketSphinx ``kws_delay`` (10 ms frames the decoder waits for a better
            end of a detection before confirming it); ``None``: its default (10).
        threaded: ``False`` decodes inside ``push`` (deterministic, for files and tests).
        utterances: also recognise the short words that are utterances of their own ("hello",
            "hi", "thank you", "bye", "yes", "okay": :mod:`gesture_sim.audio.utterances`) in the
            same worker; their hits come out of ``poll`` like the table's.
        confirm: how a spotted phrase is confirmed by the continuous recogniser before it is
            emitted (:class:`~gesture_sim.audio.utterances.ConfirmSettings`; it adds
            ``pad_s`` to the latency); ``None``: every spotted phrase is emitted.

    ``push`` never blocks and never decodes when threaded; ``poll`` returns what the worker has
    found since the last poll; ``finish`` flushes (silence so that a hit at the very end is
    confirmed) and joins the worker. Worker errors surface as :class:`GestureSimError` from
    ``poll``/``finish`` (the queue and the thread: :class:`DecoderWorker`).
    """

    what = "keyword spotter"
    thread_name = "keyword-spotter"
    flush_s = _FLUSH_S

    def __init__(self, table: KeywordTable, labels: Iterable[str] | None = None, *,
                 max_queue_s: float = 3.0, delay_frames: int | None = None,
                 threaded: bool = True, utterances: bool = True,
                 confirm: ConfirmSettings | None = DEFAULT_CONFIRM) -> None:
        super().__init__(SpotterStats(), max_queue_s=max_queue_s, threaded=threaded)
        self.table = table.for_labels(labels)
        self._labels = None if labels is None else tuple(labels)
        self._utter = UtteranceRecognizer(self._labels) if utterances else None
        if self._utter is not None and not self._utter.active:
            self._utter = None
        self._decoder = (_Decoder(self.table, delay_frames, confirm) if self.table.entries
                         else None)
        self._start_worker()

    @property
    def active(self) -> bool:
        """Whether any keyword is listened for (an empty table after ``labels`` and no
        utterance words: no)."""
        return self._decoder is not None or self._utter is not None

    # -- worker side --------------------------------------------------------------------------

    def _feed(self, block: AudioBlock, flush: bool) -> tuple[list[Keyword], bool]:
        hits, restarted = ([], False) if self._decoder is None else \
            self._decoder.feed(block.samples, block.t_start)
        if flush and self._decoder is not None:
            hits = hits + self._decoder.flush()
        if self._utter is not None:
            if restarted:  # a gap in the stream: utterances start afresh after it
                self._utter = UtteranceRecognizer(self._labels)
            hits = hits + self._utter.push(block.samples, block.t_start)
            if flush:
                hits += self._utter.finish()
        if self._decoder is not None:
            self.stats.rejected = self._decoder.rejected
        if flush:  # the padding confirmed them: the audio they needed ended with the stream
            hits = [Keyword(h.word, h.t_start, h.t_end, h.confidence,
                            min(h.t_emitted, max(block.t_start, h.t_end)), h.label)
                    for h in hits]
        self.stats.hits += len(hits)
        return hits, restarted

    def _close_decoder(self) -> None:
        if self._decoder is not None:
            self._decoder.close()


def spot_file(samples: np.ndarray, table: KeywordTable, labels: Iterable[str] | None = None, *,
              block_size: int = 160, delay_frames: int | None = None,
              stats: SpotterStats | None = None,
              confirm: ConfirmSettings | None = DEFAULT_CONFIRM) -> list[Keyword]:
    """Spot the table's keywords in float32 16 kHz samples (n,): the streaming code, fed
    ``block_size`` blocks in order without a thread (deterministic). Hits in time order.

    ``stats``: filled with the run's counters (CPU time, audio decoded) when given.
    """
    spotter = KeywordSpotter(table, labels, threaded=False, delay_frames=delay_frames,
                             confirm=confirm)
    hits = spotter.decode_all(samples, block_size, stats)
    return sorted(hits, key=lambda k: (k.t_start, k.word))


# --------------------------------------------------------------------------------------------
# Transcripts
# --------------------------------------------------------------------------------------------


def read_word_list(path: str | os.PathLike[str], tier: str = "words"
                   ) -> list[tuple[float, float, str]]:
    """Timed words ``(t_start, t_end, word)`` (s, lower case) from a Praat TextGrid's word tier
    or a plain text file of ``start end word`` lines (``#`` comments, blank lines ignored).

    Raises:
        GestureSimError: unreadable file, a TextGrid without the tier, a malformed line.
    """
    from gesture_sim.audio.textgrid import read_textgrid

    p = Path(path)
    try:
        head = p.read_bytes()[:4096]
    except OSError as exc:
        raise GestureSimError(f"{p}: cannot read transcript ({exc.strerror or exc})") from None
    probe = head.decode("utf-8", "replace").replace("\x00", "")
    if "ooTextFile" in probe or "TextGrid" in probe[:200]:
        grid = read_textgrid(p)
        if tier not in grid:
            have = ", ".join(repr(k) for k in grid) or "none"
            raise GestureSimError(f"{p}: TextGrid has no word tier {tier!r} (tiers: {have})")
        return [(iv.xmin, iv.xmax, iv.text.strip().lower()) for iv in grid[tier]
                if iv.text.strip()]
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise GestureSimError(f"{p}: transcript is not UTF-8 text") from None
    out: list[tuple[float, float, str]] = []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 2)
        try:
            a, b = float(parts[0]), float(parts[1])
            word = parts[2]
        except (ValueError, IndexError):
            raise GestureSimError(f"{p}: line {n}: expected 'START END WORD' (seconds), got "
                                  f"{raw.strip()!r}") from None
        if not (math.isfinite(a) and math.isfinite(b)) or b < a or a < 0:
            raise GestureSimError(f"{p}: line {n}: bad times {parts[0]}..{parts[1]}")
        out.extend((a, b, w) for w in [word.strip().lower()] if w)
    if not out:
        raise GestureSimError(f"{p}: transcript has no words")
    return sorted(out)


def _norm(word: str) -> str:
    return re.sub(r"[^a-z']", "", word.lower())


def keywords_from_words(words: Sequence[tuple[float, float, str]], table: KeywordTable,
                        labels: Iterable[str] | None = None) -> list[Keyword]:
    """The table's phrases, and the utterance words (:meth:`KeywordTable.with_utterance_words`),
    found in a timed word sequence (consecutive words; punctuation and case ignored). Longest
    phrase first at each position; a hit's ``t_emitted`` is its ``t_end`` (a transcript knows
    the word when it ends) and its confidence ``inf``."""
    table = table.with_utterance_words().for_labels(labels)
    phrases = sorted(((e.phrase.split(), e) for e in table.entries), key=lambda x: -len(x[0]))
    toks = [(a, b, _norm(w)) for a, b, w in words]
    toks = [t for t in toks if t[2]]
    out: list[Keyword] = []
    i = 0
    while i < len(toks):
        for pw, entry in phrases:
            k = len(pw)
            if [t[2] for t in toks[i : i + k]] == pw:
                a, b = toks[i][0], toks[i + k - 1][1]
                out.append(Keyword(entry.phrase, a, b, math.inf, b, entry.label))
                i += k
                break
        else:
            i += 1
    return out


def transcript_keywords(path: str | os.PathLike[str], table: KeywordTable,
                        labels: Iterable[str] | None = None, tier: str = "words"
                        ) -> list[Keyword]:
    """:func:`keywords_from_words` over :func:`read_word_list` (TextGrid or text list)."""
    return keywords_from_words(read_word_list(path, tier), table, labels)
