"""The one causal pipeline used by ``render`` and ``live`` (docs/DESIGN.md §1, §4).

    audio blocks -> speech state (prosody syllables, accents, boundaries, energy)
    -> one view per control step -> motion stage (belief filter + control layer [+ timing
    layer]) -> layer stages (face, listener) -> joint targets q*(t) -> PD-tracked MuJoCo physics

This module has one job: run the control steps. :meth:`GesturePipeline.push_audio` consumes a
block and runs every control step (one per library frame, default 30 Hz) whose time the audio has
reached; step t takes one :class:`~gesture_sim.audio.speech.Heard` view (what was emitted at or
before t) and passes it through the stages of :mod:`gesture_sim.stages`, built for the method by
the registry :mod:`gesture_sim.methods`. Each step's target is pushed into a rolling target
stream; :meth:`GesturePipeline.advance` steps the physics up to a stream time along it
(interpolated between control steps, held at the latest one when the physics runs ahead). The
feed loops (a file, samples, a conversation; :mod:`gesture_sim.feed`) and the live viewer drive
the same methods.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gesture_sim.audio.speech import FrameReader, Heard, SpeechState
from gesture_sim.contracts import AudioBlock
from gesture_sim.control.style import clip_style
from gesture_sim.errors import GestureSimError
from gesture_sim.methods import (
    DEFAULT_BLEND_FRAMES,
    DEFAULT_REPEAT_COST,
    DEFAULT_REPEAT_TAU_S,
    DEFAULT_TEMPERATURE,
    METHODS,
    Parts,
    method_spec,
)
from gesture_sim.runlog import PipelineLog, PipelineStatus
from gesture_sim.stages import (
    DEFAULT_LEGS,
    LEG_MODES,
    FaceLayer,
    LayerStage,
    Legs,
    ListenerLayer,
    Motion,
    MotionStage,
    MouthLayer,
    StageCost,
)

__all__ = ["DEFAULT_LEGS", "DEFAULT_TEMPERATURE", "LEG_MODES", "LIVE_LOG_S", "METHODS",
           "GesturePipeline", "PipelineLog", "PipelineStatus"]

#: How late a live mouth shows the recognised phones (s): about the phone recogniser's median
#: latency (``tools/phone_sources.py``), so that each phone's shape is shown whole.
LIVE_PHONE_LAG_S = 0.15
#: Seconds of step log a pipeline without ``record`` keeps (the live loop).
LIVE_LOG_S = 30.0

#: Tolerance (s) of a step time against the audio time.
_EPS = 1e-9


class GesturePipeline:
    """Speech in, a PD-tracked humanoid out, causally (see the module docstring).

    Args:
        library: a :class:`~gesture_sim.motion.library.MotionLibrary`.
        model: a :class:`~gesture_sim.inference.model.GestureModel`.
        policy: the controller :class:`~gesture_sim.control.policy.Policy` for that pair.
        method: one of :data:`~gesture_sim.methods.METHODS` (the registry).
        seed: seeds the physics' initial noise and the methods' random choices.
        style: the style dial in [0, 1] (0 calm, 0.5 neutral, 1 energetic).
        physics: simulate the humanoid (False: targets only, for fast evaluation).
        p_interrupt: interruption probability of the random baselines.
        temperature: the controller's softmin temperature (cost units; 0 = the paper's argmin;
            see :class:`~gesture_sim.control.controller.GestureController`).
        repeat_cost, repeat_tau_s: its novelty term (cost units, s): entering a segment played
            ``age`` s ago costs ``repeat_cost * exp(-age / repeat_tau_s)``
            (:data:`~gesture_sim.methods.DEFAULT_REPEAT_COST`; 0: the paper's MDP alone).
            sample_state: which segment to enter is chosen for one hidden state drawn from the
            belief (posterior sampling) rather than on the expected values.
        blend_frames: control steps over which a segment switch ramps from the last target
            (default :data:`~gesture_sim.control.ramp.DEFAULT_BLEND_FRAMES` = 15, 0.5 s at
            30 Hz, from the pose carried on by its velocity; 6 until stop 44, chosen then for
            foot skating and hand-speed peaks; docs/history.md, "switch ramp";
            0 = the raw jump).
        transition: how the timing layer crosses a switch, one of
            :data:`~gesture_sim.methods.TRANSITIONS` (``"ramp"``, default; ``"gpdm"``: Chiu
            2014's GPDM transitions, offline).
        stand: the older name of the leg mode: True ``legs="stand"`` (the legs track the
            standing pose), False ``legs="free"``; not given, :data:`DEFAULT_LEGS`.
        legs: one of :data:`LEG_MODES` (default :data:`DEFAULT_LEGS`, ``"clip"``: the clip's
            weight shifts over planted feet); given, it takes precedence over ``stand``.
        record: keep the whole :class:`~gesture_sim.sim.trace.SimTrace` and log of the run (False
            for the live loop: no trace, and the log keeps only its last :data:`LIVE_LOG_S`
            seconds, so memory stays flat over a long run).
        control_library: the library's :class:`~gesture_sim.control.inputs.ControlLibrary`
            (built from ``library`` when not given).
        sync: the timing layer's :class:`~gesture_sim.control.synchrony.SyncSettings`;
            accents: the accent detector's :class:`~gesture_sim.audio.accents.AccentConfig`;
            graph: a built MIMiC graph (``mimic``).
        signals: face and head signals after RUTH (:mod:`gesture_sim.signals.ruth`: nods,
            brows, blinks, jaw) added onto the clip's target through a layer stage; False keeps
            the clip's face and head as they are (the ``random`` method hears nothing: none).
        signals_file: a ``--signals`` markup file of timed labels that drive or override them.
        listener: also listen to a partner (a conversation, Okwechime 2011): the partner's
            audio, given by :meth:`push_partner_audio` (or a partner pipeline's voice, see
            :meth:`listen_to`), drives backchannels — nods, brow raises, posture shifts
            (:mod:`gesture_sim.signals.listener`) — through a second layer stage, never while
            this person speaks.
        phones: timed phones of the speech (:class:`~gesture_sim.audio.phones.Phone`, known in
            advance: a TextGrid's phone tier, a transcript aligned to the audio), or
            ``"recognise"``: phones recognised from the audio as it comes (live; shown
            :data:`LIVE_PHONE_LAG_S` late): the lips and jaw form them (visemes,
            :class:`~gesture_sim.stages.MouthLayer`); None: the jaw opens with the loudness
            (RUTH's degraded mode).
        listener_model: the listener (``listener``): ``"rule"`` (Ward & Tsukahara's pitch rule)
            or ``"okwechime"`` (Okwechime 2011's audio-driven listener: MFCC classes of the
            partner's voice -> listener states; :func:`~gesture_sim.signals.listener.
            make_listener`). interest: the listener's interest in 0..1 (Okwechime's interested
            vs not-interested listener, :mod:`gesture_sim.signals.sdm`; None: the rule's own
            rates); listener_tendencies: the interest tables (default: Table 5.4's ratios).
        listener_motion: the ``"okwechime"`` listener's motion: ``"graph"`` (real rests, nods
            and posture shifts of this library's frames,
            :func:`~gesture_sim.signals.listener_graph.listener_graph_for`), ``"envelope"``
            (the rule's envelopes) or None (the graph when the library has every state).
        finger_tracks: the library clips' finger motion (clip index -> (T, 40) rad,
            :mod:`gesture_sim.motion.finger_tracks`; :meth:`create` loads it beside the
            library): the hand layer plays it while its clip plays.
        look: the body the model draws (:data:`gesture_sim.sim.looks.LOOKS`; a viewer shows
            it; the physics is the same in every look).
        words: timed words of the speech known in advance (``(start_s, end_s, text)`` or
            :class:`~gesture_sim.audio.phones.Word`; a transcript), for a method that reads
            them (``chiu14``, which reveals each only once it has been said); live: None.
        sign_model: ``chiu14``'s :class:`~gesture_sim.inference.sign_model.SignModel` or its
            folder (None: the shipped one).
        body: the physical body (:func:`gesture_sim.sim.bodies.resolve_body`: ``"humanoid"``,
            default; ``"g1"``, ``"h1"``, a robot map file, or a ``BodySpec``). On a robot every
            stage runs as for the humanoid; each step's humanoid target is then mapped onto the
            robot before it enters the target stream (the library's frames as built once on
            the robot where the step plays one unchanged, else inverse kinematics:
            :class:`~gesture_sim.sim.robot_ik.RobotTargets`), and the physics is
            :class:`~gesture_sim.sim.robot.RobotSim`. The log keeps the humanoid's targets.
    """

    def __init__(self, library, model, policy, *, method: str = "controller", seed: int = 0,
                 style: float = 0.5, physics: bool = True, p_interrupt: float = 0.1,
                 control_library=None, record: bool = True, stand: bool | None = None,
                 legs: str | None = None,
                 blend_frames: int = DEFAULT_BLEND_FRAMES, transition: str = "ramp",
                 temperature: float = DEFAULT_TEMPERATURE,
                 repeat_cost: float = DEFAULT_REPEAT_COST,
                 repeat_tau_s: float = DEFAULT_REPEAT_TAU_S, sample_state: bool = False,
                 sync=None, accents=None, graph=None, signals: bool = True,
                 signals_file: str | Path | None = None, listener: bool = False,
                 look: str = "human", phones=None, listener_model: str = "rule",
                 interest: float | None = None, listener_tendencies=None,
                 listener_motion: str | None = None, finger_tracks: dict | None = None,
                 words=None, sign_model=None, body=None) -> None:
        from gesture_sim.control.inputs import ControlLibrary
        from gesture_sim.sim.layers import TargetLayers
        from gesture_sim.sim.targets import RollingTargets

        spec = method_spec(method)
        self.library, self.model, self.method, self.seed = library, model, method, seed
        if control_library is None:
            control_library = (library if isinstance(library, ControlLibrary)
                               else ControlLibrary.from_motion_library(library))
        self.control_library = control_library
        self.dt = 1.0 / control_library.fps
        self._style = float(style)
        self.motion: MotionStage = spec.build(Parts(
            library, control_library, model, policy, graph=graph, seed=seed, style=self._style,
            p_interrupt=p_interrupt, temperature=temperature, repeat_cost=repeat_cost,
            repeat_tau_s=repeat_tau_s, sample_state=sample_state, sync=sync,
            blend_frames=int(blend_frames), transition=transition, words=words,
            sign_model=sign_model))
        # the semantic labels the method can serve: the policy's (controller, dcnf), or the
        # chooser's own tags (MIMiC's graph switches into a segment with the tag)
        served = (getattr(policy, "labels", ()) if spec.policy
                  else getattr(self.motion.chooser, "tags", ()))
        self.labels: tuple[str, ...] = tuple(lab for lab in served if lab)
        self.layers: list[LayerStage] = []
        if signals and spec.hears:
            from gesture_sim.signals.ruth import RuthSignals, load_markup

            markup = load_markup(signals_file) if signals_file is not None else None
            ruth = RuthSignals(seed=seed, markup=markup)
            self.layers.append(FaceLayer(ruth, base=lambda: self.base_target))
            if isinstance(phones, str):
                if phones != "recognise":
                    raise GestureSimError(f"phones: {phones!r}; give timed phones, "
                                          "'recognise' or None")
                from gesture_sim.signals.visemes import LiveCoarticulator

                self.layers.append(MouthLayer(LiveCoarticulator(lag_s=LIVE_PHONE_LAG_S), ruth))
            elif phones is not None:
                from gesture_sim.signals.visemes import Coarticulator

                self.layers.append(MouthLayer(Coarticulator(list(phones)), ruth))
        face = bool(self.layers)
        self.speech = SpeechState(accents, frames=face, phones=isinstance(phones, str) and face)
        from gesture_sim.signals.hands import HandLayer

        # the fingers: the playing clip's own finger motion where it has one, else a relaxed
        # hand that lives
        segments = getattr(library, "segments", None) or []
        self._segment_clip = np.array([(sg.clip, sg.start) for sg in segments],
                                      dtype=int).reshape(-1, 2)
        self.layers.append(HandLayer(seed=seed, tracks=finger_tracks or {},
                                     playing=self._playing_clip_frame))
        self._partner_speech: SpeechState | None = None
        self._audio_sinks: list = []   # a partner's audio listener takes this voice's samples
        if listener:
            from gesture_sim.signals.listeners import make_listener

            graph = None
            if (listener_model == "okwechime" and listener_motion != "envelope"
                    and getattr(library, "clips", None)):
                from gesture_sim.signals.listener_graph import listener_graph_for

                graph = listener_graph_for(library)
            self._partner_speech = SpeechState(detect=False)
            self.layers.append(ListenerLayer(
                make_listener(listener_model, seed=seed, interest=interest,
                              tendencies=listener_tendencies, audio_motion=listener_motion,
                              graph=graph),
                FrameReader(self._partner_speech)))
        self._target_layers = TargetLayers()
        for layer in self.layers:
            self._target_layers.define(layer.name, layer.joints)
        self.leg_stage = Legs(DEFAULT_LEGS if legs is None and stand is None else
                              legs or ("stand" if stand else "free"), library, control_library)
        self.legs = self.leg_stage.mode
        self.record = record
        self.targets = RollingTargets(self.dt)
        self.sim = None
        from gesture_sim.sim.bodies import resolve_body

        self.body = resolve_body(body)
        #: maps a humanoid target onto the robot (None: the humanoid itself)
        self.to_body = None
        if self.body.is_robot:
            from gesture_sim.sim.robot import RobotSim
            from gesture_sim.sim.robot_ik import (
                RobotRetarget,
                RobotTargets,
                find_library_on_robot,
            )

            built = (find_library_on_robot(self.body.robot, library)
                     if getattr(library, "clips", None) else None)
            self.to_body = RobotTargets(RobotRetarget(self.body.robot), *(built or (None, None)))
            if physics:
                self.sim = RobotSim(self.body.robot, seed=seed)
        elif physics:
            from gesture_sim.sim.humanoid import load_model
            from gesture_sim.sim.tracking import HumanoidSim

            self.sim = HumanoidSim(load_model(look=look), seed=seed,
                                   balance=self.leg_stage.balance())
        self.costs: dict[str, StageCost] = {}
        self.reset()

    @classmethod
    def create(cls, library: str | Path | None = None, model: str | Path | None = None, *,
               method: str = "controller", seed: int = 0, style: float = 0.5,
               physics: bool = True, show_progress: bool = False, **kwargs) -> GesturePipeline:
        """Load a library folder and a model folder (defaults: the shipped ones) and the policy."""
        from gesture_sim.loading import load_stack

        spec = method_spec(method)
        stack = load_stack(library, model, policy=spec.policy, graph=spec.graph,
                           show_progress=show_progress)
        return cls(stack.library, stack.model, stack.policy, method=method, seed=seed,
                   style=style, physics=physics, control_library=stack.control_library,
                   graph=stack.graph, finger_tracks=stack.finger_tracks, **kwargs)

    # ------------------------------------------------------------------ the stages, by name
    @property
    def controller(self):
        """The method's control layer (takes style and label requests; keeps ``decisions``)."""
        return self.motion.chooser

    @property
    def filter(self):
        """The method's belief filter."""
        return self.motion.filter

    @property
    def player(self):
        """The timing layer (:class:`~gesture_sim.control.synchrony.SyncPlayer`) or None."""
        return getattr(self.motion, "player", None)

    @property
    def tracker(self):
        """This voice's :class:`~gesture_sim.audio.prosody.ProsodyTracker`."""
        return self.speech.tracker

    def _playing_clip_frame(self) -> tuple[int, int] | None:
        """(clip index, clip frame) the latest step played, or None at rest."""
        m = self._motion
        if m is None or m.segment < 0 or m.segment >= len(self._segment_clip):
            return None
        clip, start = self._segment_clip[m.segment]
        return int(clip), int(start + max(m.frame, 0))

    def _layer(self, name: str):
        return next((layer for layer in self.layers if layer.name == name), None)

    @property
    def signals(self):
        """The face and head signals (:class:`~gesture_sim.signals.ruth.RuthSignals`) or None."""
        layer = self._layer("signals")
        return layer.signals if layer is not None else None

    @property
    def listener(self):
        """The listener (:class:`~gesture_sim.signals.listener.ListenerSignals`) or None."""
        layer = self._layer("listener")
        return layer.listener if layer is not None else None

    # ------------------------------------------------------------------ control
    def reset(self, expected_s: float = 60.0) -> None:
        """Start a new stream at t = 0: speech, stages, targets, physics and logs
        (``expected_s``: how long the stream is expected to run, s, for the trace's buffers;
        a longer one grows them)."""
        self.speech.reset()
        if self._partner_speech is not None:
            self._partner_speech.reset()
        self.motion.reset()
        self._ahead: dict = {}       # the text known ahead (know_ahead)
        for layer in self.layers:
            layer.reset()
        self.targets.reset()
        self.log = PipelineLog()
        for cost in self.motion.costs.values():
            cost.seconds, cost.calls = 0.0, 0
        self.costs = {"prosody": StageCost(), **self.motion.costs, "physics": StageCost(),
                      **{layer.name: StageCost() for layer in self.layers}}
        self.leg_stage.reset()
        self.costs.update({name: StageCost() for name in self.leg_stage.costs})
        if self.to_body is not None:
            self.to_body.q_prev = None
            self.costs["body"] = StageCost()
        self._next_step = 0
        #: The clip's target of the latest step before the layers ((n_act,) rad / m; None before
        #: the first step): what the face layer's eyes counter-rotate.
        self.base_target: np.ndarray | None = None
        self._motion: Motion | None = None
        self._t_audio = 0.0
        self._level_db = -120.0
        self._level_block = None   # the latest non-empty block, whose level status() reads
        self._label: str | None = None
        n = self.filter.n_states
        self._belief = np.full(n, 1.0 / n)
        if self.sim is not None:
            t0 = time.perf_counter()
            self.sim.reset(self.start_pose())
            self.sim.begin_trace(record=self.record, expected_s=expected_s)
            self.costs["physics"].add(time.perf_counter() - t0)

    def set_style(self, dial: float) -> None:
        """Style dial in [0, 1]: 0 calm, 0.5 neutral, 1 energetic."""
        self._style = clip_style(dial)
        self.motion.set_style(self._style, self.log.energy[-1] if self.log.energy else 0.0)
        self.log.events.append((self.time, f"style {self._style:.2f}"))

    def trigger_label(self, label: str) -> bool:
        """Ask for a semantic gesture now (e.g. ``"wave"``); False if the library has none."""
        ok = self.controller.request_label(label, t=self.time)
        if ok:
            self._label = label
            self.log.events.append((self.time, label))
        return ok

    @property
    def time(self) -> float:
        """Stream time of the latest control step (s)."""
        return (self._next_step - 1) * self.dt if self._next_step else 0.0

    @property
    def audio_time(self) -> float:
        """Stream time up to which audio has been received (s)."""
        return self._t_audio

    # ------------------------------------------------------------------ the chain
    def listen_to(self, partner: GesturePipeline) -> None:
        """Take the partner's prosody from ``partner``'s own voice (a conversation of two
        pipelines: each voice is analysed once); :meth:`push_partner_audio` is then not used."""
        layer = self._layer("listener")
        if layer is None:
            raise GestureSimError("this pipeline does not listen to a partner (listener=False)")
        layer.partner = FrameReader(partner.speech)
        self._partner_speech = None
        if hasattr(layer.listener, "push_audio"):     # both listeners hear samples (laughs; MFCC)
            partner._audio_sinks.append(layer.listener.push_audio)

    def expect_audio(self, samples: np.ndarray) -> None:
        """The whole stream of this voice (float 16 kHz from t = 0), known ahead, as from a
        file; call after :meth:`reset`. The speech analysis prepares per-frame work from it
        (:meth:`~gesture_sim.audio.speech.SpeechState.expect`); what every control step hears,
        and when, is unchanged (the pushed blocks decide). Its time counts to the prosody
        stage's cost."""
        t0 = time.perf_counter()
        self.speech.expect(samples)
        self.costs["prosody"].seconds += time.perf_counter() - t0
        plan = getattr(self.motion, "expect", None)      # a method that plans ahead
        if plan is not None:
            plan(samples, **self._ahead)

    def know_ahead(self, *, words=None, phones=None, stress=None) -> None:
        """The text of this stream known ahead, for a method that plans
        (:class:`~gesture_sim.stages.PlannedMotion`): timed ``words`` and ``phones``
        (``(start_s, end_s, text)``; phone labels with ARPAbet stress digits where known) and
        stressed-syllable times ``stress`` (s). Call after :meth:`reset`, before
        :meth:`expect_audio` (:meth:`expect_speech` does both)."""
        self._ahead = {"words": words, "phones": phones, "stress": stress}

    def expect_speech(self, samples: np.ndarray, *, words=None, phones=None,
                      stress=None) -> None:
        """A voice known before it plays (a text-to-speech voice's audio (n,) float 16 kHz
        from t = 0 with its timed words and phones): :meth:`know_ahead` then
        :meth:`expect_audio`. Call after :meth:`reset`; then push the audio's blocks as it
        plays (:meth:`push_audio`), as from a file or live."""
        self.know_ahead(words=words, phones=phones, stress=stress)
        self.expect_audio(samples)

    def push_audio(self, block: AudioBlock, run: bool = True) -> None:
        """Consume one audio block and run every control step its end time reaches.

        With ``run`` false the block is only analysed; :meth:`run_steps` then runs the steps
        (a conversation analyses both voices before either person steps).
        """
        if len(block.samples):
            self._level_block = block.samples     # its level is computed when read (status)
        t0 = time.perf_counter()
        new = self.speech.push(block)
        self.costs["prosody"].add(time.perf_counter() - t0)
        for sink in self._audio_sinks:
            sink(block.samples)
        self._note(new)
        self._t_audio = max(self._t_audio, block.t_end)
        if run:
            self.run_steps()

    def push_partner_audio(self, block: AudioBlock) -> None:
        """Consume one block of the partner's speech (a pipeline made with ``listener``).

        Push it before this person's own block of the same time span, so that the control
        steps that block runs see the partner's prosody up to the same time.
        """
        if self._partner_speech is None:
            raise GestureSimError("this pipeline does not take partner audio (it has no "
                                  "listener, or listens to a partner pipeline)")
        t0 = time.perf_counter()
        self._partner_speech.push(block)
        listener = self._layer("listener").listener
        if hasattr(listener, "push_audio"):
            listener.push_audio(block.samples)
        self.costs["listener"].add(time.perf_counter() - t0)

    def finish(self, run: bool = True) -> None:
        """End of stream: flush the tracker's last syllable and run the remaining steps (with
        ``run`` false only the flush; :meth:`run_steps` then runs them)."""
        self._note(self.speech.flush())
        if run:
            self.run_steps()

    def _note(self, new) -> None:
        self.log.syllables.extend(new.syllables)
        self.log.accents.extend(new.accents)
        self.log.boundaries.extend(new.boundaries)

    def run_steps(self) -> None:
        """Run every control step the audio received so far reaches."""
        while self._next_step * self.dt <= self._t_audio + _EPS:
            self._step(self._next_step * self.dt)

    def _step(self, t: float) -> None:
        """One control step at stream time ``t`` (s): the stages in their fixed order."""
        heard: Heard = self.speech.view(t)
        motion = self.motion.step(t, heard)
        q = np.asarray(motion.target, dtype=float).copy()
        self.base_target = q.copy()      # the clip's pose, before the layers (the eyes read it)
        self._motion = motion            # what plays (the hands read it)
        if self.layers:
            for layer in self.layers:
                t0 = time.perf_counter()
                offsets, events = layer.step(t, heard)
                self._target_layers.set(layer.name, offsets)
                self.log.signals.extend(events)
                self.costs[layer.name].add(time.perf_counter() - t0)
            q = self._target_layers.apply(q)
        t0 = time.perf_counter()
        if self.leg_stage.apply(q, motion):
            self.costs["legs"].add(time.perf_counter() - t0)
        if self.to_body is not None:                 # the robot's target for this pose
            t0 = time.perf_counter()
            self.targets.push(t, self.to_body.target(q, self._playing_clip_frame(), self.dt))
            self.costs["body"].add(time.perf_counter() - t0)
        else:
            self.targets.push(t, q)
        self._belief = motion.belief
        if motion.decision is not None and motion.decision.kind == "label":
            self._label = None
        self.log.add_step(t, motion, q, heard.energy)
        self._next_step += 1
        if not self.record and len(self.log.step_times) > 2 * LIVE_LOG_S / self.dt:
            keep = int(LIVE_LOG_S / self.dt)
            self.motion.trim(self.log.trim(keep), keep)

    def start_pose(self) -> np.ndarray | None:
        """The pose a stream starts in: the library's rest pose with the legs' rest (standing, or
        with ``legs="clip"`` the middle of the planted stance), so that a render begins at rest
        without a jump; None (the standing pose) when there is nothing to set."""
        rest = self.leg_stage.rest(getattr(self.control_library, "rest_pose", None),
                                   len(self.control_library.joint_names))
        if self.to_body is None:
            return rest
        q_h = np.zeros(len(self.control_library.joint_names)) if rest is None else rest
        return self.to_body.solve(q_h, q_prev=self.to_body.stand, iterations=12)

    @property
    def has_targets(self) -> bool:
        """Whether a control step has produced a target yet (:meth:`target_at` works)."""
        return self.targets.ready

    def target_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q*(t), qd*(t) (n_joints,): linear between the last two control steps, held after."""
        return self.targets.sample(t)

    def advance(self, t: float) -> None:
        """Step the physics up to stream time ``t`` (s), following the targets."""
        if self.sim is None or not self.targets.ready:
            return
        t0 = time.perf_counter()
        self.sim.advance_to(t, self.targets.sample)
        self.costs["physics"].add(time.perf_counter() - t0)

    # ------------------------------------------------------------------ views
    @property
    def model_mj(self):
        """The simulated humanoid's MuJoCo model (for viewers and renderers)."""
        return self.sim.model if self.sim is not None else None

    @property
    def data(self):
        """The simulated humanoid's MuJoCo data (the state a viewer shows)."""
        return self.sim.data if self.sim is not None else None

    @property
    def level_db(self) -> float:
        """Level of the latest non-empty audio block (dB re full scale, RMS; -120 before any):
        computed when read, from that block, not for every block pushed."""
        block = self._level_block
        if block is not None:
            self._level_block = None
            samples = np.asarray(block, dtype=np.float32)
            rms = float(np.sqrt(np.mean(samples.astype(np.float64) ** 2)))
            self._level_db = 20.0 * np.log10(max(rms, 1e-6))
        return self._level_db

    def status(self) -> PipelineStatus:
        """A :class:`PipelineStatus` of the latest step."""
        seg = self.log.segments[-1] if self.log.segments else -1
        return PipelineStatus(
            t=self.time, level_db=self.level_db, state=int(np.argmax(self._belief)),
            belief=np.array(self._belief, dtype=float), segment=seg,
            segment_name=self.segment_name(seg),
            frame=self.log.frames[-1] if self.log.frames else -1, style=self._style,
            label=self._label,
        )

    def segment_name(self, segment: int) -> str:
        """The clip name of a segment ('' if unknown)."""
        lib = self.library
        if segment < 0 or not hasattr(lib, "segments"):
            return ""
        return lib.clips[lib.segments[segment].clip].name

    def trace(self):
        """The physics :class:`~gesture_sim.sim.trace.SimTrace` recorded so far."""
        if self.sim is None:
            raise GestureSimError("this pipeline runs without physics")
        return self.sim.trace()
