"""Words with times, live: PocketSphinx continuous decoding of the audio stream.

:class:`LiveWords` hears the same 16 kHz float32 :class:`~gesture_sim.contracts.AudioBlock`
stream as the prosody tracker and the keyword spotter and gives the words said, each with its
span and the stream time at which it became known (:class:`LiveWord`). It is the live source
of the timed words that Chiu (2014)'s sign model reads (``--method chiu14``: offline they come
from a TextGrid, a force-aligned transcript or ``--text``).

Recogniser: PocketSphinx's continuous decoder with the US English acoustic model, trigram
language model (``en-us.lm.bin``) and dictionary (``cmudict-en-us.dict``) that ship inside the
``pocketsphinx`` wheel; nothing is downloaded.

Utterances. The project's voice-activity detector (:mod:`gesture_sim.audio.vad`, Silero by
default) cuts the stream: a decoder utterance opens ``pad_s`` before the first voice window
(the decoder's silence model needs a little lead-in) and closes when the detector closes
speech (``hangover_s`` of no voice). Audio outside utterances is not decoded (no CPU spent, no
words made up from room noise). An utterance longer than ``max_utterance_s`` is ended at the
next pause of the partial hypothesis (0.15 s of silence), and at twice that length anyway.

Emission (``LiveWordsSettings.emit``):

* ``"stable"``: the partial hypothesis is read every ``poll_s`` of audio; a word is emitted
  once it is not the last segment of the hypothesis and the same word has started at the same
  frame for ``stable_s`` of audio (later audio rarely revises it then); words are emitted in
  order and never retracted. What the final hypothesis of the utterance has after the last
  emitted word is emitted when the utterance closes.
* ``"utterance"``: every word of the utterance's final hypothesis (after the decoder's
  second passes) is emitted when the utterance closes: fewer errors, later words.

Times: ``start_s``/``end_s`` from the decoder's segment frames (10 ms) on the stream clock;
``t_emitted`` is the end of the audio that had been pushed when the word was decided, so it
does not depend on thread timing, only on the blocks pushed (``t_emitted >= end_s``).

Streaming: ``push`` only appends to a bounded queue; a worker thread decodes. A recogniser that
falls behind lags, and past ``max_queue_s`` of backlog whole blocks are dropped (counted in
:attr:`LiveWords.stats`; the gap ends the utterance and restarts the detector); the caller is
never stalled. :func:`recognise_words` runs the same code over a whole recording without a
thread, deterministically.

Measured (``tools/live_words_eval.py`` on the four BEAT2 TextGrid takes, 261 s of spontaneous
speech, 789 reference words; latency = ``t_emitted - end_s``):

=====================  =====  ================  ============
setting                WER    latency med/p90   CPU per s
=====================  =====  ================  ============
stable, 0.1 s          0.52   0.21 / 0.45 s     0.3-0.5
stable, 0.2 s (dflt)   0.46   0.31 / 0.66 s     0.3-0.5
stable, 0.3 s          0.43   0.43 / 0.84 s     0.3-0.5
utterance              0.39   3.9 / 8.5 s       0.3-0.5
=====================  =====  ================  ============

The default is stable partials held 0.2 s: the sign filter reads 1-s frames and makes a frame
final ``commit_lag_s`` (0.4 s) after it ends, so a word must arrive within about a second of
its end to count at all; utterance-end emission is 15 % fewer errors but seconds late (the
detector's 0.25 s pauses leave utterances of 5-10 s in fluent speech). A wider beam (1e-60)
changed the WER by under 0.01 for a third more CPU.
"""

from __future__ import annotations

import re
import threading
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.audio.decoder_worker import DecoderWorker, WorkerStats
from gesture_sim.audio.vad import VadConfig, VoiceActivityDetector
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.errors import GestureSimError

__all__ = ["EMIT_MODES", "LiveWord", "LiveWords", "LiveWordsSettings", "LiveWordsStats",
           "recognise_words", "words_for_sign_model"]

#: Emission modes (module docstring).
EMIT_MODES = ("stable", "utterance")
#: Decoder frame rate (frames/s): PocketSphinx's 10 ms frames.
FRAME_RATE = 100
#: Samples per decoder frame.
_FRAME = SAMPLE_RATE // FRAME_RATE
#: Silence appended by :meth:`LiveWords.finish` so that an utterance open at the end closes, s
#: (the detector's hangover plus its onset windows).
_FLUSH_S = 0.4
#: A pause of the partial hypothesis at which an over-long utterance may be cut (frames).
_PAUSE_FRAMES = 15


