"""Baselines beside the gesture controller (for evaluation; Levine 2009 §6.1).

* :class:`RandomSelector` — the thesis's random baseline: uniformly random co-speech segments,
  each played at its own pace, a new one whenever the current one ends (and, at interruption
  frames, with probability ``p_interrupt``). No speech input at all: no synchrony, no rest.
* :class:`RandomChooser` — random *choice* behind the same timing layer as the controller
  (:class:`~gesture_sim.control.synchrony.SyncPlayer`): the thesis pilot's "random selection
  with syllable-peak synchronisation", which tells how much of the coupling the timing alone
  gives.
"""

from __future__ import annotations

import numpy as np

from gesture_sim.contracts import Decision
from gesture_sim.control.controller import StepResult
from gesture_sim.control.inputs import ControlLibrary


class RandomSelector:
    """Uniformly random co-speech segments at their own pace (no speech input).

    Decisions happen at the controller's points (interruption frames and segment ends); at an
    interruption frame the segment is left with probability ``p_interrupt``.
    """

    def __init__(self, library: ControlLibrary, seed: int = 0, p_interrupt: float = 0.1) -> None:
        self.library = library
        self.seed = seed
        self.p_interrupt = p_interrupt
        self.pool = np.nonzero(library.cospeech)[0]
        self.reset()

    def reset(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.segment, self.frame = -1, -1
        self.decisions: list[Decision] = []
        self.label = 0

    def set_style(self, dial: float) -> None:
        """No style: the baseline ignores the dial."""

    def request_label(self, label: str, t: float | None = None) -> bool:
        return False

    def _pick(self, exclude: int = -1) -> int:
        pool = self.pool[self.pool != exclude] if len(self.pool) > 1 else self.pool
        return int(pool[self.rng.integers(len(pool))])

    def step(self, belief: np.ndarray, t: float | None = None) -> StepResult:
        lib = self.library
        t = 0.0 if t is None else t
        decision = None
        if self.segment < 0:
            self.segment, self.frame = self._pick(), 0
            decision = Decision(t=t, segment_id=self.segment,
                                frame=int(lib.starts[self.segment]), kind="start")
        else:
            length = int(lib.lengths[self.segment])
            at_end = self.frame >= length - 1
            at_interrupt = self.frame in set(int(f) for f in lib.interrupt_frames[self.segment])
            if at_end or (at_interrupt and self.rng.random() < self.p_interrupt):
                nxt = self._pick(self.segment)
                decision = Decision(t=t, segment_id=nxt, frame=int(lib.starts[nxt]),
                                    kind="end" if at_end else "interrupt")
                self.segment, self.frame = nxt, 0
            else:
                self.frame += 1
        if decision is not None:
            self.decisions.append(decision)
        target = np.asarray(lib.segment_qpos(self.segment))[self.frame]
        return StepResult(t=t, segment=self.segment, frame=self.frame, target=target,
                          decision=decision)


class RandomChooser:
    """Random segment choice with the interface the timing layer calls on the controller.

    At every decision point it continues or switches with the controller's measured share of
    interruptions (``p_interrupt``; always switches at the end), into a uniformly random
    co-speech segment.
    """

    def __init__(self, library: ControlLibrary, n_points: int, seed: int = 0,
                 p_interrupt: float = 0.1) -> None:
        self.library = library
        self.seed = seed
        self.p_interrupt = p_interrupt
        self.pool = np.nonzero(library.cospeech)[0]
        self._points = library.decision_points()
        self.n_last = library.n_interrupts
        self.reset()

    def reset(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.label = 0
        self.decisions: list[Decision] = []

    def set_style(self, dial: float) -> None:
        """No style: random choice ignores the dial."""

    def request_label(self, label: str, t: float | None = None) -> bool:
        return False

    def decision_point(self, segment: int, frame: int) -> int:
        return int(self._points[segment].get(int(frame), -1))

    def _switch(self, t: float, kind: str, exclude: int = -1) -> Decision:
        pool = self.pool[self.pool != exclude] if len(self.pool) > 1 else self.pool
        seg = int(pool[self.rng.integers(len(pool))])
        d = Decision(t=t, segment_id=seg, frame=int(self.library.starts[seg]), kind=kind,
                     costs={"continue": 0.0})
        self.decisions.append(d)
        return d

    def decide_start(self, belief: np.ndarray, t: float) -> Decision:
        return self._switch(t, "start")

    def decide_at(self, belief: np.ndarray, a: int, k: int, t: float,
                  prefer_switch: bool = False) -> Decision:
        if k < self.n_last and not prefer_switch and self.rng.random() >= self.p_interrupt:
            return Decision(t=t, segment_id=a, frame=int(self.library.starts[a]),
                            kind="interrupt", costs={"continue": 1.0})
        return self._switch(t, "end" if k >= self.n_last else "interrupt", exclude=a)
