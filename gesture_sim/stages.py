"""The stages of one control step, each called as ``step(t, heard)`` (docs/ARCHITECTURE.md).

A control step at stream time t takes one :class:`~gesture_sim.audio.speech.Heard` view of the
speech and runs, in this fixed order:

1. the **motion stage** of the method (:class:`MotionStage`): a belief filter over the hidden
   kinematic states and a control layer that chooses the clip and frame, returning one
   :class:`Motion` (the clip's joint target and what was decided);
2. the **layer stages** (:class:`LayerStage`): offsets on named joints that ride on the clip's
   target (RUTH's face and head signals; the listener's backchannels), summed and clamped by
   :class:`~gesture_sim.sim.layers.TargetLayers`.

3. the **legs' stage** (:class:`Legs`): by default the clip's weight shifts on a planted stance
   (:class:`LowerBody`), or the standing pose, or the clip's own legs.

The pipeline (:mod:`gesture_sim.pipeline`) then pushes the target into the physics' rolling
target stream. Methods are put together from these
stages by the registry in :mod:`gesture_sim.methods`.
"""

from __future__ import annotations

import math
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
        lower: (clip index, clip frame) whose lower body the legs follow, when a stream of
            its own chose it (Levine 2009's lower-body section); None: the playing segment's.
    """

    belief: np.ndarray
    segment: int
    frame: int
    target: np.ndarray
    decision: Decision | None
    mode: str = ""
    stroke: bool = False
    served: tuple[float, float] | None = None
    lower: tuple[int, int] | None = None


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
    """A method with its own timing: its clip switches are ramped (:class:`SwitchRamp`, the
    pose ramped from carried on with time constant ``carry_tau`` steps)."""

    def __init__(self, filter_, chooser, style: float, blend_frames: int,
                 carry_tau: float = 0.0) -> None:
        super().__init__(filter_, chooser, style)
        self.ramp = SwitchRamp(blend_frames, carry_tau=carry_tau)
        self._last: np.ndarray | None = None
        self._last_v: np.ndarray | None = None

    def reset(self) -> None:
        super().reset()
        self.ramp.reset()
        self._last = self._last_v = None

    def _motion(self, belief: np.ndarray, r) -> Motion:
        q = np.asarray(r.target, dtype=float)
        if r.decision is not None and not r.decision.costs.get("continue", 0.0):
            self.ramp.start(self._last, self._last_v)
        q = self.ramp(q)
        self._last_v = None if self._last is None else q - self._last
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

    def __init__(self, chooser: SyllableSelector, style: float, blend_frames: int,
                 carry_tau: float = 0.0) -> None:
        super().__init__(chooser.filter, chooser, style, blend_frames, carry_tau)

    def reset(self) -> None:
        self.chooser.reset()           # resets its own filter
        self._dial.reset()
        self.ramp.reset()
        self._last = self._last_v = None

    def step(self, t: float, heard: Heard) -> Motion:
        t0 = time.perf_counter()
        r = self.chooser.step(t, heard.syllables)
        belief = self.filter.belief
        self.costs["inference"].add(time.perf_counter() - t0)
        self.costs["control"].add(0.0)
        m = self._motion(belief, r)
        lower = self._lower()
        if lower is None:
            return m
        return Motion(m.belief, m.segment, m.frame, m.target, m.decision, lower=lower)

    def _lower(self) -> tuple[int, int] | None:
        """The lower-body section stream's (clip, clip frame), if the chooser has one."""
        section_frame = getattr(self.chooser, "section_frame", None)
        return section_frame("lower") if section_frame is not None else None


class LayerStage(Protocol):
    """Offsets on named joints riding on the clip's target: ``step(t, heard) -> (offsets,
    events)``; ``offsets`` (len(joints),) rad or m; ``events`` (t, text) for the log."""

    name: str
    joints: tuple[str, ...]

    def reset(self) -> None: ...

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]: ...