@dataclass(frozen=True)
class LiveWord:
    """A recognised word: its span, its text and when it became known.

    ``start_s``/``end_s``/``text`` are the fields of :class:`gesture_sim.audio.phones.Word`, so
    a list of these is what :func:`gesture_sim.inference.sign_model.timed_words` and the sign
    filter take.

    Attributes:
        start_s, end_s: the word's frames (s on the stream clock).
        text: lower case, without the dictionary's variant mark (``"to"``, not ``"to(2)"``).
        t_emitted: end of the audio pushed when the word was decided (s), ``>= end_s``.
        final: whether it came from an utterance's final hypothesis (else: a stable partial).
    """

    start_s: float
    end_s: float
    text: str
    t_emitted: float
    final: bool = False

    @property
    def latency_s(self) -> float:
        """Emission time minus the word's end (s)."""
        return self.t_emitted - self.end_s


@dataclass(frozen=True)
class LiveWordsSettings:
    """How words are recognised and emitted.

    Attributes:
        emit: ``"stable"`` (stable partial hypotheses) or ``"utterance"`` (at utterance end).
        stable_s: how long (s of audio) a partial word must keep its start and text.
        poll_s: how often (s of audio) the partial hypothesis is read (``"stable"``).
        pad_s: audio decoded before an utterance's first voice window (s).
        max_utterance_s: length (s) after which an utterance is ended at the next pause.
        beam, wbeam: PocketSphinx beams (``None``: its defaults, 1e-48 and 7e-29).
        vad: the utterance cutter (its hangover is the pause that closes an utterance).
    """

    emit: str = "stable"
    stable_s: float = 0.2
    poll_s: float = 0.05
    pad_s: float = 0.15
    max_utterance_s: float = 8.0
    beam: float | None = None
    wbeam: float | None = None
    vad: VadConfig = field(default_factory=lambda: VadConfig(hangover_s=0.25))

    def __post_init__(self) -> None:
        if self.emit not in EMIT_MODES:
            raise GestureSimError(f"live words: emit must be one of {', '.join(EMIT_MODES)}, "
                                  f"got {self.emit!r}")
        if not (self.stable_s >= 0 and self.poll_s > 0 and self.pad_s >= 0
                and self.max_utterance_s > 0):
            raise GestureSimError("live words: stable_s, pad_s >= 0 and poll_s, "
                                  "max_utterance_s > 0 are needed")


@dataclass
class LiveWordsStats(WorkerStats):
    """Counters of a :class:`LiveWords` recogniser (those of :class:`WorkerStats`, where
    ``decoded_s`` is the audio the worker took in: the detector saw all of it, and:).

    Attributes:
        recognised_s: audio given to the decoder, inside utterances (s).
        words: words emitted; utterances: decoder utterances.
    """

    recognised_s: float = 0.0
    words: int = 0
    utterances: int = 0

    @property
    def backlog_s(self) -> float:
        """Audio pushed but neither decoded nor dropped yet (s)."""
        return max(self.pushed_s - self.decoded_s - self.dropped_s, 0.0)

    def to_dict(self) -> dict[str, float | int]:
        return {**self._common_dict(), "recognised_s": round(self.recognised_s, 3),
                "words": self.words, "utterances": self.utterances, **self._lag_dict()}


#: Decoders handed back by closed recognisers, by (beam, wbeam): loading the model takes about
#: a second, so a new recogniser (a new stream, a test) reuses an idle one (feature state and
#: cepstral mean reset: the same results as a new decoder).
_POOL: dict[tuple[float | None, float | None], list] = {}
_POOL_LOCK = threading.Lock()
#: The initial cepstral mean of a new decoder, by the same key.
_CMN0: dict[tuple[float | None, float | None], str] = {}


