"""The interfaces the pipeline and the timing layer call on a control layer (declared, so that
the MDP controller, MIMiC, the Levine 2009 synthesis and the baselines are interchangeable).

* :class:`SegmentChooser` — decides *which* segment plays at a decision point; the timing layer
  (:class:`~gesture_sim.control.synchrony.SyncPlayer`) decides *when*. Implemented by
  :class:`~gesture_sim.control.controller.GestureController` (the MDP) and
  :class:`~gesture_sim.control.baselines.RandomChooser`.
* :class:`StepSelector` — plays segments itself, one frame per control step, with its own
  timing: :class:`~gesture_sim.control.baselines.RandomSelector` (no speech input) and the
  controller's own ``step`` (the 2010 paper's timing).
* :class:`SyllableSelector` — plays segments with its own timing *and* its own filter over the
  syllables: :class:`~gesture_sim.inference.levine09_synthesis.Levine09Synthesis` (its forward
  update is conditioned on the segment playing, so the belief and the choice are one step).

The registry (:mod:`gesture_sim.methods`) builds each method from one of these; a test checks
every registered method against them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from gesture_sim.contracts import BeliefFilter, Decision, Syllable


@runtime_checkable
class SegmentChooser(Protocol):
    """Which segment plays next (see the module docstring).

    ``Decision.frame`` is the clip frame to play next (``library.starts[seg] + offset``);
    a decision that keeps the playing segment has ``costs["continue"] == 1.0``.
    """

    label: int
    decisions: list[Decision]

    def reset(self) -> None: ...

    def set_style(self, dial: float) -> None: ...

    def request_label(self, label: str, t: float | None = None) -> bool: ...

    def decision_point(self, segment: int, frame: int) -> int: ...

    def decide_start(self, belief: np.ndarray, t: float) -> Decision: ...

    def decide_at(self, belief: np.ndarray, a: int, k: int, t: float,
                  prefer_switch: bool = False) -> Decision: ...


@runtime_checkable
class StepSelector(Protocol):
    """Plays segments frame by frame with its own timing; ``step`` returns a
    :class:`~gesture_sim.control.controller.StepResult`."""

    decisions: list[Decision]

    def reset(self) -> None: ...

    def set_style(self, dial: float) -> None: ...

    def request_label(self, label: str, t: float | None = None) -> bool: ...

    def step(self, belief: np.ndarray, t: float | None = None): ...


@runtime_checkable
class SyllableSelector(Protocol):
    """Plays segments with its own timing and its own belief filter (``filter``) over the
    syllables emitted since the previous step; ``step`` returns a
    :class:`~gesture_sim.control.controller.StepResult`."""

    decisions: list[Decision]
    filter: BeliefFilter

    def reset(self) -> None: ...

    def set_style(self, dial: float) -> None: ...

    def request_label(self, label: str, t: float | None = None) -> bool: ...

    def step(self, t: float, syllables: Sequence[Syllable] = ()): ...