#: Joints whose flexion turns the head down / whose twist turns it left (their sum: the head's
#: pitch and yaw against the body's facing, small-angle), for the eyes' counter-rotation.
_HEAD_PITCH = ("lower_spine_flex", "upper_spine_flex", "neck_flex", "head_flex")
_HEAD_YAW = ("lower_spine_twist", "upper_spine_twist", "neck_twist", "head_twist")
#: The eyes' counter-rotation gain against the head's turn (the vestibulo-ocular reflex keeps
#: a target on the fovea with a gain near 1 for slow head movements).
VOR_GAIN = 0.9


class FaceLayer:
    """RUTH's face and head signals (:class:`~gesture_sim.signals.ruth.RuthSignals`) from the
    step's accents, boundaries, frames and voice activity, and the eyes' gaze
    (:class:`~gesture_sim.signals.gaze.Gaze`: aversion at phrase starts, back at their ends,
    at the partner while listening, saccades), the upper lids following the eyes down.

    ``base``: a function giving this step's target before the layers ((n_act,), the clip's
    pose: :attr:`GesturePipeline.base_target`); with it the eyes counter-rotate the head's
    pitch and yaw (the clip's and RUTH's: spine, neck and head, :data:`VOR_GAIN`), so that the
    gaze stays on the partner while the head nods, leans and turns."""

    name = "signals"

    def __init__(self, signals, gaze=None, base=None) -> None:
        from gesture_sim.signals.face_rig import GAZE_JOINTS
        from gesture_sim.signals.gaze import Gaze
        from gesture_sim.signals.ruth import SIGNAL_JOINTS
        from gesture_sim.sim.humanoid import actuated_index

        self.signals = signals
        self.gaze = gaze if gaze is not None else Gaze(seed=signals.seed)
        self.base = base
        eyes = tuple(j for j in GAZE_JOINTS if j not in SIGNAL_JOINTS)
        self.joints = tuple(SIGNAL_JOINTS) + eyes
        self._gaze_cols = np.array([self.joints.index(j) for j in GAZE_JOINTS])
        self._pitch_q = actuated_index(list(_HEAD_PITCH))
        self._yaw_q = actuated_index(list(_HEAD_YAW))
        self._pitch_own = np.array([SIGNAL_JOINTS.index(j) for j in _HEAD_PITCH
                                    if j in SIGNAL_JOINTS])
        self._yaw_own = np.array([SIGNAL_JOINTS.index(j) for j in _HEAD_YAW
                                  if j in SIGNAL_JOINTS])
        self._phrase_pending = True

    def reset(self) -> None:
        self.signals.reset()
        self.gaze.reset()
        self._phrase_pending = True

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]:
        from gesture_sim.signals.face_rig import gaze_offsets

        if heard.frames is not None:
            fr = heard.frames.frames
            self.signals.push_frames(fr.times, fr.intensity_db, fr.silent, heard.frames.known,
                                     fr.f0_hz)
        face, events = self.signals.step(t, heard.accents, heard.boundaries, heard.speaking,
                                         heard.silence_s)
        start = bool(heard.accents) and self._phrase_pending
        if start:
            self._phrase_pending = False
        end = bool(heard.boundaries)
        if end:
            self._phrase_pending = True
        seen = len(self.gaze.events)
        yaw, pitch = self.gaze.step(t, heard.speaking, phrase_start=start, phrase_end=end)
        q = self.base() if self.base is not None else None
        if q is not None:            # keep looking at the partner while the head moves
            pitch -= VOR_GAIN * float(q[self._pitch_q].sum() + face[self._pitch_own].sum())
            yaw -= VOR_GAIN * float(q[self._yaw_q].sum() + face[self._yaw_own].sum())
        out = np.zeros(len(self.joints))
        out[:len(face)] = face
        out[self._gaze_cols] += gaze_offsets(yaw, pitch)
        return out, list(events) + self.gaze.events[seen:]