def _take_decoder(settings: LiveWordsSettings):
    """An idle decoder of these settings, its cepstral mean set back to the model's initial one
    (PocketSphinx carries it over from utterance to utterance: a reused decoder would otherwise
    hear a new stream through the last one's channel estimate), or a new decoder."""
    key = (settings.beam, settings.wbeam)
    with _POOL_LOCK:
        idle = _POOL.get(key)
        ps = idle.pop() if idle else None
    if ps is None:
        ps = _new_decoder(settings)
        _CMN0.setdefault(key, ps.get_cmn(False))
    else:
        ps.reinit_feat()
        ps.set_cmn(_CMN0[key])
    return ps


def _give_back(settings: LiveWordsSettings, ps) -> None:
    with _POOL_LOCK:
        idle = _POOL.setdefault((settings.beam, settings.wbeam), [])
        if len(idle) < 2:
            idle.append(ps)


def _new_decoder(settings: LiveWordsSettings):
    try:
        import pocketsphinx
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise GestureSimError("live word recognition needs the pocketsphinx package "
                              "(pip install pocketsphinx)") from exc
    kw: dict[str, object] = {"loglevel": "FATAL"}
    if settings.beam is not None:
        kw["beam"] = float(settings.beam)
    if settings.wbeam is not None:
        kw["wbeam"] = float(settings.wbeam)
    return pocketsphinx.Decoder(pocketsphinx.Config(**kw))


_VARIANT = re.compile(r"\(\d+\)$")


def _is_filler(name: str) -> bool:
    return name.startswith(("<", "[", "+"))


