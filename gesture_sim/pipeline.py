"""The one causal pipeline used by ``render`` and ``live`` (docs/DESIGN.md §1, §4).

    audio blocks -> prosody syllables -> belief (CRF forward filter) -> controller decisions
    -> joint targets q*(t) -> PD-tracked MuJoCo physics

:meth:`GesturePipeline.push_audio` consumes a block and runs every control step (one per library
frame, default 30 Hz) whose time the audio has reached; at step t the inference filter sees only
the syllables emitted at or before t. :meth:`GesturePipeline.advance` steps the physics up to a
stream time, following the targets interpolated between control steps (held at the latest one when
the physics runs ahead). A file is fed block by block in simulated real time; the live viewer feeds
microphone blocks and advances with the wall clock — the same code either way.

Selection methods (``method``): ``"controller"`` (the product: the CRF belief drives the MDP,
which chooses *which* segment; the timing layer :class:`~gesture_sim.control.synchrony.SyncPlayer`
decides *when*: strokes on the accents the causal detector emits, holds, rest in silence, energy
from the voice), ``"levine09"`` (the Levine 2009 baseline), ``"random"`` (uniformly random
co-speech segments at their own pace, no speech input: the thesis's random baseline) and
``"random_sync"`` (random choice behind the same timing layer: how much the timing alone gives);
``"dcnf"`` is the controller with Chiu 2014's DCNF as the belief filter instead of the CRF;
``"mimic"`` chooses with Okwechime 2011's motion graph (MIMiC) behind the same timing layer.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, Accent, AudioBlock, Boundary, Decision, Syllable
from gesture_sim.control.style import clip_style, dial_from_style
from gesture_sim.control.synchrony import SpeechCue
from gesture_sim.errors import GestureSimError

METHODS = ("controller", "dcnf", "mimic", "levine09", "random", "random_sync")
#: Methods whose motion is timed by the speech (the timing layer).
SYNC_METHODS = ("controller", "dcnf", "mimic", "random_sync")
#: Methods that choose with the MDP policy (the belief from the CRF, or from the DCNF).
POLICY_METHODS = ("controller", "dcnf")
#: The controller's default softmin temperature (cost units), chosen by measurement: see
#: BENCHMARKS.md ("controller temperature").
DEFAULT_TEMPERATURE = 2.0
#: How strongly the vocal energy (-1..1) moves the MDP's style dial (-1 calm .. 1 energetic):
#: energy 0.5 (clearly livelier than this speaker's usual) reaches the energetic tone.
ENERGY_TO_DIAL = 2.0
#: A file whose peak amplitude stays below this (-60 dBFS) is refused as silent.
SILENCE_PEAK = 1e-3
#: Seconds of step log a pipeline without ``record`` keeps (the live loop).
LIVE_LOG_S = 30.0


@dataclass
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
class StageCost:
    """Accumulated wall time (s) and call count of one stage."""

    seconds: float = 0.0
    calls: int = 0

    def add(self, dt: float) -> None:
        self.seconds += dt
        self.calls += 1


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


class GesturePipeline:
    """Speech in, a PD-tracked humanoid out, causally (see the module docstring).

    Args:
        library: a :class:`~gesture_sim.motion.library.MotionLibrary`.
        model: a :class:`~gesture_sim.inference.model.GestureModel`.
        policy: the controller :class:`~gesture_sim.control.policy.Policy` for that pair.
        method: one of :data:`METHODS`.
        seed: seeds the physics' initial noise and the random baseline.
        style: the style dial in [0, 1] (0 calm, 0.5 neutral, 1 energetic).
        physics: simulate the humanoid (False: targets only, for fast evaluation).
        p_interrupt: interruption probability of the random baseline.
        temperature: the controller's softmin temperature (cost units; 0 = the paper's argmin;
            see :class:`~gesture_sim.control.controller.GestureController`).
        blend_frames: control steps over which a segment switch ramps from the last target
            (default 6 = 200 ms at 30 Hz, within the 5–10 frames the Gesture Controllers digest
            suggests; it lowered foot skating and hand-speed peaks on real speech, see
            BENCHMARKS.md; 0 = the raw jump).
        stand: legs track the standing pose instead of the clip's legs (default).
        record: keep the whole :class:`~gesture_sim.sim.trace.SimTrace` and log of the run (False
            for the live loop: no trace, and the log keeps only its last :data:`LIVE_LOG_S`
            seconds, so memory stays flat over a long run).
        control_library: the library's :class:`~gesture_sim.control.inputs.ControlLibrary`
            (built from ``library`` when not given).
        signals: face and head signals after RUTH (:mod:`gesture_sim.signals.ruth`: nods,
            brows, blinks, jaw) added onto the clip's target through one target layer
            (:mod:`gesture_sim.sim.layers`); False keeps the clip's face and head as they are.
        signals_file: a ``--signals`` markup file of timed labels that drive or override them.
        listener: also listen to a partner (a conversation, Okwechime 2011): the partner's
            audio, given by :meth:`push_partner_audio`, drives backchannels — nods, brow raises,
            posture shifts (:mod:`gesture_sim.signals.listener`) — through a second target
            layer, never while this person speaks.
    """

    def __init__(self, library, model, policy, *, method: str = "controller", seed: int = 0,
                 style: float = 0.5, physics: bool = True, p_interrupt: float = 0.1,
                 control_library=None, record: bool = True, stand: bool = True,
                 blend_frames: int = 6, temperature: float = DEFAULT_TEMPERATURE,
                 sync=None, accents=None, graph=None, signals: bool = True,
                 signals_file: str | Path | None = None, listener: bool = False) -> None:
        from gesture_sim.audio.accents import AccentDetector
        from gesture_sim.audio.prosody import ProsodyTracker
        from gesture_sim.control.controller import GestureController
        from gesture_sim.control.inputs import ControlLibrary

        if method not in METHODS:
            raise GestureSimError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
        self.library = library
        self.model = model
        self.method = method
        self.seed = seed
        if control_library is None:
            control_library = (library if isinstance(library, ControlLibrary)
                               else ControlLibrary.from_motion_library(library))
        self.control_library = control_library
        self.player = None
        if method == "random":
            from gesture_sim.control.baselines import RandomSelector

            self.controller = RandomSelector(self.control_library, seed=seed,
                                             p_interrupt=p_interrupt)
        elif method == "levine09":
            from gesture_sim.inference.levine09_synthesis import Levine09Synthesis

            self.controller = Levine09Synthesis(model.baseline, self.control_library, seed=seed,
                                                allowed=self.control_library.cospeech,
                                                state_model=model)
        elif method == "mimic":
            from gesture_sim.control.inputs import StateModel
            from gesture_sim.control.mimic import MimicChooser, build_graph

            graph = graph if graph is not None else build_graph(self.control_library)
            self.controller = MimicChooser(graph, self.control_library, seed=seed,
                                           model=StateModel.from_inference(model))
        elif method == "random_sync":
            from gesture_sim.control.baselines import RandomChooser

            n_points = self.control_library.n_interrupts + 1
            self.controller = RandomChooser(self.control_library, n_points, seed=seed,
                                            p_interrupt=p_interrupt)
        else:
            self.controller = GestureController(policy, self.control_library,
                                                temperature=temperature, seed=seed)
        if method in SYNC_METHODS:
            from gesture_sim.control.synchrony import SyncPlayer, SyncSettings

            fps = self.control_library.fps
            self.player = SyncPlayer(self.control_library, self.controller,
                                     sync or SyncSettings(blend_s=blend_frames / fps))
        # The 2009 synthesis filters its own observations (it takes syllables, not a belief).
        self.filter = (self.controller.filter if method == "levine09"
                       else model.new_filter("dcnf" if method == "dcnf" else "crf"))
        self.dt = 1.0 / self.control_library.fps
        self.tracker_factory = ProsodyTracker
        self.accent_detector = AccentDetector(accents)
        self.physics = physics
        # The body stands: leg joints track the standing pose and the balance controller, not
        # the clip (the clips' weight shifts and steps would make a standing body slide).
        self._legs = None
        if stand:
            from gesture_sim.sim.humanoid import leg_columns

            self._legs = leg_columns(self.control_library.joint_names)
        self.record = record
        self.blend_frames = int(blend_frames)
        self.sim = None
        if physics:
            from gesture_sim.sim.tracking import HumanoidSim

            self.sim = HumanoidSim(seed=seed)
        self.labels: tuple[str, ...] = tuple(
            lab for lab in getattr(policy, "labels", ()) if lab) if method in POLICY_METHODS else ()
        self.costs = {name: StageCost() for name in ("prosody", "inference", "control", "physics")}
        # ---- face and head signals (issue 14): the RUTH scheduler and its target layer ----
        self.signals = None
        if signals and method != "random":     # the random baseline hears nothing
            from gesture_sim.signals.ruth import SIGNAL_JOINTS, RuthSignals, load_markup
            from gesture_sim.sim.layers import TargetLayers

            markup = load_markup(signals_file) if signals_file is not None else None
            self.signals = RuthSignals(seed=seed, markup=markup)
            self._layers = TargetLayers()
            self._layers.define("signals", SIGNAL_JOINTS)
            self._sig_frames = self._sig_bounds = 0
            self.costs["signals"] = StageCost()
        # ---- end face and head signals ----
        # ---- the listener (issue 16): backchannels driven by a partner's speech ----
        self.listener = None
        if listener:
            from gesture_sim.signals.listener import LISTENER_JOINTS, ListenerSignals
            from gesture_sim.sim.layers import TargetLayers

            self.listener = ListenerSignals(seed=seed)
            self._partner: GesturePipeline | None = None
            if self.signals is None:
                self._layers = TargetLayers()
            self._layers.define("listener", LISTENER_JOINTS)
            self.costs["listener"] = StageCost()
        self._style = float(style)
        self.reset()

    # ------------------------------------------------------------------ construction
    @classmethod
    def create(cls, library: str | Path | None = None, model: str | Path | None = None, *,
               method: str = "controller", seed: int = 0, style: float = 0.5,
               physics: bool = True, show_progress: bool = False, **kwargs) -> GesturePipeline:
        """Load a library folder and a model folder (defaults: the shipped ones) and the policy."""
        from gesture_sim.loading import load_stack

        stack = load_stack(library, model, policy=method in POLICY_METHODS,
                           graph=method == "mimic", show_progress=show_progress)
        return cls(stack.library, stack.model, stack.policy, method=method, seed=seed,
                   style=style, physics=physics, control_library=stack.control_library,
                   graph=stack.graph, **kwargs)

    # ------------------------------------------------------------------ control
    def reset(self) -> None:
        """Start a new stream at t = 0: tracker, filter, controller, physics and logs."""
        self.tracker = self.tracker_factory()
        self.accent_detector.reset()
        self.filter.reset()
        self.controller.reset()
        self._dial = dial_from_style(self._style)
        self.controller.set_style(self._dial)
        if self.player is not None:
            self.player.reset()
        self._pending_accents: list[Accent] = []
        if self.listener is not None:
            self.partner_tracker = self.tracker_factory()
            self.listener.reset()
            self._partner_frames = 0
        self.log = PipelineLog()
        self.costs = {name: StageCost() for name in self.costs}
        self._pending: list[Syllable] = []
        self._next_step = 0
        self._t_audio = 0.0
        self._level_db = -120.0
        self._label: str | None = None
        self._belief = np.full(self.filter.n_states, 1.0 / self.filter.n_states)
        self._q_prev: np.ndarray | None = None
        self._q_last: np.ndarray | None = None
        self._blend_from: np.ndarray | None = None
        self._blend_k = 0
        self._t_last = 0.0
        if self.sim is not None:
            t0 = time.perf_counter()
            self.sim.reset(self.start_pose())
            self.sim.begin_trace(record=self.record)
            self.costs["physics"].add(time.perf_counter() - t0)

    def set_style(self, dial: float) -> None:
        """Style dial in [0, 1]: 0 calm, 0.5 neutral, 1 energetic."""
        self._style = clip_style(dial)
        self._set_dial(self.log.energy[-1] if self.log.energy else 0.0)
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
        """Take the partner's prosody from ``partner``'s own tracker (a conversation of two
        pipelines: each voice is analysed once); :meth:`push_partner_audio` is then not used."""
        if self.listener is None:
            raise GestureSimError("this pipeline does not listen to a partner (listener=False)")
        self._partner = partner

    def push_audio(self, block: AudioBlock, run: bool = True) -> None:
        """Consume one audio block and run every control step its end time reaches.

        With ``run`` false the block is only analysed; :meth:`run_steps` then runs the steps
        (a conversation analyses both voices before either person steps).
        """
        samples = np.asarray(block.samples, dtype=np.float32)
        if len(samples):
            rms = float(np.sqrt(np.mean(samples.astype(np.float64) ** 2)))
            self._level_db = 20.0 * np.log10(max(rms, 1e-6))
        t0 = time.perf_counter()
        new = self.tracker.push(block)
        acc, bnd = self.accent_detector.update(self.tracker)
        self.costs["prosody"].add(time.perf_counter() - t0)
        self._note_accents(acc, bnd)
        self._pending.extend(new)
        self.log.syllables.extend(new)
        self._t_audio = max(self._t_audio, block.t_end)
        if run:
            self._run_steps(self._t_audio)

    def run_steps(self) -> None:
        """Run every control step the audio received so far reaches."""
        self._run_steps(self._t_audio)

    def push_partner_audio(self, block: AudioBlock) -> None:
        """Consume one block of the partner's speech (a pipeline made with ``listener``).

        Push it before this person's own block of the same time span, so that the control
        steps that block runs see the partner's prosody up to the same time.
        """
        if self.listener is None or self._partner is not None:
            raise GestureSimError("this pipeline does not take partner audio (it has no "
                                  "listener, or listens to a partner pipeline)")
        t0 = time.perf_counter()
        self.partner_tracker.push(block)
        self.costs["listener"].add(time.perf_counter() - t0)

    def finish(self, run: bool = True) -> None:
        """End of stream: flush the tracker's last syllable and run the remaining steps (with
        ``run`` false only the flush; :meth:`run_steps` then runs them)."""
        new = self.tracker.flush()
        self._note_accents(*self.accent_detector.finish(self.tracker))
        self._pending.extend(new)
        self.log.syllables.extend(new)
        if run:
            self._run_steps(self._t_audio)

    def _run_steps(self, t_until: float) -> None:
        eps = 1e-9
        while self._next_step * self.dt <= t_until + eps:
            t = self._next_step * self.dt
            ready = [s for s in self._pending if s.t_emitted <= t + eps]
            if ready:
                self._pending = [s for s in self._pending if s.t_emitted > t + eps]
            accents = [a for a in self._pending_accents if a.t_emitted <= t + eps]
            if accents:
                self._pending_accents = self._pending_accents[len(accents):]
            t0 = time.perf_counter()
            if self.method == "levine09":
                result = self.controller.step(t, ready)
                belief = self.filter.belief
            else:
                belief = self.filter.step(t, ready)
            t1 = time.perf_counter()
            speaking, silence_s, energy = self.accent_detector.state_at(t)
            mode = ""
            if self.player is not None:
                self._set_dial(energy)
                cue = SpeechCue(speaking=speaking, silence_s=silence_s,
                                accents=[a.t for a in accents],
                                strengths=[a.pitch_z for a in accents], energy=energy)
                result = self.player.step(t, belief, cue)
                mode = result.mode
                if result.stroke:
                    self.log.strokes.append(t)
                    served = self.player.log.served
                    if served and served[-1][1] == t:
                        self.log.served.append(served[-1])
            elif self.method != "levine09":
                result = self.controller.step(belief, t)
            t2 = time.perf_counter()
            self.costs["inference"].add(t1 - t0)
            self.costs["control"].add(t2 - t1)
            self._belief = belief
            if result.decision is not None:
                self.log.decisions.append(result.decision)
                if result.decision.kind == "label":
                    self._label = None
            q = np.asarray(result.target, dtype=float).copy()
            # ---- face and head signals (issue 14): offsets on top of the clip's target ----
            if self.signals is not None:
                t3 = time.perf_counter()
                if self._next_step == 0:
                    self.signals.reset()
                    self._sig_frames = self._sig_bounds = 0
                if self.tracker.n_frames > self._sig_frames:
                    fr, known = self.tracker.frames_since(self._sig_frames)
                    self.signals.push_frames(fr.times, fr.intensity_db, fr.silent, known,
                                             fr.f0_hz)
                    self._sig_frames = self.tracker.n_frames
                bounds = self.accent_detector.boundaries[self._sig_bounds:]
                self._sig_bounds += len(bounds)
                offsets, sig_events = self.signals.step(t, accents, bounds, speaking, silence_s)
                self._layers.set("signals", offsets)
                self.log.signals.extend(sig_events)
                if not self.record and len(self.log.signals) > 4000:
                    del self.log.signals[:-2000]
                self.costs["signals"].add(time.perf_counter() - t3)
            # ---- end face and head signals ----
            if self.listener is not None:
                t3 = time.perf_counter()
                tracker = (self.partner_tracker if self._partner is None
                           else self._partner.tracker)
                if tracker.n_frames > self._partner_frames:
                    fr, known = tracker.frames_since(self._partner_frames)
                    self.listener.push_frames(fr.times, fr.intensity_db, fr.silent, known,
                                              fr.f0_hz)
                    self._partner_frames = tracker.n_frames
                offsets, events = self.listener.step(t, own_speaking=speaking)
                self._layers.set("listener", offsets)
                self.log.signals.extend(events)
                self.costs["listener"].add(time.perf_counter() - t3)
            if self.signals is not None or self.listener is not None:
                q = self._layers.apply(q)
            if self._legs is not None:
                q[self._legs] = 0.0
            if self.player is None:
                q = self._ramp(q, switched=result.decision is not None
                               and not result.decision.costs.get("continue", 0.0))
            self._q_prev, self._q_last, self._t_last = self._q_last, q, t
            log = self.log
            log.step_times.append(t)
            log.beliefs.append(np.asarray(belief, dtype=np.float32))
            log.segments.append(result.segment)
            log.frames.append(result.frame)
            log.targets.append(q.astype(np.float32))
            log.modes.append(mode)
            log.energy.append(energy)
            self._next_step += 1
            if not self.record and len(log.step_times) > 2 * LIVE_LOG_S / self.dt:
                self._trim_log()

    def _ramp(self, q: np.ndarray, switched: bool) -> np.ndarray:
        """Blend into a new segment over ``blend_frames`` control steps (smoothstep).

        A clip switch jumps the targets; the body would realise the jump at its torque limits
        (a snap). A short ramp from the last target is the "short target ramp" docs/DESIGN.md
        allows; its length is a setting (0 disables it) and its effect is measured in
        BENCHMARKS.md.
        """
        if switched and self._q_last is not None and self.blend_frames > 0:
            self._blend_from, self._blend_k = self._q_last.copy(), 0
        if self._blend_from is None:
            return q
        self._blend_k += 1
        x = min(self._blend_k / (self.blend_frames + 1), 1.0)
        w = x * x * (3.0 - 2.0 * x)
        out = self._blend_from + w * (q - self._blend_from)
        if x >= 1.0:
            self._blend_from = None
        return out

    def start_pose(self) -> np.ndarray | None:
        """The pose a stream starts in: the library's rest pose (legs standing), so that a render
        begins at rest without a jump; None (the standing pose) when the library has none."""
        rest = getattr(self.control_library, "rest_pose", None)
        if rest is None:
            return None
        q = np.asarray(rest, dtype=float).copy()
        if self._legs is not None:
            q[self._legs] = 0.0
        return q

    def _note_accents(self, accents: list[Accent], boundaries: list[Boundary]) -> None:
        self._pending_accents.extend(accents)
        self.log.accents.extend(accents)
        self.log.boundaries.extend(boundaries)

    def _set_dial(self, energy: float) -> None:
        """The MDP's style dial: the user's setting (0.5 = neutral) offset by the voice."""
        dial = dial_from_style(self._style, ENERGY_TO_DIAL * energy)
        if abs(dial - self._dial) >= 0.05:
            self._dial = dial
            self.controller.set_style(dial)

    def _trim_log(self) -> None:
        """Keep only the last :data:`LIVE_LOG_S` seconds of the log (live loop)."""
        log = self.log
        keep = int(LIVE_LOG_S / self.dt)
        for name in ("step_times", "beliefs", "segments", "frames", "targets", "modes",
                     "energy"):
            del getattr(log, name)[:-keep]
        t_min = log.step_times[0]
        log.syllables = [s for s in log.syllables if s.t_end >= t_min]
        log.decisions = [d for d in log.decisions if d.t >= t_min]
        log.events = [e for e in log.events if e[0] >= t_min]
        log.accents = [a for a in log.accents if a.t >= t_min]
        log.boundaries = [b for b in log.boundaries if b.t >= t_min]
        log.strokes = [x for x in log.strokes if x >= t_min]
        log.served = [x for x in log.served if x[1] >= t_min]
        if self.player is not None:
            plog = self.player.log
            plog.strokes = [x for x in plog.strokes if x >= t_min]
            plog.served = [x for x in plog.served if x[1] >= t_min]
            plog.accents = [x for x in plog.accents if x >= t_min]
            plog.rest_spans = [x for x in plog.rest_spans if x[1] >= t_min]
        if hasattr(self.controller, "decisions"):
            del self.controller.decisions[:-keep]

    @property
    def has_targets(self) -> bool:
        """Whether a control step has produced a target yet (:meth:`target_at` works)."""
        return self._q_last is not None

    def target_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q*(t), qd*(t) (n_joints,): linear between the last two control steps, held after."""
        if self._q_last is None:
            raise GestureSimError("no control step yet: push audio first")
        if self._q_prev is None or t >= self._t_last:
            return self._q_last, np.zeros_like(self._q_last)
        a = (t - (self._t_last - self.dt)) / self.dt
        a = min(max(a, 0.0), 1.0)
        return (self._q_prev + a * (self._q_last - self._q_prev),
                (self._q_last - self._q_prev) / self.dt)

    def advance(self, t: float) -> None:
        """Step the physics up to stream time ``t`` (s), following the targets."""
        if self.sim is None or self._q_last is None:
            return
        t0 = time.perf_counter()
        self.sim.advance_to(t, self.target_at)
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

    def status(self) -> PipelineStatus:
        seg = self.log.segments[-1] if self.log.segments else -1
        return PipelineStatus(
            t=self.time, level_db=self._level_db, state=int(np.argmax(self._belief)),
            belief=self._belief.copy(), segment=seg, segment_name=self.segment_name(seg),
            frame=self.log.frames[-1] if self.log.frames else -1, style=self._style,
            label=self._label,
        )

    def segment_name(self, segment: int) -> str:
        """The clip name of a segment ('' if unknown)."""
        lib = self.library
        if segment < 0 or not hasattr(lib, "segments"):
            return ""
        clip = lib.clips[lib.segments[segment].clip]
        return clip.name

    def trace(self):
        """The physics :class:`~gesture_sim.sim.trace.SimTrace` recorded so far."""
        if self.sim is None:
            raise GestureSimError("this pipeline runs without physics")
        return self.sim.trace()