class MouthLayer:
    """Visible speech: the lips and jaw form the phones (visemes with dominance-based
    coarticulation, :mod:`gesture_sim.signals.visemes`) through the face rig
    (:func:`gesture_sim.signals.face_rig.mouth_offsets`).

    ``articulator`` gives the viseme channels at a time (``at(t) -> (6,)``): a
    :class:`~gesture_sim.signals.visemes.Coarticulator` over phones known in advance (a
    TextGrid, a transcript aligned to the audio), or a live one fed by a phone recogniser. The
    smile of ``face`` (RUTH's ``S``) competes with the mouth shape by its dominance: RUTH adds
    the smile's corners, so this layer adds the difference between the blended corners and
    those. While it runs, RUTH's loudness-driven jaw is off (it is the degraded mode without
    phones)."""

    name = "mouth"

    def __init__(self, articulator, face=None) -> None:
        from gesture_sim.signals.face_rig import MOUTH_JOINTS

        self.articulator = articulator
        self.face = face
        if face is not None:
            face.loudness_jaw = False
        self.joints = tuple(MOUTH_JOINTS)
        self._corners = np.array([MOUTH_JOINTS.index(f"{s}_lip_corner_{k}")
                                  for s in ("left", "right") for k in ("out", "up")])

    def reset(self) -> None:
        reset = getattr(self.articulator, "reset", None)
        if reset is not None:
            reset()

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]:
        from gesture_sim.signals.face_rig import (
            SMILE_CORNER_OUT_M,
            SMILE_CORNER_UP_M,
            mouth_offsets,
        )

        for emission in heard.phones:        # a live recogniser's phones, as they are known
            self.articulator.push(emission.phone, emission.emitted_s)
        smile = self.face.smile_level(t) if self.face is not None else 0.0
        out = mouth_offsets(self.articulator.at(t), smile)
        if smile:
            out[self._corners] -= smile * np.array([SMILE_CORNER_OUT_M, SMILE_CORNER_UP_M] * 2)
        return out, []


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


#: What the legs track (``GesturePipeline(legs=...)``): ``"stand"`` the standing pose (the
#: balance controller does the rest), ``"clip"`` the clip's lower body over planted feet
#: (:class:`LowerBody`: weight shifts, sway, knee flexion; the COM target follows the target
#: pose), ``"free"`` the clip's own leg angles as they are (the motion capture's steps
#: included: the soles slide).
LEG_MODES = ("stand", "clip", "free")
#: The leg mode when none is given (BENCHMARKS.md, "Realism and plausibility").
DEFAULT_LEGS = "clip"


class Legs:
    """The legs' stage: what the leg joints of the step's target track (:data:`LEG_MODES`).

    Args:
        mode: one of :data:`LEG_MODES`.
        library: the motion library (``"clip"`` reads its clips' key points).
        control_library: its :class:`~gesture_sim.control.inputs.ControlLibrary` (joint names,
            frame rate).
    """

    def __init__(self, mode: str, library, control_library) -> None:
        from gesture_sim.errors import GestureSimError

        if mode not in LEG_MODES:
            raise GestureSimError(f"legs must be one of {', '.join(LEG_MODES)}; got {mode!r}")
        self.mode = mode
        self.columns = None
        if mode != "free":
            from gesture_sim.sim.humanoid import leg_columns

            self.columns = leg_columns(control_library.joint_names)
        self.lower = LowerBody(library, control_library.fps) if mode == "clip" else None
        #: The stages whose wall time the pipeline keeps.
        self.costs: tuple[str, ...] = ("legs",) if self.lower is not None else ()

    def balance(self):
        """The balance gains the body needs (None: the defaults): with the clip's lower body,
        the COM target follows the target pose (``BalanceGains.follow_target``)."""
        if self.lower is None:
            return None
        from gesture_sim.sim.tracking import BalanceGains

        return BalanceGains(follow_target=True)

    def reset(self) -> None:
        if self.lower is not None:
            self.lower.reset()

    def apply(self, q: np.ndarray, motion: Motion) -> bool:
        """Set the leg columns of ``q`` (n_joints,) in place; True when that was work to time
        (the clip's lower body), False for a fixed pose or the clip's own legs."""
        if self.lower is not None:
            q[self.columns] = self.lower.step(motion.segment, motion.frame, motion.lower)
            return True
        if self.columns is not None:
            q[self.columns] = 0.0
        return False

    def rest(self, rest_pose: np.ndarray | None, n_joints: int) -> np.ndarray | None:
        """The start pose (n_joints,) from the library's rest pose with the legs' rest; None
        (the standing pose) when there is no rest pose and the legs stand or are free."""
        if rest_pose is None:
            if self.lower is None:
                return None
            rest_pose = np.zeros(n_joints)
        q = np.asarray(rest_pose, dtype=float).copy()
        if self.lower is not None:
            q[self.columns] = self.lower.rest_legs
        elif self.columns is not None:
            q[self.columns] = 0.0
        return q