class _WordDecoder:
    """The detector and the decoder over one stream; single-threaded (the worker owns it).

    Stream sample ``i`` (from the origin ``t0``: the first block's start, or the block after a
    gap) is at ``t0 + i / SAMPLE_RATE``.
    """

    def __init__(self, settings: LiveWordsSettings) -> None:
        self.cfg = settings
        self._ps = _take_decoder(settings)
        self.stable_frames = int(round(settings.stable_s * FRAME_RATE))
        self.poll_samples = max(_FRAME, int(round(settings.poll_s * SAMPLE_RATE)))
        self.max_frames = int(round(settings.max_utterance_s * FRAME_RATE))
        self.utterances = 0
        self.recognised_s = 0.0
        self._t0: float | None = None
        self._in_utt = False
        self._reset_stream(0.0)

    # -- stream bookkeeping -------------------------------------------------------------------

    def _reset_stream(self, t0: float) -> None:
        self._t0 = t0
        self._vad = VoiceActivityDetector(self.cfg.vad)
        self._n = 0                          # samples pushed since the origin
        self._ring: deque[np.ndarray] = deque()  # recent audio (int16), for an utterance's pad
        self._ring_start = 0
        self._ring_n = 0
        self._keep = int((self.cfg.pad_s + 0.5) * SAMPLE_RATE) + 4 * self._vad.window
        self._scanned = 0                    # windows whose decision is final and looked at
        self._fed_to = 0                     # stream sample up to which the decoder was fed
        self._pcm = np.zeros(0, dtype="<i2")  # samples held back to whole decoder frames

    @property
    def t_pushed(self) -> float:
        """Stream time just after the last sample pushed (s)."""
        return (self._t0 or 0.0) + self._n / SAMPLE_RATE

    def feed(self, samples: np.ndarray, t_start: float) -> tuple[list[LiveWord], bool]:
        """Take float32 (n,) samples that start at stream time ``t_start`` (s).

        Returns the words decided with this audio and whether the stream was restarted (a gap
        before ``t_start``: the open utterance is closed on the audio there was).
        """
        restarted = False
        out: list[LiveWord] = []
        if self._t0 is None or abs(t_start - self.t_pushed) > 0.5 / SAMPLE_RATE + 1e-9:
            restarted = self._n > 0
            if self._in_utt:
                out.extend(self._end_utt())
            self._reset_stream(float(t_start))
        x = np.asarray(samples, dtype=np.float32).reshape(-1)
        pcm = np.clip(np.round(x.astype(np.float64) * 32767.0), -32768, 32767).astype("<i2")
        self._ring.append(pcm)
        self._ring_n += len(pcm)
        while self._ring and self._ring_n - len(self._ring[0]) >= self._keep:
            self._ring_n -= len(self._ring[0])
            self._ring_start += len(self._ring.popleft())
        self._n += len(pcm)
        self._vad.push(x)
        out.extend(self._scan())
        if self._in_utt:
            out.extend(self._decode_to(self._n))
        return out, restarted

    def _audio(self, a: int, b: int) -> np.ndarray:
        """Stream samples [a, b) still in the ring (int16)."""
        buf = np.concatenate(list(self._ring)) if self._ring else np.zeros(0, "<i2")
        lo, hi = a - self._ring_start, b - self._ring_start
        return buf[max(lo, 0):max(hi, 0)]

    def _scan(self) -> list[LiveWord]:
        """Open and close utterances at the detector's final decisions."""
        vad, w = self._vad, self._vad.window
        if not vad.enabled:  # no detector: one utterance, cut by length only
            if not self._in_utt:
                self._start_utt(self._fed_to)
            return []
        final = vad.n_windows - self.cfg.vad.onset_windows + 1
        out: list[LiveWord] = []
        if final <= self._scanned:
            return out
        flags = vad.window_speech(self._scanned, final)
        for i, on in enumerate(flags):
            j = self._scanned + i
            if on and not self._in_utt:
                a = max(j * w - int(self.cfg.pad_s * SAMPLE_RATE), self._fed_to,
                        self._ring_start)
                self._start_utt(a)
            elif not on and self._in_utt:
                out.extend(self._decode_to(self._n))
                out.extend(self._end_utt())
        self._scanned = final
        return out

    # -- the decoder --------------------------------------------------------------------------

    def _start_utt(self, a: int) -> None:
        self._ps.start_utt()
        self._in_utt = True
        self.utterances += 1
        self._utt_start = a               # stream sample of the utterance's frame 0
        self._fed_to = a
        self._pcm = np.zeros(0, dtype="<i2")
        self._since_poll = 0
        self._done_frame = 0              # utterance frames covered by emitted words
        self._seen: dict[tuple[str, int], int] = {}  # (word, start frame) -> frame first seen

    def _decode_to(self, b: int) -> list[LiveWord]:
        """Feed the decoder the stream up to sample ``b``, in whole frames, polling."""
        x = self._audio(self._fed_to, b)
        base = self._fed_to - len(self._pcm)  # stream sample of pcm[0]
        self._fed_to = max(self._fed_to, b)
        pcm = np.concatenate([self._pcm, x]) if len(self._pcm) else x
        n = len(pcm) // _FRAME * _FRAME
        self._pcm = pcm[n:].copy()
        out: list[LiveWord] = []
        i = 0
        while i < n:
            k = min(n - i, self.poll_samples - self._since_poll)
            k = max(_FRAME, k // _FRAME * _FRAME)
            self._ps.process_raw(pcm[i:i + k].tobytes(), False, False)
            self.recognised_s += k / SAMPLE_RATE
            i += k
            self._since_poll += k
            if self._since_poll >= self.poll_samples:
                self._since_poll = 0
                out.extend(self._poll())
                if not self._in_utt:  # cut for length: the rest opens a new utterance
                    rest, fed = self._pcm, self._fed_to
                    self._start_utt(base + i)
                    self._pcm, self._fed_to = rest, fed
        return out

    def _segments(self) -> list[tuple[str, int, int]]:
        return [(s.word, int(s.start_frame), int(s.end_frame)) for s in self._ps.seg() or ()]

    def _poll(self) -> list[LiveWord]:
        frames = int(self._ps.n_frames())
        stable = self.cfg.emit == "stable"
        if not stable and frames < self.max_frames:
            return []
        segs = self._segments()
        out = self._emit(segs, frames, final=False) if stable else []
        if frames >= self.max_frames:
            pause = bool(segs) and _is_filler(segs[-1][0]) and \
                segs[-1][2] - segs[-1][1] >= _PAUSE_FRAMES
            if pause or frames >= 2 * self.max_frames:
                out.extend(self._end_utt())
        return out

    def _end_utt(self) -> list[LiveWord]:
        if not self._in_utt:
            return []
        self._ps.end_utt()
        self._in_utt = False
        return self._emit(self._segments(), int(self._ps.n_frames()), final=True)

    def _emit(self, segs: list[tuple[str, int, int]], frames: int, final: bool
              ) -> list[LiveWord]:
        """Words of the hypothesis ``segs`` that are decided now, in order."""
        words = [(i, _VARIANT.sub("", name), sf, ef) for i, (name, sf, ef) in enumerate(segs)
                 if not _is_filler(name)]
        if not final:
            self._seen = {(t, sf): self._seen.get((t, sf), frames) for _, t, sf, _ in words}
        t_utt = (self._t0 or 0.0) + self._utt_start / SAMPLE_RATE
        now = round(self.t_pushed, 6)
        out: list[LiveWord] = []
        for i, text, sf, ef in words:
            if ef + 1 <= self._done_frame:
                continue
            if sf < self._done_frame and (ef + 1 - self._done_frame) < 0.5 * (ef + 1 - sf):
                continue  # a revision of a word already emitted
            if not final and (i == len(segs) - 1
                              or frames - self._seen[(text, sf)] < self.stable_frames):
                break
            start = max(sf, self._done_frame)
            end = max(ef + 1, start + 1)
            out.append(LiveWord(round(t_utt + start / FRAME_RATE, 6),
                                round(t_utt + end / FRAME_RATE, 6), text.lower(),
                                max(now, round(t_utt + end / FRAME_RATE, 6)), final))
            self._done_frame = end
        return out

    def close(self) -> None:
        """End an open utterance (its words are not emitted) and hand the decoder back."""
        if self._ps is None:
            return
        if self._in_utt:
            self._ps.end_utt()
            self._in_utt = False
        ps, self._ps = self._ps, None
        _give_back(self.cfg, ps)


class LiveWords(DecoderWorker[LiveWord]):
    """Streaming word recogniser: ``push`` blocks, ``poll`` words; a worker thread decodes.

    Args:
        settings: see :class:`LiveWordsSettings` (default: stable partials, 0.2 s).
        max_queue_s: backlog (s of audio) past which pushed blocks are dropped (counted). A
            file pushed faster than real time needs a backlog as long as the file (or
            ``threaded=False``, or :func:`recognise_words`); a live stream keeps the default.
        threaded: ``False`` decodes inside ``push`` (deterministic, for files and tests).

    ``push`` never blocks and never decodes when threaded; ``poll`` returns the words found
    since the last poll, in order; ``finish`` flushes (silence so that an open utterance
    closes) and joins the worker. Worker errors surface as :class:`GestureSimError` from
    ``poll``/``finish`` (the queue and the thread: :class:`DecoderWorker`).
    """

    what = "live words"
    thread_name = "live-words"
    flush_s = _FLUSH_S

    def __init__(self, settings: LiveWordsSettings | None = None, *, max_queue_s: float = 3.0,
                 threaded: bool = True) -> None:
        super().__init__(LiveWordsStats(), max_queue_s=max_queue_s, threaded=threaded)
        self.settings = settings or LiveWordsSettings()
        self._decoder = _WordDecoder(self.settings)
        self._start_worker()

    # -- worker side --------------------------------------------------------------------------

    def _feed(self, block: AudioBlock, flush: bool) -> tuple[list[LiveWord], bool]:
        words, restarted = self._decoder.feed(block.samples, block.t_start)
        if flush:
            words = words + self._decoder._end_utt()
            # the padding closed the utterance: what it needed ended with the stream (a word
            # heard in the padding alone is none)
            end = block.t_start
            words = [w if w.t_emitted <= end else
                     LiveWord(w.start_s, min(w.end_s, end), w.text, end, w.final)
                     for w in words if w.start_s < end]
        self.stats.utterances = self._decoder.utterances
        self.stats.recognised_s = self._decoder.recognised_s
        self.stats.words += len(words)
        return words, restarted

    def _close_decoder(self) -> None:
        self._decoder.close()


def recognise_words(samples: np.ndarray, settings: LiveWordsSettings | None = None, *,
                    block_size: int = 160, stats: LiveWordsStats | None = None
                    ) -> list[LiveWord]:
    """The words of float32 16 kHz samples (n,): the streaming code, fed ``block_size`` blocks
    in order without a thread (deterministic). Words in emission order (= time order).

    ``stats``: filled with the run's counters (CPU time, audio decoded) when given.
    """
    return LiveWords(settings, threaded=False).decode_all(samples, block_size, stats)


def words_for_sign_model(words: Iterable[LiveWord]) -> list[tuple[float, float, str]]:
    """``(start_s, end_s, text)`` tuples (what ``run_file(words=)`` and ``set_words`` take)."""
    return [(w.start_s, w.end_s, w.text) for w in words]
