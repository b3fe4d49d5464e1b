"""The listening body: backchannels driven by the partner's speech, causally.

Okwechime 2011's audio-driven listener (thesis §4.5.3) maps the speaker's MFCC classes to
listener motion and so "nods whenever speech is present"; the thesis's later chapters add rules
so that the listener responds to *what* the speaker does. Here the rule is prosodic, after Ward
& Tsukahara 2000: a region of pitch below the speaker's 26th percentile lasting >= 110 ms, after
>= 700 ms of speech, invites a backchannel about 700 ms later. Adapted to a causal pipeline:

* **Opportunity.** The partner has spoken for at least ``min_speech_s`` since the last pause and
  then pauses for ``pause_wait_s`` (no speech frame known in that time). The pause start
  (``t_cue``) is the end of the last speech frame; the decision (``t_emitted``) is the first
  control step at which that much silence is known, so it is causal by construction.
* **Invitation** (the listener's reading of the phrase end). Over the last ``final_s`` of
  voiced speech before the pause (looking back at most ``final_lookback_s``):
  *low*: at least ``low_region_s`` of those frames lie below the partner's ``low_pct``
  percentile of F0 (speaker-relative: percentiles of the partner's own voiced frames so far);
  *falling* (final lowering): the end level (mean of the last ``end_s`` of voiced frames) lies
  ``fall_st`` semitones below the highest point of the looked-back stretch (5-frame running
  median) and below the partner's median; *rising*: the end level lies ``rise_st`` above its
  lowest point (a question, a continuation rise). Invited = (low or falling) and not rising.
* **Decision.** An invited cue gets a backchannel with probability ``p_invited``, any other
  opportunity with ``p_other`` (seeded). Never while ``own_speaking`` is true or within
  ``own_quiet_s`` after it stops; never within ``refractory_s`` of the previous backchannel.
* **Speech frames.** A partner frame is speech when it is not silent and its intensity lies
  within ``speech_rel_db`` of the partner's running speech level (a running mean of its
  non-silent frames' dB): relative, so the partner's gain does not change a decision.
  F0 frames further than ``octave_st`` from the current run's median are pitch-tracking
  errors (octave jumps) and are ignored.

Motion (offsets on :data:`LISTENER_JOINTS`, rad for hinges, m for slides; 0 at rest)
    * **nod**: a down-up head nod (:func:`gesture_sim.signals.ruth.jog_goal` ``D`` split over
      neck and head), ``nod_rad`` in total (+-``nod_jitter``), starting ``react_s`` after the
      decision and peaking ``nod_attack_s`` later; with probability ``p_double`` a second, smaller
      cycle ``second_gap_s`` after the first peak (dropped if the listener starts to speak
      before it begins). Uninvited nods are ``uninvited_scale`` smaller.
      With probability ``p_brow`` the brows rise with it (AU1+2, ``brow_m``): kind ``nod+brow``.
    * **shift**: every ``shift_min_s``..``shift_max_s`` (uniform, seeded) of partner speech heard
      while listening, a slow lean/bend of the spine (``shift_bend_rad``, ``shift_flex_rad``)
      held ``shift_hold_min_s``..``shift_hold_max_s`` and released; released early when the
      listener starts to speak.
    * **attention**: while listening (not speaking, the partner heard within
      ``attend_hold_s``) a slight head tilt (``attend_tilt_rad``, side seeded) and forward lean
      (``attend_lean_rad``), ramped in over ``attend_on_s`` and out over ``attend_off_s``;
      with them the head comes up by ``attend_lift_rad`` (*Posture*, below).
    Every envelope is a raised cosine (:class:`gesture_sim.signals.ruth.Action`), so the
    offsets are smooth and the PD physics tracks them.

**Posture** (the rule's listener, :class:`ListenerSignals` with ``posture=True``, as
``make_listener`` builds it for the pipeline). The listening body plays the library's
rests, whose pose holds the head about 15 deg down against the body's facing (the shipped
library's rest pose: neck and head flexion 6.4 deg each, the spine 2 deg; BEAT2's speaker looks
down a little as he speaks). The face layer's eyes counter-rotate that pitch to keep the gaze on
the partner, so the listener looked up at its partner from under its lids with its head hanging
forward. A person who looks at someone at eye level holds the head about level (the natural
head position: the visual axis horizontal, Moorrees & Kean 1958; its flexion varies by a few
degrees, SD about 2-4 deg) and keeps the eyes near the middle of the orbit, turning the head
for the rest of a gaze shift (eye-head coordination). So while listening the head comes up by
``attend_lift_rad`` (ramped in and out with the attention) and the eyes counter-rotate the
listener's own head pitch (lean, lift, nods, posture shifts; ``vor_gain``) on
``left_eye_pitch`` / ``right_eye_pitch``, as :class:`gesture_sim.stages.FaceLayer` does for the
clip's and RUTH's pitch: the two add up on the eye joints. Audio-driven listeners
(:mod:`~gesture_sim.signals.listener_audio`) keep their own posture (the graph plays real
excerpts on the clip's pose).

Events ``(t, text)``: ``"backchannel nod"`` / ``"backchannel nod+brow"`` stamped at the nod's
reference peak (as :mod:`~gesture_sim.signals.ruth` stamps its batons), ``"shift"`` at the
shift's start. Times are seconds on the stream clock.

**Interest** (Okwechime 2011 ch. 5; :mod:`gesture_sim.signals.sdm`). ``interest=None`` (the
default) is the rule above, unchanged. With an ``interest`` in 0..1 the response probabilities
are scaled by :meth:`~gesture_sim.signals.sdm.ListenerTendencies.scale` (1 at 0.5; without
mined rules the thesis's Table 5.4 ratios: nods x1.7 and voiced backchannels x1.5 from
interest 0 to 1, gaze and smiles x1, posture activity x1.1):

* a backchannel at an opportunity: ``p_invited`` / ``p_other`` times the ``nod`` factor
  (clipped to 1: the interested listener's invited rate saturates at 1);
* a **voiced backchannel** ("mm-hm", the thesis's [V]) drawn at every opportunity, independently
  of the nod, with ``p_voiced`` (``p_voiced * p_other / p_invited`` uninvited) times the
  ``voiced`` factor; kinds ``nod+mm``, ``nod+brow+mm``, or ``mm`` alone (a small head dip,
  ``voiced_scale`` of a nod). It is silent: the listener layer has no jaw and no layer opens
  the mouth or makes a sound at the ``"backchannel ...mm"`` events;
* brows: ``p_brow`` times the ``brow`` factor; posture shifts: their gaps divided by the
  ``activity`` factor; the attentive tilt/lean (gaze at the speaker): times the
  ``gaze_partner`` factor (clipped to 0.5..1.5).

Those draws use their own seeded streams, so the nod decisions of a given seed stay aligned
across interest levels.

**The partner's laughs** (Okwechime's speaker [L] => listener [L]; the thesis finds it with a
large confidence for interested and not-interested listeners alike, §5.3.1). The partner's
samples, given to :meth:`ListenerSignals.push_audio` (the pipeline gives them to any listener
that has the method), run the causal laugh detector :mod:`gesture_sim.audio.laughter`; a laugh
(or :meth:`~ListenerBase.push_laugh` from another source) is known at its detection time plus
the given latency. At the first control step that knows it, unless the listener speaks (or did
within ``own_quiet_s``) or responded to a laugh within ``laugh_refractory_s``, the listener
**smiles** (``laugh_smile_scale`` of RUTH's smile from ``laugh_react_s`` on, event ``"laugh
smile"`` at its peak) and with ``p_laugh_back`` (times the dial's ``laugh`` factor, 1 without
mined rules: Table 5.4's [L] row) **laughs back**: ``laugh_bob_cycles`` small down-up head
bobs (``laugh_bob_rad``) at ``laugh_bob_hz`` and a slight forward lean of the trunk
(``laugh_lean_rad``), event ``"laugh back"`` at their start. The listener has no jaw or voice:
the laugh back is silent. These draws have their own seeded stream, so without a laugh every
output is bit for bit as before. :attr:`~ListenerBase.partner_laughs` and
:attr:`~ListenerBase.laugh_responses` keep the history.

``make_listener`` builds either this rule (``"rule"``) or the audio-driven listener of
:mod:`gesture_sim.signals.listener_audio` (``"okwechime"``), which has the same
:meth:`~ListenerSignals.step` interface.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from gesture_sim.contracts import PROSODY_FRAME_STEP
from gesture_sim.running import RunningStat
from gesture_sim.signals.ruth import SIGNAL_JOINTS, Action, RuthConfig, jog_goal, rise
from gesture_sim.units import semitones

__all__ = ["LISTENER_JOINTS", "LISTENER_MODELS", "Backchannel", "Cue", "ListenerConfig",
           "ListenerSignals"]

#: The joints the listener drives, in the order of :meth:`ListenerSignals.step`'s offsets.
LISTENER_JOINTS: tuple[str, ...] = (
    "neck_flex", "neck_bend", "neck_twist", "head_flex", "head_bend", "head_twist",
    "left_brow_raise", "right_brow_raise", "lower_spine_flex", "lower_spine_bend",
    "upper_spine_bend", "left_lip_corner_out", "left_lip_corner_up", "right_lip_corner_out",
    "right_lip_corner_up", "left_eye_pitch", "right_eye_pitch",
)
_J = {name: i for i, name in enumerate(LISTENER_JOINTS)}
#: The listener's joints that pitch its head (> 0 down), which its eyes counter-rotate.
_PITCH = np.array([_J["lower_spine_flex"], _J["neck_flex"], _J["head_flex"]])
_EYES = np.array([_J["left_eye_pitch"], _J["right_eye_pitch"]])
#: The listener models of ``make_listener``.
LISTENER_MODELS: tuple[str, ...] = ("rule", "okwechime")
_STEP = PROSODY_FRAME_STEP
_EPS = 1e-9


@dataclass(frozen=True)
class ListenerConfig:
    """Settings of the listener (s, dB, semitones "st", rad, m, probabilities).

    Attributes:
        speech_rel_db: a non-silent frame is speech when its intensity (dB) is at most this far
            below the partner's running speech level.
        level_tau_s: time constant (s of non-silent frames) of that running level.
        min_speech_s: speech (s, since the last pause) before a pause is an opportunity.
        pause_wait_s: silence (s) after the last speech frame before deciding; a silence this
            long also ends the speech run.
        final_s: the final stretch of voiced frames judged (s of voiced frames).
        final_lookback_s: how far (s) before the pause start the final stretch may lie.
        min_final_s: fewer voiced frames than this (s) in the lookback: no pitch evidence, the
            cue is not invited.
        low_pct: percentile of the partner's voiced F0 below which a frame is low (Ward: 26).
        low_region_s: low frames (s) in the final stretch that make it a low-pitch region
            (Ward: 110 ms).
        end_s: the phrase-end level is the mean F0 (st) of the last ``end_s`` (s) of voiced
            frames.
        fall_st: final lowering: the end level lies at least this far (st) below the highest
            point of the lookback (5-frame running median) and below the partner's median.
        rise_st: a rising end: the end level lies at least this far (st) above the lowest point
            of the lookback (5-frame running median).
        octave_st: F0 frames further than this (st) from the run's median are ignored.
        history_s: the partner's voiced F0 kept for the percentiles (s of voiced frames).
        p_invited, p_other: probability of a backchannel at an invited / other opportunity.
        refractory_s: minimum time (s) between two backchannel decisions.
        own_quiet_s: no backchannel until this long (s) after the listener's own speech.
        react_s: delay (s) from the decision to the nod's start.
        nod_rad: total nod (rad) over neck and head; neck_share: the neck's share of it.
        nod_jitter: seeded relative variation of a nod's size (+-).
        nod_attack_s, nod_decay_s: the nod's raised-cosine down and up times (s).
        p_double: probability of a second cycle; second_scale: its size (of the first);
            second_gap_s: peak-to-peak time (s) of the two cycles.
        uninvited_scale: size of a nod at an uninvited opportunity (of a full nod).
        p_brow: probability that a nod comes with a brow raise; brow_m: the raise (m);
            brow_hold_s, brow_decay_s: held after the nod's peak, then released (s).
        shift_min_s, shift_max_s: partner speech heard (s) between two posture shifts.
        shift_bend_rad: largest lateral bend of a shift (rad, over lower and upper spine);
            shift_flex_rad: largest fore/aft lean of a shift (rad, lower spine).
        shift_attack_s, shift_decay_s: the shift's ramps (s); shift_hold_min_s,
            shift_hold_max_s: its hold (s, uniform).
        attend_tilt_rad, attend_lean_rad: the attentive head tilt (rad, neck and head roll)
            and forward lean (rad, lower spine flexion).
        attend_on_s, attend_off_s: their raised-cosine ramps in and out (s).
        attend_hold_s: partner silence (s) after which attention relaxes.
        attend_lift_rad: while listening the head comes up by this much (rad over neck and
            head, a ``U`` jog split like the nods), ramped in and out with the attention: the
            library's rest pose holds the head about 15 deg down (BEAT2's speaker), and a
            listener looking at a partner at eye level holds it about level (module docstring,
            *Posture*).
        vor_gain: the eyes counter-rotate the listener's own head pitch (lean, lift, nods,
            posture shifts) by this gain, so the gaze stays on the partner
            (:data:`gesture_sim.stages.VOR_GAIN`, the same reflex for the clip's and RUTH's).
        p_voiced: probability of a voiced backchannel at an invited opportunity (used only
            with an ``interest``; an assumed base: the thesis gives ratios, not rates).
        voiced_scale: size of the head dip of a voiced backchannel without a nod (of a nod).
        p_smile: probability that a backchannel comes with a smile (Okwechime's listener
            *smile* signal; an assumed base: the thesis gives no smile rate, and Table 5.4 no
            interest ratio for it); smile_scale: its size (of RUTH's full smile);
            smile_attack_s, smile_hold_s, smile_decay_s: its envelope (s).
        laugh_react_s: delay (s) from hearing the partner's laugh (its detection, known) to
            the listener's smile.
        laugh_smile_scale: size of the smile at a partner's laugh (of RUTH's full smile);
            laugh_smile_attack_s, laugh_smile_hold_s, laugh_smile_decay_s: its envelope (s).
        p_laugh_back: probability that the listener also laughs back (Okwechime's speaker
            [L] => listener [L]; an assumed base, times the dial's ``laugh`` factor).
        laugh_bob_rad: each laugh-back bob of the head (rad over neck and head, down-up);
            laugh_bob_hz: bobs per second; laugh_bob_cycles: how many; laugh_lean_rad: the
            trunk's forward lean under them (rad, lower spine), held over the bobs.
        laugh_refractory_s: a partner laugh detected within this (s) of the previous response
            gets none (a continuing bout is one laugh anyway).
    """

    speech_rel_db: float = 25.0
    level_tau_s: float = 5.0
    min_speech_s: float = 0.8
    pause_wait_s: float = 0.25
    final_s: float = 0.2
    final_lookback_s: float = 0.5
    min_final_s: float = 0.06
    low_pct: float = 28.0
    low_region_s: float = 0.11
    end_s: float = 0.05
    fall_st: float = 2.0
    rise_st: float = 2.0
    octave_st: float = 8.0
    history_s: float = 60.0
    p_invited: float = 0.9
    p_other: float = 0.05
    refractory_s: float = 1.6
    own_quiet_s: float = 0.5
    react_s: float = 0.08
    nod_rad: float = math.radians(8.0)
    neck_share: float = 0.4
    nod_jitter: float = 0.2
    nod_attack_s: float = 0.22
    nod_decay_s: float = 0.28
    p_double: float = 0.4
    second_scale: float = 0.55
    second_gap_s: float = 0.42
    uninvited_scale: float = 0.6
    p_brow: float = 0.35
    brow_m: float = 0.006
    brow_hold_s: float = 0.12
    brow_decay_s: float = 0.35
    shift_min_s: float = 8.0
    shift_max_s: float = 20.0
    shift_bend_rad: float = math.radians(3.0)
    shift_flex_rad: float = math.radians(1.5)
    shift_attack_s: float = 1.2
    shift_decay_s: float = 1.5
    shift_hold_min_s: float = 2.0
    shift_hold_max_s: float = 5.0
    attend_tilt_rad: float = math.radians(3.0)
    attend_lean_rad: float = math.radians(2.0)
    attend_on_s: float = 1.2
    attend_off_s: float = 0.8
    attend_hold_s: float = 4.0
    attend_lift_rad: float = math.radians(14.0)
    vor_gain: float = 0.9
    p_voiced: float = 0.3
    p_smile: float = 0.3
    smile_scale: float = 0.6
    smile_attack_s: float = 0.35
    smile_hold_s: float = 1.2
    smile_decay_s: float = 0.6
    voiced_scale: float = 0.35
    laugh_react_s: float = 0.15
    laugh_smile_scale: float = 0.9
    laugh_smile_attack_s: float = 0.3
    laugh_smile_hold_s: float = 1.5
    laugh_smile_decay_s: float = 0.8
    p_laugh_back: float = 0.5
    laugh_bob_rad: float = math.radians(2.5)
    laugh_bob_hz: float = 4.5
    laugh_bob_cycles: int = 3
    laugh_lean_rad: float = math.radians(1.5)
    laugh_refractory_s: float = 2.0


@dataclass(frozen=True)
class Backchannel:
    """One backchannel.

    Attributes:
        t_cue: the partner's pause start (end of its last speech frame), s.
        t_emitted: when the listener decided (>= t_cue + ``pause_wait_s``), s.
        t_peak: when the nod's reference reaches its (first) peak, s.
        kind: ``"nod"`` or ``"nod+brow"``; with an interest also ``"nod+mm"``,
            ``"nod+brow+mm"`` or ``"mm"`` (a voiced backchannel).
        invited: whether the cue was a low/falling phrase end (the rule).
    """

    t_cue: float
    t_emitted: float
    t_peak: float
    kind: str
    invited: bool


@dataclass(frozen=True)
class Cue:
    """One backchannel opportunity (a pause after enough speech), taken or not.

    Attributes:
        t_cue: pause start (s); t_decided: the control step that judged it (s).
        speech_s: the partner's speech before the pause (s).
        low, falling, rising: the intonation tests (module docstring); invited: their verdict.
        taken: whether a backchannel followed; blocked: why not although drawn
            (``"own speech"``, ``"refractory"``) or ``""``.
    """

    t_cue: float
    t_decided: float
    speech_s: float
    low: bool
    falling: bool
    rising: bool
    invited: bool
    taken: bool
    blocked: str = ""


def _from_signal_joints(g: np.ndarray) -> np.ndarray:
    """Offsets on :data:`SIGNAL_JOINTS` (shape (11,)) -> :data:`LISTENER_JOINTS` (shared
    joints only)."""
    out = np.zeros(len(LISTENER_JOINTS))
    for i, name in enumerate(SIGNAL_JOINTS):
        if name in _J:
            out[_J[name]] = g[i]
    return out


def _median5(x: np.ndarray) -> np.ndarray:
    """5-point running median (edges shrink), shape as ``x``."""
    n = len(x)
    return np.array([np.median(x[max(i - 2, 0): i + 3]) for i in range(n)]) if n else x


class ListenerBase:
    """What both listeners share: their settings, seed and interest dial, and the unit
    motions (a 1 rad nod over neck and head, a 1 rad J tilt, the brow raise) on
    :data:`LISTENER_JOINTS`. :attr:`NEUTRAL_SCALE` is a listener's response scales without
    an interest."""

    NEUTRAL_SCALE: dict[str, float] = {"nod": 1.0, "brow": 1.0, "voiced": 0.0,
                                       "activity": 1.0, "gaze_partner": 1.0, "smile": 1.0}

    def _setup(self, config: ListenerConfig | None, seed: int, interest: float | None,
               tendencies) -> None:
        self.cfg = config or ListenerConfig()
        self.seed = int(seed)
        self.tendencies = tendencies
        self.set_interest(interest)
        c = self.cfg
        rc = RuthConfig(pitch_rad=1.0, roll_rad=1.0, neck_share=c.neck_share)
        self._nod_unit = _from_signal_joints(jog_goal("D", rc))          # 1 rad in total
        self._tilt_unit = _from_signal_joints(jog_goal("J", rc))         # 1 rad roll, J side
        self._brow = np.zeros(len(LISTENER_JOINTS))
        self._brow[_J["left_brow_raise"]] = self._brow[_J["right_brow_raise"]] = c.brow_m

    # ------------------------------------------------------------------ partner laughs
    def _reset_laugh(self, stream: int) -> None:
        """A new stream for the laugh response (its own seeded draws: ``stream``)."""
        from gesture_sim.audio.laughter import LaughterDetector

        self.laughter = LaughterDetector()
        self._rng_laugh = np.random.default_rng([self.seed, stream])
        self._laugh_seen = 0
        self._laugh_pending: deque[tuple[float, float, float]] = deque()  # (known, start, end)
        self._laugh_last = -math.inf
        #: the partner's laughs heard, ``(t_known, start, end)`` (s), and the responses
        #: ``(t, "smile" | "smile+laugh" | "blocked ...")``.
        self.partner_laughs: list[tuple[float, float, float]] = []
        self.laugh_responses: list[tuple[float, str]] = []

    def _hear_laughs(self, samples: np.ndarray, latency_s: float) -> None:
        """Run the laugh detector on the partner's next samples; new laughs become known
        ``latency_s`` after their detection."""
        self.laughter.push(samples)
        laughs = self.laughter.laughs
        for lg in laughs[self._laugh_seen:]:
            self.push_laugh(lg.t_detected + latency_s, lg.start, lg.end)
        self._laugh_seen = len(laughs)

    def push_laugh(self, t_known: float, start: float | None = None,
                   end: float | None = None) -> None:
        """The partner laughed (``start``..``end`` s, default ``t_known``), known at
        ``t_known`` (s): the listener responds at the first step at or after it. The audio
        path (:meth:`push_audio`) calls this; another source of the laugh signal (annotations,
        a face detector) may too."""
        a = float(t_known if start is None else start)
        b = float(t_known if end is None else end)
        self._laugh_pending.append((float(t_known), a, b))

    def _laugh_step(self, t: float, own: bool) -> None:
        """Respond to the partner's laughs known by ``t``: a smile, and with ``p_laugh_back``
        (times the dial's ``laugh`` factor) a laugh back: smile + head bobs + a trunk lean."""
        c = self.cfg
        while self._laugh_pending and self._laugh_pending[0][0] <= t + _EPS:
            known, a, b = self._laugh_pending.popleft()
            self.partner_laughs.append((known, a, b))
            if own or t - self._own_last < c.own_quiet_s - _EPS:
                self.laugh_responses.append((round(t, 4), "blocked own speech"))
                continue
            if t - self._laugh_last < c.laugh_refractory_s - _EPS:
                self.laugh_responses.append((round(t, 4), "blocked refractory"))
                continue
            self._laugh_last = t
            u = float(self._rng_laugh.random())
            back = u < min(c.p_laugh_back * self._scale.get("laugh", 1.0), 1.0)
            from gesture_sim.signals.ruth import smile_goal

            s1 = t + c.laugh_react_s
            peak = s1 + c.laugh_smile_attack_s
            self._actions.append(Action("underliner", "S", _from_signal_joints(smile_goal()),
                                        c.laugh_smile_scale, s1, peak,
                                        peak + c.laugh_smile_hold_s, c.laugh_smile_decay_s))
            self._emit(peak, "laugh smile")
            kind = "smile"
            if back:
                kind = "smile+laugh"
                period = 1.0 / max(c.laugh_bob_hz, 1e-6)
                goal = c.laugh_bob_rad * self._nod_unit
                for i in range(max(int(c.laugh_bob_cycles), 1)):
                    b0 = s1 + i * period
                    self._actions.append(Action("baton", "D*", goal, 1.0, b0,
                                                b0 + 0.45 * period, b0 + 0.45 * period,
                                                0.55 * period))
                lean = np.zeros(len(LISTENER_JOINTS))
                lean[_J["lower_spine_flex"]] = c.laugh_lean_rad
                n_s = max(int(c.laugh_bob_cycles), 1) * period
                self._actions.append(Action("underliner", "lean", lean, 1.0, s1,
                                            s1 + 0.5 * n_s, s1 + n_s, 0.6))
                self._emit(s1, "laugh back")
            self.laugh_responses.append((round(t, 4), kind))

    def _motion(self, t: float, dt: float, listening: bool, attention_gain: float = 1.0
                ) -> tuple[np.ndarray, list[tuple[float, str]]]:
        """The step's offsets on :data:`LISTENER_JOINTS`: the attentive tilt and lean ramped
        in while ``listening`` (times ``attention_gain``), plus the running actions (nods,
        brows, smiles) and the posture shift; and the step's events (logged)."""
        c = self.cfg
        if listening:
            self._attend_x = min(self._attend_x + dt / max(c.attend_on_s, 1e-6), 1.0)
        else:
            self._attend_x = max(self._attend_x - dt / max(c.attend_off_s, 1e-6), 0.0)
        out = rise(self._attend_x) * self._attend_goal
        if attention_gain != 1.0:
            out = out * attention_gain
        self._actions = [a for a in self._actions if t < a.end]
        for a in self._actions:
            out = out + a.value(t)
        if self._shift is not None:
            if t >= self._shift.end:
                self._shift = None
            else:
                out = out + self._shift.value(t)
        self.events.extend(self._new)
        return out, self._new

    def set_interest(self, interest: float | None) -> None:
        """Set the interest (None: no scaling; else clipped to 0..1), live."""
        self.interest = None if interest is None else min(max(float(interest), 0.0), 1.0)
        if self.interest is None:
            self._scale = dict(self.NEUTRAL_SCALE)
            return
        if self.tendencies is None:
            from gesture_sim.signals.sdm import ListenerTendencies

            self.tendencies = ListenerTendencies.from_thesis()
        self._scale = dict(self.tendencies.scale(self.interest))


class ListenerSignals(ListenerBase):
    """The causal listener (see the module docstring).

    Args:
        config: :class:`ListenerConfig`. seed: seeds the decisions, nod variants and shifts.
        interest: None (the rule unchanged) or 0..1 (module docstring; :meth:`set_interest`
            changes it live).
        tendencies: the interest tables (:class:`~gesture_sim.signals.sdm.
            ListenerTendencies`; default: Table 5.4 around the rule's base rates).
        posture: also hold the listening posture (module docstring, *Posture*: the head lift
            and the eyes' counter-rotation, on ``left_eye_pitch`` / ``right_eye_pitch``);
            False: the backchannels' offsets alone, 0 on the eyes. ``make_listener`` (so
            the pipeline's listener) turns it on.

    Feed the partner's prosody frames with :meth:`push_frames` as they become known and call
    :meth:`step` once per control step; :attr:`backchannels` and :attr:`cues` keep the history,
    :attr:`events` every event.
    """

    def __init__(self, config: ListenerConfig | None = None, seed: int = 0,
                 interest: float | None = None, tendencies=None, posture: bool = False) -> None:
        self._setup(config, seed, interest, tendencies)
        self.posture = bool(posture)
        self.reset()

    def reset(self) -> None:
        """A new stream at t = 0."""
        c = self.cfg
        self._rng = np.random.default_rng([self.seed, 0])        # backchannel decisions
        self._rng_shift = np.random.default_rng([self.seed, 1])  # posture shifts
        self._rng_voiced = np.random.default_rng([self.seed, 2])  # voiced backchannels
        self._rng_smile = np.random.default_rng([self.seed, 3])   # smiles
        self.backchannels: list[Backchannel] = []
        self.cues: list[Cue] = []
        self.events: list[tuple[float, str]] = []
        self._new: list[tuple[float, str]] = []
        self._frames: deque[tuple[float, float, float, bool, float]] = deque()
        # the partner's speech level (dB): an exponential average with time constant
        # level_tau_s (a cumulative mean at first) over its non-silent frames
        self._level = RunningStat(min_weight=_STEP / max(c.level_tau_s, _STEP),
                                  location="first")
        self._hist: deque[float] = deque(maxlen=max(int(round(c.history_s / _STEP)), 10))
        self._run_start = -math.inf
        self._run_voiced: list[tuple[float, float]] = []
        self._last_speech_end = -math.inf
        self._cue_done = True
        self._last_bc = -math.inf
        self._own_last = -math.inf
        self._own_now = False
        self._actions: list[Action] = []
        self._shift: Action | None = None
        self._speech_acc = 0.0
        self._next_shift = self._draw_shift_gap()
        side = 1.0 if self._rng_shift.random() < 0.5 else -1.0
        self._attend_goal = side * c.attend_tilt_rad * self._tilt_unit
        self._attend_goal[_J["lower_spine_flex"]] += c.attend_lean_rad
        self._attend_x = 0.0
        self._t_last: float | None = None
        self._reset_laugh(4)

    # ------------------------------------------------------------------ inputs
    def push_audio(self, samples: np.ndarray, latency_s: float = 0.0) -> None:
        """The partner's next samples (float, 16 kHz, contiguous from t = 0): only for its
        laughs (:mod:`gesture_sim.audio.laughter`; the backchannels read :meth:`push_frames`).
        A laugh is known ``latency_s`` after its detection."""
        self._hear_laughs(samples, latency_s)

    def push_frames(self, times: np.ndarray, intensity_db: np.ndarray, silent: np.ndarray,
                    t_known: np.ndarray, f0_hz: np.ndarray | None = None) -> None:
        """The partner's prosody frames (each (n,), 100 Hz): centre times (s), intensity (dB),
        silent flags, the stream time each became known (s) and F0 (Hz, NaN/0 unvoiced;
        ``None``: no pitch, so no cue is invited). Used once ``t_known <= t`` (causal)."""
        n = len(np.asarray(times))
        f0 = np.full(n, np.nan) if f0_hz is None else np.asarray(f0_hz, float)
        self._frames.extend(zip(np.asarray(t_known, float).tolist(),
                                np.asarray(times, float).tolist(),
                                np.asarray(intensity_db, float).tolist(),
                                np.asarray(silent, bool).tolist(), f0.tolist(), strict=True))

    # ------------------------------------------------------------------ step
    def step(self, t: float, own_speaking: bool) -> tuple[np.ndarray, list[tuple[float, str]]]:
        """Advance to control step ``t`` (s).

        Args:
            own_speaking: whether the listener itself is speaking (as known at ``t``).

        Returns:
            (offsets (len(LISTENER_JOINTS),) rad/m, the events ``(t, text)`` of this step).
        """
        c = self.cfg
        self._new = []
        dt = 0.0 if self._t_last is None else min(max(t - self._t_last, 0.0), 0.25)
        self._t_last = t
        self._own_now = bool(own_speaking)
        if own_speaking:
            self._own_last = t
            if self._shift is not None:
                self._shift.close(t, c.shift_decay_s)
            self._actions = [a for a in self._actions if a.start <= t]  # no second cycle
        while self._frames and self._frames[0][0] <= t + _EPS:
            _, tc, i_db, silent, f0 = self._frames.popleft()
            self._absorb(t, tc, i_db, silent, f0)
        self._maybe_shift(t)
        self._laugh_step(t, bool(own_speaking))
        listening = (not own_speaking) and self._last_speech_end >= t - c.attend_hold_s
        gain = (min(max(self._scale["gaze_partner"], 0.5), 1.5) if self.interest is not None
                else 1.0)
        out, events = self._motion(t, dt, listening, gain)
        return (self._posture(out) if self.posture else out), events

    def _posture(self, out: np.ndarray) -> np.ndarray:
        """The head lift of a listener looking at its partner (ramped with the attention) and
        the eyes counter-rotating the listener's own head pitch (module docstring, *Posture*)."""
        c = self.cfg
        if c.attend_lift_rad:
            out = out - (rise(self._attend_x) * c.attend_lift_rad) * self._nod_unit
        if c.vor_gain:
            out[_EYES] = -c.vor_gain * float(out[_PITCH].sum())
        return out

    # ------------------------------------------------------------------ frames
    def _absorb(self, t: float, tc: float, i_db: float, silent: bool, f0: float) -> None:
        """One partner frame (centre ``tc``), absorbed at control step ``t``."""
        c = self.cfg
        start, end = tc - 0.5 * _STEP, tc + 0.5 * _STEP
        speech = False
        if not silent and math.isfinite(i_db):
            self._level.update(i_db)
            speech = i_db >= self._level.mean - c.speech_rel_db
        if speech:
            if start - self._last_speech_end >= c.pause_wait_s - _EPS:
                self._run_start = start
                self._run_voiced = []
            self._last_speech_end = end
            self._cue_done = False
            if not self._own_now:
                self._speech_acc += _STEP
            if math.isfinite(f0) and f0 > 0:
                st = semitones(f0, 100.0)
                self._run_voiced.append((tc, st))
                self._hist.append(st)
                if len(self._run_voiced) > 2000:
                    del self._run_voiced[:1000]
            return
        if (not self._cue_done and end - self._last_speech_end >= c.pause_wait_s - _EPS):
            self._cue_done = True
            speech_s = self._last_speech_end - self._run_start
            if speech_s >= c.min_speech_s - _EPS:
                self._opportunity(t, self._last_speech_end, speech_s)

    def _intonation(self, t_cue: float) -> tuple[bool, bool, bool]:
        """(low, falling, rising) of the phrase end before the pause at ``t_cue``."""
        c = self.cfg
        if len(self._run_voiced) < 3 or len(self._hist) < 3:
            return False, False, False
        run = np.asarray(self._run_voiced)
        tv, st = run[:, 0], run[:, 1]
        keep = np.abs(st - np.median(st)) <= c.octave_st
        tv, st = tv[keep], st[keep]
        look = tv >= t_cue - c.final_lookback_s
        if np.count_nonzero(look) * _STEP < c.min_final_s - _EPS:
            return False, False, False
        hist = np.asarray(self._hist)
        thr_low, med = np.percentile(hist, [c.low_pct, 50.0])
        t_last = tv[look][-1]
        fin = look & (tv > t_last - c.final_s + _EPS)
        fin_st = st[fin]
        low = np.count_nonzero(fin_st < thr_low) * _STEP >= c.low_region_s - _EPS
        smooth = _median5(st[look])
        end = float(st[look & (tv > t_last - c.end_s + _EPS)].mean())
        falling = bool(end <= smooth.max() - c.fall_st and end < med)
        rising = bool(end >= smooth.min() + c.rise_st)
        return bool(low), falling, rising

    def _opportunity(self, t: float, t_cue: float, speech_s: float) -> None:
        """Judge the pause that began at ``t_cue`` at control step ``t``."""
        c = self.cfg
        low, falling, rising = self._intonation(t_cue)
        invited = (low or falling) and not rising
        u, u_brow, u_double, u_size = self._rng.random(4)  # drawn for every opportunity
        sc = self._scale
        p_nod = c.p_invited if invited else c.p_other
        if self.interest is not None:
            p_nod = min(p_nod * sc["nod"], 1.0)
        nod = bool(u < p_nod)
        voiced = False
        if self.interest is not None:
            p_v = c.p_voiced * (1.0 if invited else c.p_other / max(c.p_invited, _EPS))
            voiced = bool(self._rng_voiced.random() < min(p_v * sc["voiced"], 1.0))
        drawn = nod or voiced
        blocked = ""
        if drawn and (self._own_now or t - self._own_last < c.own_quiet_s - _EPS):
            blocked = "own speech"
        elif drawn and t - self._last_bc < c.refractory_s - _EPS:
            blocked = "refractory"
        taken = drawn and not blocked
        self.cues.append(Cue(t_cue, t, speech_s, low, falling, rising, invited, taken, blocked))
        if not taken:
            return
        self._last_bc = t
        size = c.nod_rad * (1.0 + c.nod_jitter * (2.0 * u_size - 1.0))
        if not invited:
            size *= c.uninvited_scale
        if not nod:                       # a voiced backchannel alone: a small head dip
            size *= c.voiced_scale
        goal = size * self._nod_unit
        s1 = t + c.react_s
        p1 = s1 + c.nod_attack_s
        self._actions.append(Action("baton", "D*", goal, 1.0, s1, p1, p1, c.nod_decay_s))
        if nod and u_double < c.p_double:
            p2 = p1 + c.second_gap_s
            self._actions.append(Action("baton", "D*", goal, c.second_scale,
                                        p2 - c.nod_attack_s, p2, p2, c.nod_decay_s))
        kind = "nod" if nod else ""
        if nod and u_brow < c.p_brow * sc["brow"]:
            kind = "nod+brow"
            self._actions.append(Action("baton", "1+2*", self._brow, 1.0, s1, p1,
                                        p1 + c.brow_hold_s, c.brow_decay_s))
        if voiced:
            kind = f"{kind}+mm" if kind else "mm"
        self.backchannels.append(Backchannel(t_cue, t, p1, kind, invited))
        self._emit(p1, f"backchannel {kind}")
        if self._rng_smile.random() < c.p_smile * sc.get("smile", 1.0):
            from gesture_sim.signals.ruth import smile_goal

            peak = s1 + c.smile_attack_s
            self._actions.append(Action("underliner", "S", _from_signal_joints(smile_goal()),
                                        c.smile_scale, s1, peak, peak + c.smile_hold_s,
                                        c.smile_decay_s))
            self._emit(peak, "smile S")

    # ------------------------------------------------------------------ shifts
    def _draw_shift_gap(self) -> float:
        c = self.cfg
        return float(self._rng_shift.uniform(c.shift_min_s, max(c.shift_max_s, c.shift_min_s)))

    def _maybe_shift(self, t: float) -> None:
        c = self.cfg
        if (self._speech_acc < self._next_shift / self._scale["activity"]
                or self._shift is not None or self._own_now
                or t - self._own_last < c.own_quiet_s):
            return
        r = self._rng_shift
        side = 1.0 if r.random() < 0.5 else -1.0
        bend = side * c.shift_bend_rad * float(r.uniform(0.5, 1.0))
        goal = np.zeros(len(LISTENER_JOINTS))
        goal[_J["lower_spine_bend"]] = 0.6 * bend
        goal[_J["upper_spine_bend"]] = 0.4 * bend
        goal[_J["lower_spine_flex"]] = c.shift_flex_rad * float(r.uniform(-1.0, 1.0))
        hold = float(r.uniform(c.shift_hold_min_s, max(c.shift_hold_max_s, c.shift_hold_min_s)))
        peak = t + c.shift_attack_s
        self._shift = Action("underliner", "shift", goal, 1.0, t, peak, peak + hold,
                             c.shift_decay_s)
        self._speech_acc = 0.0
        self._next_shift = self._draw_shift_gap()
        self._emit(t, "shift")

    def _emit(self, t: float, text: str) -> None:
        self._new.append((round(float(t), 4), text))