class LowerBody:
    """Leg targets that follow the clip's lower body over planted feet (``legs="clip"``).

    The clips' own leg angles cannot be tracked by a body whose feet stay planted: the motion
    capture steps (the BEAT2 speaker of the default library lifts a foot every few seconds) and
    stands wider than the humanoid. What a planted stance can show of it is where the pelvis is
    over the feet. For every frame of every clip (from its key points, in the pelvis heading
    frame, and its root height) this stage keeps the pelvis's

    * lateral split ``σ`` along the line between the sole centres (a fraction of the feet's
      separation: 0 midway, ±0.5 over the left / right sole; the weight shift),
    * fore-aft offset ``φ`` from the mid-point of the soles, perpendicular to that line (m),
    * height ``h`` above the floor (m),

    each about the clip's own median (its usual stance). At each control step the playing
    segment's frame gives ``p = (φ, σ·w, h_median − h)`` (m; w = 0.18 m, this humanoid's sole
    separation; at rest, no segment: 0), low-passed by two first-order lags of ``tau`` seconds
    each, ``p̄``; the pelvis target over this humanoid's stance is then ::

        dx = max_dx · tanh(gain_x · p̄_x / max_dx)          (forward, m)
        dy = max_dy · tanh(gain_y · p̄_y / max_dy)          (to the left, m)
        dz = max_dz · tanh(max(gain_z · p̄_z, 0) / max_dz)  (lowering, m)

    (a soft bound: never beyond ``max_*``). The lags matter: the segments the timing layer plays
    last about a second and come from all over the take, so σ jumps at the segment rate (and
    the capture's steps swing it by ±0.3 of the separation within a second); two lags of 1.2 s
    keep the slow part — a weight shift every few seconds — and the gain (4 laterally) gives it
    back the size of the capture's own sway while standing (``tools/lower_body.py``,
    BENCHMARKS.md "Realism and plausibility").
    :class:`~gesture_sim.sim.tracking.StanceLegs` turns the target
    into hip, knee and ankle angles with the soles flat where they stand, the pelvis upright
    and square to the feet and the knees soft (≥ 5°). The balance controller follows the COM
    of that pose (``BalanceGains.follow_target``), so the weight shift is carried out rather
    than fought.

    Args:
        library: a :class:`~gesture_sim.motion.library.MotionLibrary` (clips with key points);
            anything else gives the planted stance without motion.
        fps: the control rate (Hz).
        gain, tau, max_dx, max_dy, max_dz: as above (gains (x, y, z); s; m).
        model: the humanoid for :class:`~gesture_sim.sim.tracking.StanceLegs` (default: the
            shipped one).
    """

    name = "legs"

    def __init__(self, library, fps: float, gain: tuple[float, float, float] = (1.0, 4.0, 1.0),
                 tau: float = 1.2, max_dx: float = 0.02, max_dy: float = 0.05,
                 max_dz: float = 0.04, model=None) -> None:
        from gesture_sim.sim.tracking import StanceLegs

        self.stance = StanceLegs(model)
        feet = self.stance.feet
        self.width = float(abs(feet[0, 1] - feet[1, 1]))
        self.gain = tuple(float(g) for g in gain)
        self.tau, self.dt = float(tau), 1.0 / float(fps)
        self.max_dx, self.max_dy, self.max_dz = float(max_dx), float(max_dy), float(max_dz)
        clips, segments = getattr(library, "clips", None), getattr(library, "segments", None)
        if clips is None or segments is None:             # no clips to read (a ControlLibrary)
            clips, segments = [], []
        self._segments = list(segments)
        self._intent = [self._clip_intent(c) for c in clips]
        self.reset()

    def _clip_intent(self, clip) -> np.ndarray | None:
        """(T, 3) target pelvis offsets (dx, dy, dz) of one clip's frames (m), unfiltered."""
        from gesture_sim.motion.retarget import KEYPOINTS

        kp = getattr(clip, "keypoints", None)
        if kp is None or len(kp) == 0:
            return None
        kp = np.asarray(kp, dtype=float)
        left, right = kp[:, KEYPOINTS.index("left_foot")], kp[:, KEYPOINTS.index("right_foot")]
        mid = 0.5 * (left[:, :2] + right[:, :2])
        a = left[:, :2] - right[:, :2]
        sep = np.maximum(np.linalg.norm(a, axis=1), 0.05)
        split = -np.einsum("tc,tc->t", mid, a) / sep ** 2
        fwd = np.stack([a[:, 1], -a[:, 0]], axis=1) / sep[:, None]
        fore = -np.einsum("tc,tc->t", mid, fwd)
        height = np.asarray(clip.root_pos, dtype=float)[:, 2]
        out = np.empty((len(kp), 3))
        out[:, 0] = fore - np.median(fore)
        out[:, 1] = (split - np.median(split)) * self.width
        out[:, 2] = np.median(height) - height
        return out

    def reset(self) -> None:
        """Back to the middle of the stance (the rest pose's legs)."""
        self.stance.reset()
        self._lag = np.zeros((2, 3))
        self.offset = np.zeros(3)
        self.rest_legs = self.stance.solve(0.0, 0.0, 0.0, iterations=20)
        self._legs = self.rest_legs.copy()

    def target(self, segment: int, frame: int) -> np.ndarray:
        """The clip's pelvis offset (φ, σ·w, h_median − h) (m) at a segment's frame (0 at
        rest), before the filter, the gains and the bounds."""
        if segment < 0 or segment >= len(self._segments):
            return np.zeros(3)
        seg = self._segments[segment]
        return self.clip_target(seg.clip, seg.start + int(frame))

    def clip_target(self, clip: int, frame: int) -> np.ndarray:
        """As :meth:`target`, at a clip's frame (clamped to the clip; 0 for an unknown clip or
        one without key points)."""
        intent = self._intent[clip] if 0 <= clip < len(self._intent) else None
        if intent is None:
            return np.zeros(3)
        return intent[min(max(int(frame), 0), len(intent) - 1)]

    def step(self, segment: int, frame: int,
             clip_frame: tuple[int, int] | None = None) -> np.ndarray:
        """Leg angles (len(LEG_JOINTS),) for this control step, in LEG_JOINTS order: from the
        playing segment's frame, or from ``clip_frame`` (clip index, clip frame) when a
        lower-body stream of its own gives one (:attr:`Motion.lower`)."""
        k = self.dt / (self.tau + self.dt)
        lag = self._lag
        p = self.target(segment, frame) if clip_frame is None else self.clip_target(*clip_frame)
        lag[0] += k * (p - lag[0])
        lag[1] += k * (lag[0] - lag[1])
        (gx, gy, gz), (fx, fy, fz) = self.gain, lag[1].tolist()
        dx = self.max_dx * math.tanh(gx * fx / self.max_dx)
        dy = self.max_dy * math.tanh(gy * fy / self.max_dy)
        dz = self.max_dz * math.tanh(max(gz * fz, 0.0) / self.max_dz)
        self.offset = np.array([dx, dy, dz])
        self._legs = self.stance.solve(dx, dy, dz)
        return self._legs