@dataclass
class RunResult:
    """A whole file through the pipeline.

    Attributes:
        pipeline: the pipeline after the run (its ``log`` and ``trace()``).
        audio: (n,) float32 16 kHz samples; duration: seconds.
        wall: wall-clock seconds of the run; costs: seconds per stage.
    """

    pipeline: GesturePipeline
    audio: np.ndarray
    duration: float
    wall: float
    costs: dict[str, float]


def run_file(pipeline: GesturePipeline, audio_path: str | Path, *, block_size: int = 160,
             show_progress: bool = False,
             labels: Sequence[tuple[float, str]] = (), keywords=None,
             transcript: str | Path | None = None) -> RunResult:
    """Feed a file through the pipeline block by block, in simulated real time.

    ``labels`` are semantic gestures requested at given stream times, ``(t_s, "wave")``, as a
    key press would request them live. ``keywords`` (a
    :class:`~gesture_sim.audio.keywords.KeywordTable`) spots the table's words in the audio
    (PocketSphinx, the same decoder the live spotter runs) — or, with ``transcript`` (a TextGrid
    word tier or ``start end word`` lines), reads them from the aligned text — and requests each
    hit's label at the time the spotter knew it (``t_emitted``; the transcript's word end).
    The hits are kept in ``pipeline.log.words``.
    """
    from gesture_sim.audio.sources import iter_blocks, load_audio
    from gesture_sim.progress import progress

    samples, _info = load_audio(audio_path)
    if len(samples) == 0:
        raise GestureSimError(f"{audio_path}: no audio samples")
    peak = float(np.max(np.abs(samples)))
    if peak < SILENCE_PEAK:
        level = 20.0 * np.log10(max(peak, 1e-12))
        raise GestureSimError(
            f"{audio_path}: silent (peak {level:.0f} dBFS); nothing to gesture to")
    words = []
    if keywords is not None:
        from gesture_sim.audio.keywords import spot_file, transcript_keywords

        words = (transcript_keywords(transcript, keywords, pipeline.labels)
                 if transcript is not None else spot_file(samples, keywords, pipeline.labels))
        labels = list(labels) + [(w.t_emitted, w.label) for w in words if w.label]
    unknown = sorted({lab for _, lab in labels} - set(pipeline.labels))
    if unknown:
        raise GestureSimError(f"unknown semantic label(s) {', '.join(unknown)}; this library "
                              f"has: {', '.join(pipeline.labels) or 'none'}")
    pending = sorted(labels)
    duration = len(samples) / SAMPLE_RATE
    pipeline.reset()
    pipeline.log.words = list(words)
    t0 = time.perf_counter()
    bar = progress(total=round(duration, 1), desc="simulating", enabled=show_progress, unit="s")
    done = 0.0
    for block in iter_blocks(samples, block_size):
        while pending and pending[0][0] <= block.t_start:
            pipeline.trigger_label(pending.pop(0)[1])
        pipeline.push_audio(block)
        pipeline.advance(pipeline.time)
        if block.t_end - done >= 0.5:
            bar.update(round(block.t_end - done, 1))
            done = block.t_end
    pipeline.finish()
    pipeline.advance(duration)
    bar.close()
    wall = time.perf_counter() - t0
    return RunResult(pipeline=pipeline, audio=samples, duration=duration, wall=wall,
                     costs={k: v.seconds for k, v in pipeline.costs.items()})
