"""Data contracts between the pipeline stages (docs/DESIGN.md §2).

Time is seconds since the stream began, one clock for all stages; all quantities are SI
(seconds, radians, metres) unless a field name says otherwise (``_db``, ``_hz``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

#: The one audio format the pipeline sees after the source converts it.
SAMPLE_RATE = 16_000
#: Prosody frame step (s): F0 and intensity are computed every 10 ms.
PROSODY_FRAME_STEP = 0.01


@dataclass(frozen=True)
class AudioBlock:
    """A block of mono float32 audio at :data:`SAMPLE_RATE`.

    Attributes:
        samples: shape (n,), float32, nominally in [-1, 1].
        t_start: time of the first sample (s since the stream began).
    """

    samples: np.ndarray
    t_start: float

    @property
    def t_end(self) -> float:
        """Time just after the last sample (s)."""
        return self.t_start + len(self.samples) / SAMPLE_RATE


@dataclass(frozen=True)
class Syllable:
    """One syllable found by the prosody tracker.

    Attributes:
        t_start, t_end: syllable boundaries (s), at intensity troughs.
        t_emitted: stream time at which the tracker knew the syllable (s); ``t_emitted - t_end``
            is the prosody latency.
        f0_hz: mean F0 over its voiced frames (Hz), or ``None`` when unvoiced (unknown, not 0).
        intensity_db: mean intensity (dB).
        voiced: whether enough of the syllable was voiced for ``f0_hz`` to be defined.
    """

    t_start: float
    t_end: float
    t_emitted: float
    f0_hz: float | None
    intensity_db: float
    voiced: bool

    @property
    def length(self) -> float:
        """Syllable duration (s)."""
        return self.t_end - self.t_start


@dataclass(frozen=True)
class Decision:
    """A control-layer decision: which segment plays next and from which frame.

    Attributes:
        t: stream time of the decision (s).
        segment_id: index of the chosen segment in the motion library.
        frame: first frame of the segment to play (index into its clip).
        kind: why a decision was taken here: ``"end"`` (segment finished), ``"interrupt"``
            (an interruption frame), ``"label"`` (a semantic label) or ``"start"``.
        costs: the cost terms behind the choice (for the timeline figure and the decision log).
    """

    t: float
    segment_id: int
    frame: int
    kind: str
    costs: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Accent:
    """A pitch accent (a prominent, stressed syllable nucleus), emitted causally.

    Attributes:
        t: best estimate of the accented nucleus time known at emission (s).
        t_emitted: stream time at which the detector knew it (s), ``>= t``.
        strength: combined prominence z (intensity, rise and F0 against the speaker's running
            statistics; see :mod:`gesture_sim.audio.accents`).
        pitch_z: the F0 of the emitting frame against the speaker's running voiced F0 (z, in
            semitones; 0 when unvoiced): how much of a *pitch* accent it is.
    """

    t: float
    t_emitted: float
    strength: float
    pitch_z: float = 0.0


@dataclass(frozen=True)
class Boundary:
    """A prosodic phrase boundary, emitted causally.

    Attributes:
        t: time the phrase ended (s): the end of its last speech frame.
        t_emitted: stream time at which the detector knew it (s).
        kind: ``"pause"`` (speech followed by a pause) or ``"end"`` (the stream ended in speech).
    """

    t: float
    t_emitted: float
    kind: str


@runtime_checkable
class BeliefFilter(Protocol):
    """An inference layer at run time: a causal filter from syllables to a belief over the
    hidden kinematic states (the remapped CRF, the Levine 2009 HMM, the DCNF).

    ``step(t, syllables)`` takes the syllables emitted since the previous step (``t_emitted <=
    t``) and returns the belief (n_states,), non-negative, summing to one.
    """

    @property
    def n_states(self) -> int: ...

    def reset(self) -> None: ...

    def step(self, t: float, syllables: Sequence[Syllable] = ()) -> np.ndarray: ...


@dataclass(frozen=True)
class Keyword:
    """A spotted keyword or keyphrase (:mod:`gesture_sim.audio.keywords`).

    Attributes:
        word: the phrase as written in the keyword table, lower case (``"thank you"``).
        t_start, t_end: where the phrase was heard (s), from the decoder's segment frames (or the
            transcript's word intervals).
        confidence: log10 likelihood ratio of the phrase's path against the best free phone
            loop over the same frames (the PocketSphinx keyword-spotting score; higher is surer,
            the table's thresholds are on this scale, typically -40 ... 0); ``inf`` for a word
            read from a transcript.
        t_emitted: stream time of the audio the decision needed (s), ``>= t_end``;
            ``t_emitted - t_end`` is the spotting latency.
        label: the semantic gesture label the table maps the phrase to (``"bow"``).
    """

    word: str
    t_start: float
    t_end: float
    confidence: float
    t_emitted: float
    label: str = ""


@dataclass(frozen=True)
class Turn:
    """Who speaks when (a conversation's roles; :mod:`gesture_sim.audio.turns`).

    Attributes:
        person: index of the speaking person (0 or 1 in a two-person scene).
        t_start, t_end: the stretch of speech (s, stream clock), ``t_end > t_start``.
    """

    person: int
    t_start: float
    t_end: float

    @property
    def duration(self) -> float:
        """Length of the turn (s)."""
        return self.t_end - self.t_start