class PlannedMotion(TimedMotion):
    """Speech known ahead: a plan of real segments whose own strokes fall on the stressed
    syllables and accents (:mod:`gesture_sim.control.planner`), played nearly unbent by a
    :class:`~gesture_sim.control.planner.PlannedPlayer`; without the speech ahead (live, from a
    microphone) every step is the causal stage's (``causal``: the controller behind the timing
    layer).

    :meth:`expect` takes the whole audio before the first step (the pipeline's
    :meth:`~gesture_sim.pipeline.GesturePipeline.expect_audio`) with the text known ahead;
    the analysis ahead (:func:`~gesture_sim.audio.known.analyse_known`) and the plan are made
    there, their wall time in ``costs["planning"]``.

    Args:
        causal: the causal :class:`TimedMotion` (its filter and control layer are this stage's).
        player: the planned player. plan_library: the planner's view of the library.
        settings: :class:`~gesture_sim.control.planner.PlanSettings`.
        new_filter: a factory of fresh belief filters (the belief ahead, for the prior).
    """

    def __init__(self, causal: TimedMotion, player, plan_library, settings,
                 new_filter=None) -> None:
        # the causal stage's filter, control layer and style dial are this stage's own
        self.causal = causal
        self.player = player
        self.plan_library = plan_library
        self.settings = settings
        self.new_filter = new_filter
        self.filter = causal.filter
        self.chooser = causal.chooser
        self.costs = dict(causal.costs)
        self.costs["planning"] = StageCost()
        self.plan = None
        self.known = None
        self.timing: dict[str, float] = {}

    def reset(self) -> None:
        self.causal.reset()
        self.player.reset()
        self.plan = self.known = None

    def set_style(self, style: float, energy: float) -> None:
        self.causal.set_style(style, energy)

    def trim(self, t_min: float, keep: int) -> None:
        self.causal.trim(t_min, keep)

    def expect(self, samples: np.ndarray, words=None, phones=None, stress=None) -> None:
        """Plan the stream ``samples`` (n,) float 16 kHz, known ahead with its timed ``words``,
        ``phones`` and ``stress`` (s) where given."""
        from gesture_sim.audio.known import analyse_known
        from gesture_sim.control.planner import Speech, plan_speech

        t0 = time.perf_counter()
        known = analyse_known(samples, words=words, phones=phones, stress=stress)
        t1 = time.perf_counter()
        fps = self.plan_library.fps
        k = np.arange(int(np.ceil(known.duration_s * fps)) + 1)
        belief = self._belief_ahead(known, k / fps) if self.settings.prior_weight > 0 else None
        t2 = time.perf_counter()
        targets = np.concatenate([known.stress, known.accents])
        weights = np.concatenate([np.ones(len(known.stress)),
                                  np.full(len(known.accents), self.settings.accent_weight
                                          if len(known.stress) else 1.0)])
        speech = Speech(known.duration_s, targets, known.spans, weights=weights,
                        belief=belief, energy=known.energy_at(k / fps))
        self.known = known
        self.plan = plan_speech(self.plan_library, speech, self.settings)
        self.player.set_plan(self.plan)
        t3 = time.perf_counter()
        #: wall seconds of the analysis ahead, the belief ahead and the search
        self.timing = {"analysis_s": t1 - t0, "belief_s": t2 - t1, "search_s": t3 - t2}
        self.costs["planning"].add(t3 - t0)

    def _belief_ahead(self, known, times: np.ndarray) -> np.ndarray | None:
        """(K, S) the belief a fresh filter holds at ``times`` (s) over the syllables ahead,
        each seen at its emission time, as the causal step sees it."""
        if self.new_filter is None:
            return None
        f = self.new_filter()
        f.reset()
        syl = sorted(known.syllables, key=lambda s: s.t_emitted)
        out, j = [], 0
        for t in times:
            new = []
            while j < len(syl) and syl[j].t_emitted <= t + 1e-9:
                new.append(syl[j])
                j += 1
            out.append(np.asarray(f.step(float(t), new), dtype=float))
        return np.asarray(out)

    def step(self, t: float, heard: Heard) -> Motion:
        if self.plan is None:
            return self.causal.step(t, heard)
        t0 = time.perf_counter()
        belief = self.filter.step(t, heard.syllables)
        t1 = time.perf_counter()
        self.causal._dial.follow(heard.energy)        # the emblems' choice, as on the causal path
        cue = SpeechCue(speaking=heard.speaking, silence_s=heard.silence_s,
                        accents=[a.t for a in heard.accents], energy=heard.energy)
        r = self.player.step(t, belief, cue)
        self.costs["inference"].add(t1 - t0)
        self.costs["control"].add(time.perf_counter() - t1)
        return Motion(belief, r.segment, r.frame, r.target, r.decision, r.mode, r.stroke)
