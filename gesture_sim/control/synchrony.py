"""The timing layer: *when* the body moves (Levine 2009 synchrony rule; issue "the body follows
the speech").

The control layer's MDP (:class:`~gesture_sim.control.controller.GestureController`) decides
*which* motion plays; this layer decides *when*, from the speech, causally:

* **Strokes on accents.** A stroke is a peak of the clip's hand speed. When the accent detector
  emits an accent, the playhead runs to the next stroke peak so that it arrives ``lead_s`` after
  the emission (playback faster than the clip, up to ``rate_max``; a preparation too long for that
  is skipped, the jump smoothed by the switch ramp, only with ``skip_after_s`` set; by default
  never, as in real motion).
  McNeill's rule, as the thesis cites it: the
  stroke ends at or before the stress peak — here, as early as the causal detector allows.
* **Holds (late termination).** Without a pending accent the clip plays at its own pace to the
  next speed dip after a stroke and holds there (the pre-stroke hold, drifting on at
  ``hold_rate``) until the next accent, at most ``hold_max_s``; then it creeps on at
  ``rate_idle``.
* **Early termination.** At a decision point, with an accent pending and no stroke left in the
  playing segment within reach, the MDP's best *switch* is taken instead of continuing.
* **Rest in silence.** After ``rest_after_s`` of silence the hands retract over ``to_rest_s`` to a
  rest pose drawn from the library's own co-speech frames (hands low and slow) and stay there,
  with a breathing motion. Voice onset leaves rest with a fresh segment whose first stroke is
  triggered at once (at voice onset, before the first accent is known). A stream begins at
  rest.
* **Energy from the voice.** ``energy`` in [-1, 1] (louder, livelier speech than this speaker's
  usual > 0) scales the playback rate and the amplitude about the rest pose; the style dial of
  the MDP (which segments) is the pipeline's to set from the same figure. The amplified pose
  keeps every joint within the range the library's co-speech frames cover (``amplitude_in_range``):
  larger gestures, never a pose no real gesture had (an elbow bent past the speaker's own, the
  hand folded back to the jaw).

Everything here is per control step (one library frame, 1/fps s); times are stream seconds.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from gesture_sim.contracts import Decision
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.control.ramp import (
    DEFAULT_BLEND_FRAMES,
    DEFAULT_CARRY_S,
    SwitchRamp,
    TransitionPath,
    carried,
    smoothstep,
)
from gesture_sim.errors import GestureSimError

#: Modes of the player, as logged.
MODES = ("rest", "play", "hold", "stroke", "to_rest")


@dataclass(frozen=True)
class SyncSettings:
    """Settings of the timing layer (seconds, frames per control step, m/s).

    Attributes:
        lead_s: aimed time from an accent's emission to the stroke peak.
        rate_max: fastest playback toward a stroke (× the clip's own speed).
        skip_after_s: a stroke peak farther than this at ``rate_max`` is reached by skipping
            the preparation (a jump, smoothed by the switch ramp); ``None`` (the default):
            never, as real motion does. The skips made half of all target switches and cost
            naturalness by every figure: with physics on the three held-out takes (stop 42, 27 runs;
            docs/history.md, "skipped preparations"), turning them off took the discriminator from
            0.963 to 0.942, FGD 50 -> 47, jerk 84 -> 79 m/s³, target switches 124 -> 60 a minute,
            with every coupling figure still beating random clips and mismatched audio and no fall
            (the one fall without skips, stop 41, the balance law's hip strategy now catches:
            ``BalanceGains.hip_guard``). The hand that came to the jaw on take 2_2 without skips
            (gap -2.4 cm) was no self-touch of the library (that segment's own frames stay 13 cm
            from the head) but the amplitude: see ``amplitude_in_range``. 0.12 s was the old
            default.
        accent_ttl_s: an accent not served within this time after its emission is dropped.
        stroke_quantile: an accent calls for a stroke when its strength is at least this
            quantile of the speaker's last 60 accents (0: every accent); the weaker ones pass
            without a stroke, so that strokes mark the prominent syllables, not every one.
        stroke_rate: strokes per second the speaker's accents are thinned to, most prominent
            first: when the last 60 accents came at a rate R above it, an accent calls for a
            stroke only when its strength reaches the ``1 - stroke_rate / R`` quantile of their
            strengths (slow speech keeps every accent). ``None``: the stroke rate of the
            library's co-speech clips (stroke marks per second of real motion: 1.26 /s for the
            default library), so the body strokes as often as the real speaker did; 0: no limit.
        hold_max_s: longest pre-stroke hold while speech goes on; then ``rate_idle``.
        hold_rate: playback rate during a pre-stroke hold while speech goes on: a held hand
            drifts on slowly along its clip, as real holds do, instead of freezing (a frozen
            target is a speed minimum at zero, which real speech-time motion does not have;
            0, 0.15, 0.2 and 0.3 measured kinematic and with physics: docs/history.md). Pauses
            hold still.
        hold_at_entry: a segment entered without a pending accent holds at its first frame
            (segments begin at slow points) instead of playing its first stroke unaccented.
        finish_stroke: a stroke under way to an accent is not interrupted: the decision points
            before its peak are passed over (the MDP decides after it); without it an
            interruption frame on the way could cut the stroke and leave the accent unmet.
        rate_idle: playback rate after a hold timed out.
        pause_hold_s: silence after which the playhead holds (no stroke starts in a pause).
        rest_after_s: silence that sends the hands to rest.
        to_rest_s: duration of the retraction to rest.
        blend_s: the switch ramp (a jump of the targets is blended in over this time; default
            :data:`~gesture_sim.control.ramp.DEFAULT_BLEND_FRAMES` steps at 30 Hz).
        rate_tau_s: time constant (s) of a first-order easing of the playback rate (before
            the real-hand speed bound, which it never exceeds): the rate steps between play,
            stroke, hold and idle and with the voice's energy, and a step in the rate is a step
            in the targets' velocity; 0: the rate steps (before stop 44). 0.05 s: FGD, the
            discriminator and the jerk fall with the coupling kept; 0.1 s and more lower
            beat consistency (docs/history.md, "switch ramp").
        carry_s: the pose a switch ramp (or the retraction to rest) blends from carries on
            with the targets' velocity at the switch, decaying with this time constant (s;
            :func:`~gesture_sim.control.ramp.carried`; default
            :data:`~gesture_sim.control.ramp.DEFAULT_CARRY_S`); 0: blended from the pose held
            still (the targets' velocity dropped to zero at every switch; before stop 44).
        energy_rate, energy_gain: playback rate factor ``1 + energy_rate * energy``; the
            amplitude about the rest pose is ``1 + energy_gain * energy`` (0.6 … 1.5) times a
            factor that brings each segment's hand extent towards the co-speech median
            (bounded by ``gain_range``), so the voice sets how large the motion is whatever
            form the MDP chose.
        gain_range: the bounds of the extent-normalising factor.
        amplitude_in_range: the amplified pose (``rest + gain * (clip - rest)``) keeps each
            joint within the range of the library's co-speech frames, or within the clip's own
            value where the clip itself lies beyond that range (a gain of 1 or under is never
            bounded: it leaves the clip as it is or brings it towards the rest pose). Without
            it the gain (up to 1.5 × 1.33) drove joints past any real gesture on a quarter of
            the control steps of take 2_2: the right elbow to 3.3 rad (the speaker's largest
            co-speech flexion 2.36, the humanoid's limit 2.62), folding the hand back to the
            jaw and neck for 4 frames and sweeping it past the cranium in the next switch ramp
            (gaps -2.4 cm; 13 cm and more with the range kept). False: the old unbounded gain.
        gain_tau_s: time constant (s) of a first-order smoothing of that amplitude: the voice's
            energy and each new segment's extent factor change the amplitude step-wise, and a
            step in the amplitude is a step in the joint targets (jerk); 0: no smoothing (the
            amplitude jumps with the energy, as before; measured in docs/history.md,
            "amplitude").
        speed_quantile: the hand speed the targets may reach is this quantile of the library's
            co-speech hand speed (real motion): playback slows where rate × amplitude would
            make the hands faster than real people move them; and the joint targets' step is
            scaled down (all joints together) where a joint would move faster than this
            quantile of its own speed in the co-speech clips × ``joint_speed_margin`` (jumps,
            blends, retractions).
        onset_entry_s: leaving rest at a voice onset, the fresh segment is entered at most
            this far (s of the clip at ``rate_max``) before its first stroke peak, its earlier
            preparation left out (the ramp from rest is the preparation): the first stroke
            comes that much sooner after the onset. ``None``: at the segment's start, as
            before (issue 55; ``gesture-sim bench onset``).
        onset_blend_s: the switch ramp's length when leaving rest at a voice onset (``None``:
            ``blend_s``): the hands rise from rest into the stroke in this time.
        onset_rate_at_once: leaving rest, the playback rate starts at its value instead of
            easing up from 0 over ``rate_tau_s`` (the ramp from rest already smooths the
            targets' velocity).
        peak_prominence: a stroke peak's prominence in hand speed (m/s).
        breathing_hz, breathing_rad: the resting breath (upper spine flexion, clavicles).
    """

    lead_s: float = 0.08
    rate_max: float = 1.5
    skip_after_s: float | None = None
    accent_ttl_s: float = 0.35
    stroke_quantile: float = 0.0
    stroke_rate: float | None = None
    hold_max_s: float = 0.8
    hold_rate: float = 0.2
    hold_at_entry: bool = True
    finish_stroke: bool = True
    rate_idle: float = 0.6
    pause_hold_s: float = 0.2
    rest_after_s: float = 0.4
    to_rest_s: float = 0.35
    blend_s: float = DEFAULT_BLEND_FRAMES / 30.0
    carry_s: float = DEFAULT_CARRY_S
    rate_tau_s: float = 0.05
    energy_rate: float = 0.3
    energy_gain: float = 0.7
    gain_range: tuple[float, float] = (0.75, 1.33)
    amplitude_in_range: bool = True
    gain_tau_s: float = 0.4
    speed_quantile: float = 0.99
    joint_speed_margin: float = 1.0
    onset_entry_s: float | None = None
    onset_blend_s: float | None = None
    onset_rate_at_once: bool = False
    peak_prominence: float = 0.2
    breathing_hz: float = 0.25
    breathing_rad: float = 0.012

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class SpeechCue:
    """What the speech says to the timing layer at one control step.

    Attributes:
        speaking: voice activity now. silence_s: seconds since the last voiced/loud frame.
        accents: times (s) of the accents emitted since the previous step.
        strengths: how prominent each is (the pipeline passes the pitch prominence, z units),
            same length, or empty (all strong).
        energy: vocal energy in [-1, 1] relative to the speaker's running statistics.
    """

    speaking: bool
    silence_s: float
    accents: Sequence[float] = ()
    energy: float = 0.0
    strengths: Sequence[float] = ()


@dataclass(frozen=True)
class StrokeMarks:
    """Stroke peaks and dips of one segment (frame offsets from its start, ascending)."""

    peaks: np.ndarray
    dips: np.ndarray


def stroke_marks(speed: np.ndarray, prominence: float = 0.2, sigma: float = 1.0) -> StrokeMarks:
    """Peaks (strokes) and dips (hold points) of a ``(T,)`` hand-speed curve (m/s per frame).

    Peaks: maxima of the lightly smoothed speed with at least ``prominence`` m/s. Dips: the
    minimum between two peaks, before the first and after the last.
    """
    s = np.asarray(speed, dtype=float)
    if s.size < 3:
        return StrokeMarks(np.zeros(0, np.int64), np.zeros(0, np.int64))
    sm = gaussian_filter1d(s, sigma) if sigma > 0 else s
    peaks, _ = find_peaks(sm, prominence=prominence)
    edges = np.concatenate([[0], peaks, [len(sm) - 1]])
    dips = [int(a + np.argmin(sm[a:b + 1])) for a, b in zip(edges[:-1], edges[1:], strict=True)
            if b > a]
    dips = sorted(set(d for d in dips if d not in set(peaks.tolist())))
    return StrokeMarks(peaks.astype(np.int64), np.asarray(dips, dtype=np.int64))


@dataclass
class SyncStep:
    """One control step of the timing layer.

    Attributes:
        t: stream time (s). segment: playing segment (-1 at rest or retracting to it).
        frame: integer frame offset shown (floor of the playhead; -1 at rest).
        target: (n_joints,) joint targets (rad).
        decision: the MDP decision taken at this step, if any. mode: one of :data:`MODES`.
        stroke: True when a stroke peak was passed at this step. rate: playback rate.
        gain: amplitude about the rest pose.
    """

    t: float
    segment: int
    frame: int
    target: np.ndarray
    decision: Decision | None
    mode: str
    stroke: bool = False
    rate: float = 0.0
    gain: float = 1.0


@dataclass
class SyncLog:
    """What the timing layer did: stroke times, served accents (accent t, stroke t), holds."""

    strokes: list[float] = field(default_factory=list)
    served: list[tuple[float, float]] = field(default_factory=list)
    accents: list[float] = field(default_factory=list)
    rest_spans: list[list[float]] = field(default_factory=list)


class SyncPlayer:
    """Plays the segments the MDP chooses, timed by the speech (see the module docstring).

    Args:
        library: the control library (segment poses, hand speeds, decision frames, rest pose).
        chooser: the MDP controller (``decide_start(b, t)``, ``decide_at(b, a, k, t)``,
            ``decision_point(a, frame)``, ``label``, ``policy.n_points``).
        settings: :class:`SyncSettings`.
        rest_pose: (n_joints,) the rest pose (default: ``library.rest_pose`` or zeros).
        path: the switch ramp's transition path (:data:`~gesture_sim.control.ramp.
            TransitionPath`, e.g. a :class:`~gesture_sim.motion.gpdm.GPDMPath`); None: the
            straight line in joint space.

    The amplitude is scaled about the rest pose on every joint (the legs are held by the
    pipeline, the face joints are at rest in the clips); the breath moves the upper spine and
    the clavicles.
    """

    def __init__(self, library: ControlLibrary, chooser, settings: SyncSettings | None = None,
                 rest_pose: np.ndarray | None = None, path: TransitionPath | None = None
                 ) -> None:
        if library.segment_qpos is None:
            raise GestureSimError("the timing layer needs a library with joint poses")
        self.library = library
        self.chooser = chooser
        self.cfg = settings or SyncSettings()
        self.path = path            # the switch ramp's transition path (None: joint space)
        self.dt = 1.0 / library.fps
        q0 = np.asarray(library.segment_qpos(0))
        self.n_joints = q0.shape[1]
        rp = rest_pose if rest_pose is not None else getattr(library, "rest_pose", None)
        self.rest = np.zeros(self.n_joints) if rp is None else np.asarray(rp, float).copy()
        names = list(library.joint_names) or [""] * self.n_joints
        self._breath = np.zeros(self.n_joints)
        for j, name in enumerate(names):
            if name == "upper_spine_flex":
                self._breath[j] = 1.0
            elif name.endswith("clavicle_elevate"):
                self._breath[j] = 0.8
        self._marks: dict[int, StrokeMarks] = {}
        self._qpos: dict[int, np.ndarray] = {}
        self._speed: dict[int, np.ndarray] = {}
        self.v_cap = np.inf
        pool = np.nonzero(library.cospeech)[0]
        dq = np.concatenate([np.abs(np.diff(self.qpos(i), axis=0)) for i in pool
                             if library.lengths[i] > 1])
        self.qd_cap = (self.cfg.joint_speed_margin
                       * np.quantile(dq, self.cfg.speed_quantile, axis=0) + 1e-3 * self.dt)
        # the range of every joint over the co-speech frames: the amplitude stays within it
        q_pool = [self.qpos(i) for i in pool]
        self.q_lo = np.min([q.min(axis=0) for q in q_pool], axis=0)
        self.q_hi = np.max([q.max(axis=0) for q in q_pool], axis=0)
        ext = getattr(library, "hand_extent", None)
        self.extent = None if ext is None else np.asarray(ext, dtype=float)
        self.extent_ref = (float(np.median(self.extent[pool])) if self.extent is not None
                           else 0.0)
        if library.hand_speed is not None:
            self.v_cap = float(np.quantile(np.concatenate([library.hand_speed(i) for i in pool]),
                                           self.cfg.speed_quantile))
        self.stroke_rate = self.cfg.stroke_rate
        if self.stroke_rate is None:
            # the real speaker's own stroke rate: stroke marks per second of co-speech clips
            seconds = float(np.sum(library.lengths[pool])) / library.fps
            self.stroke_rate = (sum(len(self.marks(int(i)).peaks) for i in pool) / seconds
                                if seconds > 0 else 0.0)
        # the carried pose of a switch stays within the co-speech range (amplitude_in_range)
        self._bounds = (self.q_lo, self.q_hi) if self.cfg.amplitude_in_range else None
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to rest at t = 0."""
        self.mode = "rest"
        self.segment = -1
        self.p = 0.0
        self.pending: float | None = None       # time the pending accent was emitted
        self.pending_t: float | None = None     # its own time
        self.hold_t = 0.0
        self.idle = False
        self._ramp = SwitchRamp(int(round(self.cfg.blend_s / self.dt)),
                                carry_tau=self.cfg.carry_s / self.dt,
                                path=self.path, bounds=self._bounds)
        self._last = self.rest.copy()
        self._last_v = np.zeros_like(self._last)    # the targets' change over the last step
        self._rate_now = 0.0                          # the last step's playback rate
        self._rest_v: np.ndarray | None = None
        self._rest_from: np.ndarray | None = None
        self._rest_k = 0
        self.log = SyncLog()
        self.log.rest_spans.append([0.0, float("inf")])
        self._strengths: deque[float] = deque(maxlen=60)
        self._accent_times: deque[float] = deque(maxlen=60)
        self._gain_now: float | None = None      # the smoothed amplitude (gain_tau_s)

    # ------------------------------------------------------------------ library views
    def hand_speed(self, a: int) -> np.ndarray:
        """(length,) the segment's own hand speed (m/s) per frame."""
        v = self._speed.get(a)
        if v is None:
            hs = self.library.hand_speed
            v = (np.asarray(hs(a), float) if hs is not None
                 else np.zeros(int(self.library.lengths[a])))
            self._speed[a] = v
        return v

    def marks(self, a: int) -> StrokeMarks:
        m = self._marks.get(a)
        if m is None:
            m = stroke_marks(self.hand_speed(a), self.cfg.peak_prominence)
            self._marks[a] = m
        return m

    def qpos(self, a: int) -> np.ndarray:
        q = self._qpos.get(a)
        if q is None:
            q = np.asarray(self.library.segment_qpos(a), dtype=float)
            self._qpos[a] = q
        return q

    def _pose(self, a: int, p: float, gain: float) -> np.ndarray:
        q = self.qpos(a)
        i = int(np.floor(p))
        i = min(max(i, 0), len(q) - 1)
        j = min(i + 1, len(q) - 1)
        x = p - i
        clip = q[i] + (q[j] - q[i]) * x
        out = self.rest + gain * (clip - self.rest)
        if self.cfg.amplitude_in_range and gain != 1.0:
            out = np.clip(out, np.minimum(self.q_lo, clip), np.maximum(self.q_hi, clip))
        return out

    def _cospeech(self, a: int) -> bool:
        return a < 0 or bool(self.library.cospeech[a])

    def _strong(self, strength: float, t_accent: float) -> bool:
        """Whether the accent at ``t_accent`` (s) of this ``strength`` calls for a stroke: at
        least the ``stroke_quantile`` of this speaker's recent accent strengths, and at least
        the quantile that thins their recent rate to ``stroke_rate`` (the first few always do)."""
        if self.cfg.stroke_quantile <= 0.0 and self.stroke_rate <= 0.0:
            return True
        hist, times = self._strengths, self._accent_times
        q = self.cfg.stroke_quantile
        if self.stroke_rate > 0.0 and len(times) >= 5:
            span = times[-1] - times[0]
            rate = (len(times) - 1) / span if span > 0 else np.inf
            q = max(q, 1.0 - self.stroke_rate / rate)
        ok = (len(hist) < 5 or not np.isfinite(strength) or q <= 0.0
              or strength >= np.quantile(np.asarray(hist), q))
        if np.isfinite(strength):
            hist.append(strength)
            times.append(t_accent)
        return bool(ok)

    def _gain(self, energy: float) -> float:
        """Amplitude about the rest pose for the playing segment (see ``energy_gain``),
        smoothed over ``gain_tau_s``."""
        cfg = self.cfg
        if not self._cospeech(self.segment):
            self._gain_now = None
            return 1.0                 # an emblem keeps its own form
        voice = float(np.clip(1.0 + cfg.energy_gain * energy, 0.6, 1.5))
        norm = 1.0
        if self.extent is not None and self.segment >= 0 and self.extent_ref > 0:
            norm = self.extent_ref / max(float(self.extent[self.segment]), 1e-3)
        target = voice * float(np.clip(norm, *cfg.gain_range))
        if self._gain_now is None or cfg.gain_tau_s <= 0.0:
            self._gain_now = target
        else:
            self._gain_now += (target - self._gain_now) * min(1.0, self.dt / cfg.gain_tau_s)
        return self._gain_now

    def _next_peak(self, a: int, p: float) -> int | None:
        pk = self.marks(a).peaks
        nxt = pk[pk > p + 1e-9]
        return int(nxt[0]) if len(nxt) else None

    # ------------------------------------------------------------------ stepping
    def step(self, t: float, belief: np.ndarray, cue: SpeechCue) -> SyncStep:
        """One control step at stream time ``t`` (s) with the newest belief and speech cue."""
        cfg = self.cfg
        strengths = list(cue.strengths) or [np.inf] * len(cue.accents)
        for ta, strength in zip(cue.accents, strengths, strict=True):
            self.log.accents.append(float(ta))
            if self._strong(float(strength), float(ta)):
                self.pending, self.pending_t = t, float(ta)
        if self.pending is not None and t - self.pending > cfg.accent_ttl_s:
            self.pending = self.pending_t = None
        energy = float(np.clip(cue.energy, -1.0, 1.0))
        gain = self._gain(energy)
        label = bool(getattr(self.chooser, "label", 0))
        decision: Decision | None = None
        stroke = False
        rate = 0.0

        if self.mode in ("rest", "to_rest"):
            starting = label or cue.speaking         # voice onset (or a requested gesture)
            if starting:
                decision = self.chooser.decide_start(belief, t)
                from_rest = self.mode == "rest" and not label
                self._enter(decision, blend=True,
                            onset=from_rest)
                self._close_rest(t)
                if self.pending is None:
                    self.pending, self.pending_t = t, t
            else:
                return self._rest_step(t, gain)
        elif (not cue.speaking and cue.silence_s >= cfg.rest_after_s and not label
              and self._cospeech(self.segment)):
            self.mode = "to_rest"
            self._rest_from, self._rest_k = self._last.copy(), 0
            self._rest_v = self._last_v.copy()
            self.pending = self.pending_t = None
            self.log.rest_spans.append([t, float("inf")])
            return self._rest_step(t, gain)

        # ---- a requested gesture does not wait for the playhead: decide at the next
        # decision point of the playing segment now (a semantic entry, Gesture Controllers §8.1)
        if label and decision is None:
            decision = self._serve_label(belief, t)
        # ---- play / hold / stroke
        a = self.segment
        length = int(self.library.lengths[a])
        fps = self.library.fps
        if not self._cospeech(a):
            rate = 1.0                 # a requested emblem plays through at its own pace
            self.mode = "play"
        elif self.pending is not None:
            peak = self._next_peak(a, self.p)
            dist = (peak if peak is not None else length - 1) - self.p
            want = cfg.lead_s * fps
            if (peak is not None and cfg.skip_after_s is not None
                    and dist > cfg.rate_max * cfg.skip_after_s * fps):
                self._jump_to(a, max(self.p, peak - cfg.rate_max * want))
                dist = peak - self.p
            rate = float(np.clip(dist / max(want, 1e-9), 1.0, cfg.rate_max))
            self.mode = "stroke"
            self.hold_t, self.idle = 0.0, False
        elif cue.silence_s >= cfg.pause_hold_s:
            self.mode = "hold"                 # a pause: no stroke starts, the hands wait
            rate = 0.0
        elif self.mode == "hold":
            self.hold_t += self.dt
            rate = cfg.hold_rate
            if self.hold_t >= cfg.hold_max_s:
                self.mode, self.idle = "play", True
                rate = cfg.rate_idle
        else:
            rate = cfg.rate_idle if self.idle else 1.0
            self.mode = "play"
        if rate > 0:
            rate *= float(np.clip(1.0 + cfg.energy_rate * energy, 0.5, 1.5))
        if cfg.rate_tau_s > 0 and not math.isnan(self._rate_now):
            # the playback rate eases to its new value: a step in the rate is a step in the
            # targets' velocity
            rate = self._rate_now + (rate - self._rate_now) * (
                1.0 - math.exp(-self.dt / cfg.rate_tau_s))
            rate = rate if rate > 1e-3 else 0.0
        if rate > 0:
            # no faster than real hands: the clip's speed over the coming frames × rate × gain
            v = self.hand_speed(a)
            i0 = int(np.floor(self.p))
            v_ahead = float(v[i0:i0 + int(np.ceil(rate)) + 1].max()) * gain
            if v_ahead * rate > self.v_cap:
                rate = max(self.v_cap / v_ahead, 0.25)
        self._rate_now = rate
        if rate > 0:
            p_new = self.p + rate
            peak = self._next_peak(a, self.p)
            if peak is not None and self.p < peak <= p_new:
                stroke, self.idle = True, False
                self.log.strokes.append(t)
                if self.pending is not None:
                    self.log.served.append((float(self.pending_t), t))
                    self.pending = self.pending_t = None
                    self.mode = "play"
            if self.pending is None and not self.idle and self._cospeech(a):
                dips = self.marks(a).dips
                lo = float(peak) if stroke else self.p
                crossed = dips[(dips > lo + 1e-9) & (dips <= p_new)]
                if len(crossed):
                    p_new = float(crossed[0])
                    self.mode, self.hold_t = "hold", 0.0
            decision = self._advance(belief, t, a, p_new) or decision
        q = self._limit(self._ramp(self._pose(self.segment, self.p, gain)))
        self._last_v = q - self._last
        self._last = q
        return SyncStep(t=t, segment=self.segment, frame=int(np.floor(self.p)), target=q,
                        decision=decision, mode=self.mode, stroke=stroke, rate=rate, gain=gain)

    def _advance(self, belief: np.ndarray, t: float, a: int, p_new: float) -> Decision | None:
        """Move the playhead to ``p_new``; at the first decision frame crossed on the way (an
        interruption frame or the last frame; a requested emblem's last frame only) take the
        MDP's decision, and follow it if it switches. With an accent pending and no stroke
        left in the segment after that frame, the MDP's best switch is preferred to
        continuing (early termination)."""
        last = int(self.library.lengths[a]) - 1
        p_new = min(p_new, float(last))
        target = (self._next_peak(a, self.p) if self.pending is not None
                  and self.cfg.finish_stroke else None)
        through = not self._cospeech(a)        # a requested emblem plays through to its end
        for f in range(int(np.floor(self.p)) + 1, int(np.floor(p_new)) + 1):
            k = self.chooser.decision_point(a, f)
            if k < 0 or (target is not None and f < target) or (through and f < last):
                continue
            early = self.pending is not None and self._next_peak(a, float(f)) is None
            decision = self.chooser.decide_at(belief, a, k, t, prefer_switch=early)
            if decision.costs.get("continue", 0.0):
                continue
            self._enter(decision, blend=True)
            return decision
        self.p = p_new
        if self.p >= last:        # a last frame that is no decision point: start afresh
            decision = self.chooser.decide_start(belief, t)
            self._enter(decision, blend=True)
            return decision
        return None

    def _serve_label(self, belief: np.ndarray, t: float) -> Decision | None:
        a = self.segment
        last = int(self.library.lengths[a]) - 1
        for f in range(int(np.ceil(self.p)), last + 1):
            k = self.chooser.decision_point(a, f)
            if k >= 0:
                d = self.chooser.decide_at(belief, a, k, t)
                if not d.costs.get("continue", 0.0):
                    self._enter(d, blend=True)
                    self.mode = "play"
                    return d
                return None
        return None

    def _enter(self, decision: Decision, blend: bool, onset: bool = False) -> None:
        """Start playing the decided segment at the decided frame (ramping from the last
        target when the pose jumps). ``onset``: leaving rest at a voice onset (the settings
        ``onset_entry_s``, ``onset_blend_s`` and ``onset_rate_at_once`` apply)."""
        cfg = self.cfg
        seg = int(decision.segment_id)
        offset = float(decision.frame - int(self.library.starts[seg]))
        if onset and cfg.onset_entry_s is not None and self._cospeech(seg):
            peak = self._next_peak(seg, offset)
            if peak is not None:
                offset = max(offset, peak - cfg.onset_entry_s * cfg.rate_max
                             * self.library.fps)
        jumped = seg != self.segment or abs(offset - self.p) > 1.5
        self.segment, self.p = seg, offset
        self.hold_t, self.idle = 0.0, False
        # a new segment waits at its entry for the next accent (its first stroke is the
        # accent's), unless one is pending already
        self.mode = "play" if self.pending is not None or not cfg.hold_at_entry else "hold"
        if onset and cfg.onset_rate_at_once:
            self._rate_now = float("nan")        # the next step's rate is taken as it is
        if blend and jumped:
            n = (None if not onset or cfg.onset_blend_s is None
                 else int(round(cfg.onset_blend_s / self.dt)))
            self._ramp.start(self._last, self._last_v, n=n)

    def _jump_to(self, a: int, p: float) -> None:
        self.segment, self.p = a, float(p)
        self._start_blend()

    def _start_blend(self) -> None:
        self._ramp.start(self._last, self._last_v)

    def _limit(self, q: np.ndarray) -> np.ndarray:
        """Scale the step from the last target so that no joint moves faster than real
        co-speech motion does (``qd_cap`` per step), keeping the step's direction."""
        step = q - self._last
        ratio = float(np.max(np.abs(step) / self.qd_cap))
        return self._last + step / ratio if ratio > 1.0 else q

    def _rest_step(self, t: float, gain: float) -> SyncStep:
        cfg = self.cfg
        breath = (cfg.breathing_rad * np.sin(2 * np.pi * cfg.breathing_hz * t)) * self._breath
        rest = self.rest + breath
        if self.mode == "to_rest" and self._rest_from is not None:
            self._rest_k += 1
            n = max(1, int(round(cfg.to_rest_s / self.dt)))
            w = smoothstep(self._rest_k / n)
            c = carried(self._rest_from, self._rest_v, self._rest_k, cfg.carry_s / self.dt,
                        self._bounds)
            q = c + w * (rest - c)
            if self._rest_k >= n:
                self.mode, self._rest_from = "rest", None
        else:
            self.mode = "rest"
            q = rest
        self._ramp.reset()
        q = self._limit(q)
        self._last_v = q - self._last
        self._last = q
        return SyncStep(t=t, segment=-1, frame=-1, target=q, decision=None, mode=self.mode,
                        gain=gain)

    def _close_rest(self, t: float) -> None:
        if self.log.rest_spans and self.log.rest_spans[-1][1] == float("inf"):
            self.log.rest_spans[-1][1] = t
