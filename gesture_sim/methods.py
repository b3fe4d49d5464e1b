"""The registry of selection methods: each name maps to how its motion stage is built.

A method is a belief filter, a control layer and a timing (:mod:`gesture_sim.stages`):

==============  ============================  ==========================  ===================
method          belief filter                 control layer               timing
==============  ============================  ==========================  ===================
``controller``  remapped CRF (Levine 2010)    MDP policy (softmin)        the timing layer
``dcnf``        DCNF (Chiu 2014)              MDP policy (softmin)        the timing layer
``mimic``       remapped CRF                  MIMiC motion graph (2011)   the timing layer
``random_sync`` remapped CRF (ignored)        uniformly random            the timing layer
``chiu14``      sign filter (Chiu 2014)       segment of the sign         the timing layer
``planned``     remapped CRF (as a prior)     plan over the speech ahead  the plan, nudged
``levine09``    the 2009 HMM, in the synth.   Levine 2009 synthesis       its own
``random``      remapped CRF (ignored)        uniformly random            its own (no speech)
==============  ============================  ==========================  ===================

The timing layer is :class:`~gesture_sim.control.synchrony.SyncPlayer` (strokes on accents,
holds, rest in silence, energy). To add a method, write its control layer against a protocol of
:mod:`gesture_sim.control.protocols` and register a :class:`MethodSpec` here; nothing else in
the step changes (docs/ARCHITECTURE.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gesture_sim.control.ramp import DEFAULT_BLEND_FRAMES
from gesture_sim.errors import GestureSimError

#: The controller's default softmin temperature (cost units), chosen by measurement: see
#: docs/history.md (the controller's row).
DEFAULT_TEMPERATURE = 2.0
#: The controller's novelty term (``GestureController(repeat_cost=, repeat_tau_s=)``: cost
#: units, s): entering a segment played ``age`` seconds ago costs ``16 exp(-age / 40 s)``.
#: Without it the controller replays a few central segments (31 distinct of the 67 co-speech
#: ones a take, the top five 41 % of the frames) and its FGD to real co-speech motion is 47
#: against random clips' 31; with it 35, every coupling figure as before (docs/history.md,
#: "novelty term").
DEFAULT_REPEAT_COST = 16.0
DEFAULT_REPEAT_TAU_S = 40.0

#: How the timing layer crosses a segment switch: ``"ramp"`` (the switch ramp in joint space,
#: :class:`~gesture_sim.control.ramp.SwitchRamp`) or ``"gpdm"`` (Chiu 2014's transitions on a
#: GPDM of the library's co-speech frames, :class:`~gesture_sim.motion.gpdm.GPDMPath`; fitted
#: at build, about 3.5 s, and 0.05–0.2 s a switch: an offline option).
TRANSITIONS = ("ramp", "gpdm")


@dataclass
class Parts:
    """What a method is built from (the loaded stack and the pipeline's settings).

    Attributes:
        library: the motion library; control_library: its
            :class:`~gesture_sim.control.inputs.ControlLibrary`; model: the
            :class:`~gesture_sim.inference.model.GestureModel`; policy: the MDP policy (or None);
            graph: the MIMiC graph (or None: built from the library).
        seed, style, p_interrupt, temperature, repeat_cost, repeat_tau_s, sample_state, sync,
            blend_frames, transition: as for :class:`~gesture_sim.pipeline.GesturePipeline`.
        words: timed words known in advance (a transcript; ``chiu14`` reveals them as they
            are said), or None. sign_model: a
            :class:`~gesture_sim.inference.sign_model.SignModel` or its folder (None: the
            shipped one).
    """

    library: object
    control_library: object
    model: object
    policy: object
    graph: object = None
    seed: int = 0
    style: float = 0.5
    p_interrupt: float = 0.1
    temperature: float = DEFAULT_TEMPERATURE
    repeat_cost: float = DEFAULT_REPEAT_COST
    repeat_tau_s: float = DEFAULT_REPEAT_TAU_S
    sample_state: bool = False
    sync: object = None
    blend_frames: int = DEFAULT_BLEND_FRAMES
    transition: str = "ramp"
    words: object = None
    sign_model: object = None


@dataclass(frozen=True)
class MethodSpec:
    """One registered method.

    Attributes:
        name: the ``--method`` name. build: ``Parts -> MotionStage``.
        policy: needs the MDP policy (its semantic labels are the method's labels).
        graph: needs the MIMiC graph. hears: takes speech at all (False: no face signals
            either). timed: behind the timing layer (so ``--transition`` applies). signs:
            predicts Chiu 2014's gestural signs: reads a sign model (``--sign-model``) and
            the words said (``live`` recognises them unless ``--no-words``). doc: one line for
            ``--help``.
    """

    name: str
    build: Callable[[Parts], object]
    policy: bool = False
    graph: bool = False
    hears: bool = True
    timed: bool = True
    signs: bool = False
    doc: str = ""


# The builders import their stages when called, so that the registry itself is cheap to import
# (``--help`` lists it).
def _carry_steps(p: Parts) -> float:
    """The switch ramp's carry (:data:`~gesture_sim.control.ramp.DEFAULT_CARRY_S`) in control
    steps, for the methods with their own timing (the timing layer's is ``sync.carry_s``)."""
    from gesture_sim.control.ramp import DEFAULT_CARRY_S

    carry_s = getattr(p.sync, "carry_s", DEFAULT_CARRY_S)
    return carry_s * p.control_library.fps


def _player(p: Parts, chooser):
    """The timing layer over ``chooser`` with the pipeline's settings and transition."""
    from gesture_sim.control.synchrony import SyncPlayer, SyncSettings
    from gesture_sim.errors import GestureSimError

    if p.transition not in TRANSITIONS:
        raise GestureSimError(f"unknown transition {p.transition!r} "
                              f"(one of {', '.join(TRANSITIONS)})")
    path = None
    if p.transition == "gpdm":
        from gesture_sim.motion.gpdm import GPDMPath, gpdm_for

        path = GPDMPath(gpdm_for(p.library))
    settings = p.sync or SyncSettings(blend_s=p.blend_frames / p.control_library.fps)
    return SyncPlayer(p.control_library, chooser, settings, path=path)


def _timed(chooser_of: Callable[[Parts], object], filter_kind: str = "crf"
           ) -> Callable[[Parts], object]:
    def build(p: Parts):
        from gesture_sim.stages import TimedMotion

        chooser = chooser_of(p)
        return TimedMotion(p.model.new_filter(filter_kind), chooser, _player(p, chooser),
                           p.style)

    return build


def _mdp(p: Parts):
    from gesture_sim.control.controller import GestureController

    return GestureController(p.policy, p.control_library, temperature=p.temperature, seed=p.seed,
                             repeat_cost=p.repeat_cost, repeat_tau_s=p.repeat_tau_s,
                             sample_state=p.sample_state)


def _planned(settings_of: Callable[[Parts], object]) -> Callable[[Parts], object]:
    """Speech known ahead: the planner over the controller's stage (its filter, its labels;
    every step causal when no speech is known ahead)."""
    def build(p: Parts):
        from gesture_sim.control.planner import PlanLibrary, PlannedPlayer
        from gesture_sim.stages import PlannedMotion

        causal = _timed(_mdp)(p)
        cfg = settings_of(p)
        eta = None
        if p.policy is not None and getattr(p.policy, "eta", None) is not None:
            tones = list(getattr(p.policy, "tones", ()))
            eta = p.policy.eta[tones.index("neutral") if "neutral" in tones else 0]
        lib = PlanLibrary.from_control_library(p.control_library, eta,
                                               prominence=cfg.peak_prominence)
        from dataclasses import replace

        player = PlannedPlayer(p.control_library, causal.chooser, energy_gain=cfg.energy_gain,
                               settings=replace(p.sync or causal.player.cfg,
                                                blend_s=cfg.blend_s),
                               path=causal.player.path)
        return PlannedMotion(causal, player, lib, cfg,
                             new_filter=lambda: p.model.new_filter("crf"))

    return build


def _plan_settings(unbent: bool = False, **changes) -> Callable[[Parts], object]:
    """The planner's settings (:class:`~gesture_sim.control.planner.PlanSettings`) of a row:
    the defaults, ``unbent`` without the nudge, with ``changes``."""
    def settings(p: Parts):
        from dataclasses import replace

        from gesture_sim.control.planner import PlanSettings

        cfg = PlanSettings().unbent() if unbent else PlanSettings()
        return replace(cfg, **changes)

    return settings


def _mimic(p: Parts):
    from gesture_sim.control.inputs import StateModel
    from gesture_sim.control.mimic import MimicChooser, build_graph

    graph = p.graph if p.graph is not None else build_graph(p.control_library)
    return MimicChooser(graph, p.control_library, seed=p.seed,
                        model=StateModel.from_inference(p.model))


def _random_chooser(p: Parts):
    from gesture_sim.control.baselines import RandomChooser

    return RandomChooser(p.control_library, p.control_library.n_interrupts + 1, seed=p.seed,
                         p_interrupt=p.p_interrupt)


def _levine09(p: Parts):
    from gesture_sim.inference.levine09_synthesis import Levine09Synthesis
    from gesture_sim.stages import SyllableMotion

    synth = Levine09Synthesis(p.model.baseline, p.control_library, seed=p.seed,
                              allowed=p.control_library.cospeech, state_model=p.model,
                              motion_library=p.library, section_blend_frames=p.blend_frames)
    return SyllableMotion(synth, p.style, p.blend_frames, _carry_steps(p))


def _random(p: Parts):
    from gesture_sim.control.baselines import RandomSelector
    from gesture_sim.stages import SelectorMotion

    selector = RandomSelector(p.control_library, seed=p.seed, p_interrupt=p.p_interrupt)
    return SelectorMotion(p.model.new_filter("crf"), selector, p.style, p.blend_frames,
                          _carry_steps(p))


def _chiu14(p: Parts):
    """Chiu 2014: the sign filter over 1-s frames -> a segment of the predicted sign -> the
    timing layer (:mod:`gesture_sim.control.sign_chooser`)."""
    import numpy as np

    from gesture_sim.control.sign_chooser import SignChooser
    from gesture_sim.inference.sign_model import SignModel, default_sign_model_dir
    from gesture_sim.stages import TimedMotion

    model = p.sign_model
    if not isinstance(model, SignModel):
        model = SignModel.load(model if model is not None else default_sign_model_dir())
    n = p.control_library.n_segments
    stored = model.segment_signs or {}
    fp = str(getattr(p.library, "fingerprint", ""))
    if stored.get("fingerprint") == fp and len(stored.get("signs", ())) == n:
        signs = list(stored["signs"])
    elif getattr(p.library, "segments", None) is not None and len(p.library.segments) == n:
        from gesture_sim.motion.signs import library_signs

        signs = library_signs(p.library)[0]
    else:
        signs = ["Beats"] * n
    chooser = SignChooser(p.control_library, signs, stay=np.diag(model.transition_matrix()),
                          frame_s=model.layout.frame_s, seed=p.seed)
    return TimedMotion(model.new_filter(p.words), chooser, _player(p, chooser), p.style)


#: Every method, in the order ``--help`` lists them.
REGISTRY: dict[str, MethodSpec] = {s.name: s for s in (
    MethodSpec("controller", _timed(_mdp), policy=True,
               doc="CRF belief -> MDP policy -> timing layer (the product)"),
    MethodSpec("dcnf", _timed(_mdp, "dcnf"), policy=True,
               doc="the controller with Chiu 2014's DCNF as the belief filter"),
    MethodSpec("mimic", _timed(_mimic), graph=True,
               doc="Okwechime 2011's MIMiC motion graph behind the timing layer"),
    MethodSpec("levine09", _levine09, timed=False,
               doc="Levine 2009: prosody HMM selection with its own timing"),
    MethodSpec("random", _random, hears=False, timed=False,
               doc="uniformly random co-speech segments, no speech input"),
    MethodSpec("random_sync", _timed(_random_chooser),
               doc="random choice behind the timing layer"),
    MethodSpec("planned", _planned(_plan_settings()), policy=True,
               doc="speech known ahead: real segments planned so that their own strokes "
                   "fall on the stressed syllables and accents (live: the controller)"),
    MethodSpec("planned_noprior", _planned(_plan_settings(prior_weight=0.0)), policy=True,
               doc="ablation: the planner without the inference layer's belief prior"),
    MethodSpec("planned_unbent", _planned(_plan_settings(unbent=True)), policy=True,
               doc="ablation: the planner without the nudge (rate 1, no holds, no gain)"),
    MethodSpec("chiu14", _chiu14,
               doc="Chiu 2014: speech -> gestural signs (1-s frames) -> a segment of the "
                   "sign, behind the timing layer", signs=True),
)}
METHODS: tuple[str, ...] = tuple(REGISTRY)


def methods_where(**flags: bool) -> tuple[str, ...]:
    """The registered methods whose :class:`MethodSpec` fields equal ``flags`` (e.g.
    ``methods_where(signs=True)``), in registry order: for messages that list them."""
    return tuple(n for n, s in REGISTRY.items()
                 if all(getattr(s, k) == want for k, want in flags.items()))


def serves_labels(spec: MethodSpec) -> bool:
    """Whether the method can play semantic gestures (``--label``, keywords): those with the
    MDP policy (its labels) or the MIMiC graph (its segments' tags)."""
    return spec.policy or spec.graph


def no_labels_note(method: str | None, library: object) -> str | None:
    """Why a method serves no semantic labels, naming the library's (``library``: anything with
    ``segments`` whose items have ``tags``), for messages about a label it cannot play, e.g.
    ``"--method random serves no semantic labels (this library has 9: beckon, ...;
    controller, dcnf, mimic serve them)"``; None for a method that serves them (or an unknown
    name): the message then names the labels the run has."""
    if method is None or method not in REGISTRY or serves_labels(REGISTRY[method]):
        return None
    tags = sorted({t for s in getattr(library, "segments", ()) or () for t in
                   getattr(s, "tags", ()) if t})
    serving = ", ".join(n for n, s in REGISTRY.items() if serves_labels(s))
    has = f"this library has {len(tags)}: {', '.join(tags)}" if tags else \
        "this library has none either"
    return f"--method {method} serves no semantic labels ({has}; {serving} serve them)"


def method_spec(name: str) -> MethodSpec:
    """The registered method ``name``; one clear error for an unknown one."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise GestureSimError(
            f"unknown method {name!r}; choose one of {', '.join(METHODS)}") from None
