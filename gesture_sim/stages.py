"""The stages of one control step, each called as ``step(t, heard)`` (docs/ARCHITECTURE.md).

A control step at stream time t takes one :class:`~gesture_sim.audio.speech.Heard` view of the
speech and runs, in this fixed order:

1. the **motion stage** of the method (:class:`MotionStage`): a belief filter over the hidden
   kinematic states and a control layer that chooses the clip and frame, returning one
   :class:`Motion` (the clip's joint target and what was decided);
2. the **layer stages** (:class:`LayerStage`): offsets on named joints that ride on the clip's
   target (RUTH's face and head signals; the listener's backchannels), summed and clamped by
   :class:`~gesture_sim.sim.layers.TargetLayers`.

The pipeline (:mod:`gesture_sim.pipeline`) then holds the legs in the standing pose and pushes
the target into the physics' rolling target stream. Methods are put together from these stages
by the registry in :mod:`gesture_sim.methods`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from gesture_sim.audio.speech import FrameReader, Heard
from gesture_sim.contracts import BeliefFilter, Decision
from gesture_sim.control.protocols import SegmentChooser, StepSelector, SyllableSelector
from gesture_sim.control.ramp import SwitchRamp
from gesture_sim.control.style import dial_from_style
from gesture_sim.control.synchrony import SpeechCue, SyncPlayer

#: How strongly the vocal energy (-1..1) moves the MDP's style dial (-1 calm .. 1 energetic):
#: energy 0.5 (clearly livelier than this speaker's usual) reaches the energetic tone.
ENERGY_TO_DIAL = 2.0


@dataclass
class StageCost:
    """Accumulated wall time (s) and call count of one stage."""

    seconds: float = 0.0
    calls: int = 0

    def add(self, dt: float) -> None:
        self.seconds += dt
        self.calls += 1


@dataclass(frozen=True)
class Motion:
    """What the motion stage produced at one step.

    Attributes:
        belief: (S,) the belief over the hidden kinematic states.
        segment: playing segment (-1 at rest); frame: its frame offset.
        target: (n_joints,) the clip's joint target (rad or m).
        decision: the decision taken at this step, if any.
        mode: the timing layer's mode ("" for a method with its own timing).
        served: (accent t, stroke t) when a stroke served an accent at this step.
        stroke: a stroke peak was passed at this step.
    """

    belief: np.ndarray
    segment: int
    frame: int
    target: np.ndarray
    decision: Decision | None
    mode: str = ""
    stroke: bool = False
    served: tuple[float, float] | None = None


@dataclass
class _Dial:
    """The control layer's style dial: the user's setting (0.5 neutral) offset by the voice."""

    chooser: object
    style: float
    value: float = field(init=False)

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.value = dial_from_style(self.style)
        self.chooser.set_style(self.value)

    def follow(self, energy: float) -> None:
        dial = dial_from_style(self.style, ENERGY_TO_DIAL * energy)
        if abs(dial - self.value) >= 0.05:
            self.value = dial
            self.chooser.set_style(dial)


class MotionStage(Protocol):
    """Chooses the motion: ``step(t, heard) -> Motion`` (see the module docstring).

    ``chooser`` is the control layer (it takes style and label requests and keeps its
    ``decisions``); ``filter`` the belief filter; ``costs`` the "inference" and "control" wall
    times.
    """

    chooser: object
    filter: object
    costs: dict[str, StageCost]

    def reset(self) -> None: ...

    def set_style(self, style: float, energy: float) -> None: ...

    def step(self, t: float, heard: Heard) -> Motion: ...

    def trim(self, t_min: float, keep: int) -> None: ...


class _Motion:
    """What the three motion stages share: the dial, the costs, the log trimming."""

    def __init__(self, filter_, chooser, style: float) -> None:
        self.filter = filter_
        self.chooser = chooser
        self.costs = {"inference": StageCost(), "control": StageCost()}
        self._dial = _Dial(chooser, float(style))

    def reset(self) -> None:
        self.filter.reset()
        self.chooser.reset()
        self._dial.reset()

    def set_style(self, style: float, energy: float) -> None:
        self._dial.style = float(style)
        self._dial.follow(energy)

    def trim(self, t_min: float, keep: int) -> None:
        """Forget what is older than ``t_min`` (s) / the last ``keep`` decisions (live loop)."""
        if hasattr(self.chooser, "decisions"):
            del self.chooser.decisions[:-keep]


class TimedMotion(_Motion):
    """A belief filter and a segment chooser behind the timing layer (:class:`~gesture_sim.
    control.synchrony.SyncPlayer`): the chooser decides *which* segment, the player *when*."""

    filter: BeliefFilter
    chooser: SegmentChooser

    def __init__(self, filter_: BeliefFilter, chooser: SegmentChooser, player: SyncPlayer,
                 style: float) -> None:
        self.player = player
        super().__init__(filter_, chooser, style)

    def reset(self) -> None:
        super().reset()
        self.player.reset()

    def step(self, t: float, heard: Heard) -> Motion:
        t0 = time.perf_counter()
        belief = self.filter.step(t, heard.syllables)
        t1 = time.perf_counter()
        self._dial.follow(heard.energy)
        cue = SpeechCue(speaking=heard.speaking, silence_s=heard.silence_s,
                        accents=[a.t for a in heard.accents],
                        strengths=[a.pitch_z for a in heard.accents], energy=heard.energy)
        r = self.player.step(t, belief, cue)
        served = None
        if r.stroke:
            log = self.player.log.served
            if log and log[-1][1] == t:
                served = log[-1]
        self.costs["inference"].add(t1 - t0)
        self.costs["control"].add(time.perf_counter() - t1)
        return Motion(belief, r.segment, r.frame, r.target, r.decision, r.mode, r.stroke, served)

    def trim(self, t_min: float, keep: int) -> None:
        super().trim(t_min, keep)
        plog = self.player.log
        plog.strokes = [x for x in plog.strokes if x >= t_min]
        plog.served = [x for x in plog.served if x[1] >= t_min]
        plog.accents = [x for x in plog.accents if x >= t_min]
        plog.rest_spans = [x for x in plog.rest_spans if x[1] >= t_min]


class _Ramped(_Motion):
    """A method with its own timing: its clip switches are ramped (:class:`SwitchRamp`)."""

    def __init__(self, filter_, chooser, style: float, blend_frames: int) -> None:
        super().__init__(filter_, chooser, style)
        self.ramp = SwitchRamp(blend_frames)
        self._last: np.ndarray | None = None

    def reset(self) -> None:
        super().reset()
        self.ramp.reset()
        self._last = None

    def _motion(self, belief: np.ndarray, r) -> Motion:
        q = np.asarray(r.target, dtype=float)
        if r.decision is not None and not r.decision.costs.get("continue", 0.0):
            self.ramp.start(self._last)
        q = self.ramp(q)
        self._last = q.copy()
        return Motion(belief, r.segment, r.frame, q, r.decision)


class SelectorMotion(_Ramped):
    """A belief filter and a selector that plays segments with its own timing (the random
    baseline, which ignores the belief)."""

    filter: BeliefFilter
    chooser: StepSelector

    def step(self, t: float, heard: Heard) -> Motion:
        t0 = time.perf_counter()
        belief = self.filter.step(t, heard.syllables)
        t1 = time.perf_counter()
        r = self.chooser.step(belief, t)
        self.costs["inference"].add(t1 - t0)
        self.costs["control"].add(time.perf_counter() - t1)
        return self._motion(belief, r)


class SyllableMotion(_Ramped):
    """A selector that filters the syllables itself (Levine 2009's synthesis: its forward
    update is conditioned on the segment playing, so the filter and the choice are one step)."""

    chooser: SyllableSelector

    def __init__(self, chooser: SyllableSelector, style: float, blend_frames: int) -> None:
        super().__init__(chooser.filter, chooser, style, blend_frames)

    def reset(self) -> None:
        self.chooser.reset()           # resets its own filter
        self._dial.reset()
        self.ramp.reset()
        self._last = None

    def step(self, t: float, heard: Heard) -> Motion:
        t0 = time.perf_counter()
        r = self.chooser.step(t, heard.syllables)
        belief = self.filter.belief
        self.costs["inference"].add(time.perf_counter() - t0)
        self.costs["control"].add(0.0)
        return self._motion(belief, r)


class LayerStage(Protocol):
    """Offsets on named joints riding on the clip's target: ``step(t, heard) -> (offsets,
    events)``; ``offsets`` (len(joints),) rad or m; ``events`` (t, text) for the log."""

    name: str
    joints: tuple[str, ...]

    def reset(self) -> None: ...

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]: ...


class FaceLayer:
    """RUTH's face and head signals (:class:`~gesture_sim.signals.ruth.RuthSignals`) from the
    step's accents, boundaries, frames and voice activity."""

    name = "signals"

    def __init__(self, signals) -> None:
        from gesture_sim.signals.ruth import SIGNAL_JOINTS

        self.signals = signals
        self.joints = tuple(SIGNAL_JOINTS)

    def reset(self) -> None:
        self.signals.reset()

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]:
        if heard.frames is not None:
            fr = heard.frames.frames
            self.signals.push_frames(fr.times, fr.intensity_db, fr.silent, heard.frames.known,
                                     fr.f0_hz)
        return self.signals.step(t, heard.accents, heard.boundaries, heard.speaking,
                                 heard.silence_s)


class ListenerLayer:
    """The listener's backchannels (:class:`~gesture_sim.signals.listener.ListenerSignals`)
    from the partner's voice (a :class:`~gesture_sim.audio.speech.FrameReader` on the
    partner's tracker), never while this person speaks."""

    name = "listener"

    def __init__(self, listener, partner: FrameReader) -> None:
        from gesture_sim.signals.listener import LISTENER_JOINTS

        self.listener = listener
        self.partner = partner
        self.joints = tuple(LISTENER_JOINTS)

    def reset(self) -> None:
        self.listener.reset()

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]:
        new = self.partner.take()
        if new is not None:
            fr = new.frames
            self.listener.push_frames(fr.times, fr.intensity_db, fr.silent, new.known, fr.f0_hz)
        return self.listener.step(t, own_speaking=heard.speaking)
