"""The one causal speech state: what has been heard by each control step (docs/DESIGN.md §1).

:class:`SpeechState` owns the prosody tracker and the accent detector of one voice. Audio blocks
go in through :meth:`SpeechState.push`; each control step at stream time t takes one frozen
:class:`Heard` from :meth:`SpeechState.view`: the syllables and accents whose emission time
``t_emitted`` is at or before t (the only place in the package that gates them by it), the
prosodic boundaries and the per-frame curves detected since the previous view, and the voice
activity and vocal energy as known at t. Every stage of the step reads the same view, so no
stage keeps its own cursor on the tracker.

:class:`FrameReader` is the one incremental cursor on a tracker's frames; a view uses one, and a
listener reading its partner's voice holds another on the partner's tracker.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gesture_sim.audio.accents import AccentConfig, AccentDetector
from gesture_sim.audio.prosody import ProsodyFrames, ProsodyTracker
from gesture_sim.contracts import Accent, AudioBlock, Boundary, Syllable

#: Tolerance (s) of the emission-time gate (a step at t sees what was emitted at t).
EPS = 1e-9


@dataclass(frozen=True)
class Frames:
    """Prosody frames new since a reader's previous read.

    Attributes:
        frames: the frames (:class:`~gesture_sim.audio.prosody.ProsodyFrames`, n frames).
        known: (n,) stream time (s) at which each frame became known.
    """

    frames: ProsodyFrames
    known: np.ndarray


class FrameReader:
    """An incremental cursor on the frames of a :class:`SpeechState`'s tracker (the state's
    current tracker: a reset state starts a new one)."""

    def __init__(self, source: SpeechState) -> None:
        self.source = source
        self.k = 0

    def reset(self) -> None:
        """Start again at frame 0."""
        self.k = 0

    def take(self) -> Frames | None:
        """The frames analysed since the previous call; None when there are none."""
        tracker = self.source.tracker
        n = tracker.n_frames
        if n <= self.k:
            return None
        fr, known = tracker.frames_since(self.k)
        self.k = n
        return Frames(fr, known)


@dataclass(frozen=True)
class Heard:
    """What a control step at time ``t`` knows of the speech (one view per step).

    Attributes:
        t: the step's stream time (s).
        syllables: syllables emitted since the previous view with ``t_emitted <= t``.
        accents: accents emitted since the previous view with ``t_emitted <= t``.
        boundaries: prosodic boundaries the detector found since the previous view.
        frames: the prosody frames analysed since the previous view (None: none new, or the
            state was made without ``frames``).
        speaking: voice activity known at t; silence_s: seconds of silence known at t;
        energy: vocal energy in (-1, 1) known at t (:class:`~gesture_sim.audio.accents.
            AccentDetector`).
        phones: phones the recogniser emitted since the previous view with ``emitted_s <= t``
            (:class:`~gesture_sim.audio.phones.PhoneEmission`; empty without a recogniser).
    """

    t: float
    syllables: tuple[Syllable, ...]
    accents: tuple[Accent, ...]
    boundaries: tuple[Boundary, ...]
    frames: Frames | None
    speaking: bool
    silence_s: float
    energy: float
    phones: tuple = ()


@dataclass(frozen=True)
class Analysed:
    """What one block (or the end of the stream) added: for the run's log."""

    syllables: list[Syllable]
    accents: list[Accent]
    boundaries: list[Boundary]


class SpeechState:
    """The tracker and accent detector of one voice, viewed causally per control step.

    Args:
        accents: the accent detector's settings (default :class:`~gesture_sim.audio.accents.
            AccentConfig`).
        frames: put the new prosody frames into each :class:`Heard` (a face layer reads them).
        detect: run the accent detector (False: a voice that is only listened to, through a
            :class:`FrameReader`; :meth:`view` is then not used).
        phones: also recognise phones from the audio alone
            (:class:`~gesture_sim.audio.phones.PhoneRecogniser`, PocketSphinx's phone loop), each
            seen by the first view at or after its emission time.
    """

    def __init__(self, accents: AccentConfig | None = None, frames: bool = False,
                 detect: bool = True, phones: bool = False) -> None:
        self.detector = AccentDetector(accents) if detect else None
        self.want_frames = bool(frames)
        self.want_phones = bool(phones)
        self._frames = FrameReader(self)
        self.reset()

    def reset(self) -> None:
        """A new stream at t = 0."""
        old = getattr(self, "tracker", None)
        if old is not None:
            old.release()            # its detector's network serves the new tracker
        self.tracker = ProsodyTracker()
        if self.detector is not None:
            self.detector.reset()
        self._frames.reset()
        self._syllables: list[Syllable] = []
        self._accents: list[Accent] = []
        self._n_boundaries = 0
        self.recogniser = None
        if self.want_phones:
            from gesture_sim.audio.phones import PhoneRecogniser

            self.recogniser = PhoneRecogniser()
        self._phones: list = []

    def expect(self, samples: np.ndarray) -> None:
        """This stream's whole audio (float 16 kHz, from its first sample), known ahead, as
        from a file (:meth:`ProsodyTracker.expect`): the same results at the same times, with
        less work."""
        self.tracker.expect(samples)

    def push(self, block: AudioBlock) -> Analysed:
        """Analyse one audio block; returns what it added."""
        new = self.tracker.push(block)
        if self.recogniser is not None:
            self._phones.extend(self.recogniser.push(np.asarray(block.samples, dtype=float)))
        if self.detector is None:
            return Analysed(new, [], [])
        acc, bnd = self.detector.update(self.tracker)
        return self._note(new, acc, bnd)

    def flush(self) -> Analysed:
        """End of stream: the tracker's last syllable and the detector's closing boundary."""
        new = self.tracker.flush()
        if self.recogniser is not None:
            self._phones.extend(self.recogniser.finish())
        if self.detector is None:
            return Analysed(new, [], [])
        acc, bnd = self.detector.finish(self.tracker)
        return self._note(new, acc, bnd)

    def _note(self, syllables: list[Syllable], accents: list[Accent],
              boundaries: list[Boundary]) -> Analysed:
        self._syllables.extend(syllables)
        self._accents.extend(accents)
        return Analysed(syllables, accents, boundaries)

    def view(self, t: float) -> Heard:
        """The frozen view of a control step at stream time ``t`` (s); call with increasing t."""
        ready: list[Syllable] = []
        if self._syllables:
            ready = [s for s in self._syllables if s.t_emitted <= t + EPS]
            if ready:
                self._syllables = [s for s in self._syllables if s.t_emitted > t + EPS]
        accents = [a for a in self._accents if a.t_emitted <= t + EPS]
        if accents:
            self._accents = self._accents[len(accents):]
        bounds = self.detector.boundaries[self._n_boundaries:]
        self._n_boundaries += len(bounds)
        speaking, silence_s, energy = self.detector.state_at(t)
        phones: tuple = ()
        if self._phones:
            phones = tuple(e for e in self._phones if e.emitted_s <= t + EPS)
            if phones:
                self._phones = [e for e in self._phones if e.emitted_s > t + EPS]
        return Heard(t=t, syllables=tuple(ready), accents=tuple(accents),
                     boundaries=tuple(bounds),
                     frames=self._frames.take() if self.want_frames else None,
                     speaking=speaking, silence_s=silence_s, energy=energy, phones=phones)
