"""What a pipeline run did (:class:`PipelineLog`) and where it is now (:class:`PipelineStatus`).

The log is what the timeline figure, the metrics and the decision log read; a live run keeps only
its last seconds (:meth:`PipelineLog.trim`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from gesture_sim.contracts import Accent, Boundary, Decision, Syllable

if TYPE_CHECKING:
    from gesture_sim.stages import Motion


@dataclass(frozen=True)
class PipelineStatus:
    """A snapshot for overlays and logs.

    Attributes:
        t: stream time of the latest control step (s). level_db: level of the latest audio (dBFS).
        state: argmax hidden state; belief: (S,). segment: playing segment index (-1 before the
        first step); segment_name: its clip name; frame: frame offset in the segment.
        style: the dial in [0, 1]; label: the pending semantic label or None.
    """

    t: float
    level_db: float
    state: int
    belief: np.ndarray
    segment: int
    segment_name: str
    frame: int
    style: float
    label: str | None


@dataclass
class PipelineLog:
    """What happened, for the timeline figure, metrics and the decision log.

    Attributes:
        syllables: every syllable the tracker emitted.
        step_times: control-step times (s); beliefs: (k, S) per step; segments, frames: (k,).
        decisions: the controller's decisions. events: (t, text) style/label events.
        targets: (k, n_joints) the joint targets sent to the physics.
        accents, boundaries: what the accent detector emitted. modes: (k,) the timing layer's
        mode per step ("" for methods without it); energy: (k,) the vocal energy per step.
        strokes: times (s) the timing layer passed a stroke peak; served: (accent t, stroke t).
        words: the spotted keywords (:class:`~gesture_sim.contracts.Keyword`) of a file run.
        signals: (t, text) face and head signal events (RUTH; t = the envelope's reference
            peak, s), e.g. "nod D*", "brow 1+2*", "blink boundary", "jog TL", "calm".
    """

    syllables: list[Syllable] = field(default_factory=list)
    step_times: list[float] = field(default_factory=list)
    beliefs: list[np.ndarray] = field(default_factory=list)
    segments: list[int] = field(default_factory=list)
    frames: list[int] = field(default_factory=list)
    targets: list[np.ndarray] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)
    accents: list[Accent] = field(default_factory=list)
    boundaries: list[Boundary] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    strokes: list[float] = field(default_factory=list)
    served: list[tuple[float, float]] = field(default_factory=list)
    words: list = field(default_factory=list)
    signals: list[tuple[float, str]] = field(default_factory=list)

    def add_step(self, t: float, motion: Motion, q: np.ndarray, energy: float) -> None:
        """Log one control step (its target ``q`` (n_joints,) as sent to the physics)."""
        self.step_times.append(t)
        self.beliefs.append(np.asarray(motion.belief, dtype=np.float32))
        self.segments.append(motion.segment)
        self.frames.append(motion.frame)
        self.targets.append(q.astype(np.float32))
        self.modes.append(motion.mode)
        self.energy.append(energy)
        if motion.decision is not None:
            self.decisions.append(motion.decision)
        if motion.stroke:
            self.strokes.append(t)
            if motion.served is not None:
                self.served.append(motion.served)

    def trim(self, keep: int) -> float:
        """Keep only the last ``keep`` steps and what happened since the first of them; returns
        that step's time (s)."""
        for name in ("step_times", "beliefs", "segments", "frames", "targets", "modes",
                     "energy"):
            del getattr(self, name)[:-keep]
        t_min = self.step_times[0]
        self.syllables = [s for s in self.syllables if s.t_end >= t_min]
        self.decisions = [d for d in self.decisions if d.t >= t_min]
        self.events = [e for e in self.events if e[0] >= t_min]
        self.accents = [a for a in self.accents if a.t >= t_min]
        self.boundaries = [b for b in self.boundaries if b.t >= t_min]
        self.strokes = [x for x in self.strokes if x >= t_min]
        self.served = [x for x in self.served if x[1] >= t_min]
        self.signals = [x for x in self.signals if x[0] >= t_min]
        return t_min
