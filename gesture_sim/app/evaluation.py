"""Motion-quality evaluation of whole methods on speech files (``gesture-sim eval motion``).

For each method, audio file and seed the simulated body's motion is reduced to joint positions
and scored with :mod:`gesture_sim.metrics.motion` (ENGINEERING_NOTES §7) and a few physics
plausibility figures (:func:`gesture_sim.metrics.physics.physics_metrics`).

Methods (:data:`EVAL_METHODS`):

- ``controller``, ``levine09``, ``random``: the causal pipeline
  (:class:`gesture_sim.pipeline.GesturePipeline`) with physics, fed the file block by block.
- ``real``: the file's own motion capture (``reference``: a BVH or SMPL-X file), retargeted with
  the library's retargeter at 30 fps, legs held at the standing pose as the pipeline does, and
  tracked by the same :class:`~gesture_sim.sim.tracking.HumanoidSim` (same seed rule).
- ``mismatched``: the controller's motion for one file scored against another file's audio
  (the next file given, cyclically, both cut to the shorter; with a single file, the same audio
  rotated by half its length). A control that should score at chance on the audio metrics.

Joint positions (:data:`EVAL_POINTS`, 12 points, metres): pelvis, chest, neck (body origins),
head, shoulders, elbows, wrists and hands (sites of the humanoid contract). They are computed
by forward kinematics of every recorded ``qpos`` row of the trace (100 Hz), expressed in the
pelvis heading frame (origin: the pelvis projected onto the floor, x forward, z up; see
:func:`gesture_sim.motion.retarget.heading_frame`), and linearly interpolated to 30 fps.

Reference ("real") motion for FGD and the speed histograms: the library's co-speech clips
(those whose source is BEAT2; all clips if there are none), posed kinematically on the standing
body (upper-body joint angles of the clip, legs at the standing pose, root upright), i.e. the
real motion as the pipeline would ask the body to play it. The FGD feature extractor
(:class:`~gesture_sim.metrics.motion.FGDExtractor`, PCA, 32 components, 34-frame windows,
pelvis-relative, per-coordinate deviations floored at 2 cm: :func:`fit_extractor`) is fitted
once on *all* clips of the library by ``tools/fit_fgd_extractor.py``
and stored as ``<library>/fgd_extractor.npz``; when that file is missing or belongs to another
library (fingerprint), the same fit is done in memory (deterministic) and the report says so.

Realism beside FGD (:mod:`gesture_sim.metrics.realism`): ``disc_accuracy``, the held-out
accuracy of a small classifier telling 3 s windows of the run from windows of the same real
co-speech motion (0.5 = indistinguishable; runs under 13.5 s scored have too few windows and
leave it out), with the reference's own floor ``disc_accuracy_split`` (real against real); and
``bc_beat2``, beat consistency by the BEAT2 tools' rule (minima above 0.10 of the real motion's
per-point mean speed, 2 s left out at each end; left out when no audio beat is left), beside the
project's ``bc``; both are rows of the eval table (:data:`TABLE_METRICS`).

Beat consistency is averaged over the gesturing points (head, elbows, wrists, hands:
:data:`BEAT_POINTS`); the trunk points move too little for their speed minima to be more than
balance noise. The hand-speed envelope of the prosody coupling is the mean speed of the two hand
sites; intensity (dB) and F0 (Hz, NaN unvoiced) are the prosody tracker's 10 ms frames.
Accent hits − chance subtracts the hit rate of the same hand-speed peaks shifted in time
(:func:`~gesture_sim.metrics.motion.accent_hit_chance`), so it reads timing at any peak density.

The joint positions live in :mod:`gesture_sim.metrics.points`, the reference clips and the FGD
extractor in :mod:`gesture_sim.metrics.reference`, the audio inputs (prosody frames, onsets,
TextGrid stress, the mismatched control, BC's chance level) in :mod:`gesture_sim.metrics.inputs`,
the summaries, verdicts and table in :mod:`gesture_sim.metrics.summary`; the report's files and
plots are the app's (:mod:`gesture_sim.app.report`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import jsonable
from gesture_sim.methods import METHODS, method_spec
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics import realism as rl
from gesture_sim.metrics.inputs import (  # noqa: F401 (re-exported)
    CHANCE_SHIFTS,
    AudioInput,
    bc_chance,
    head_timing,
    load_input,
    prosody_frames,
    rotated,
    stress_timing,
)
from gesture_sim.metrics.points import (
    BEAT_POINTS,
    EVAL_FPS,
    HAND_POINTS,
    POINT_NAMES,
    PointFK,
    trace_positions,
)
from gesture_sim.metrics.reference import (
    FGD_WINDOW,
    clip_positions,
    cospeech_clips,
    legs_zeroed,
    library_windows,
    load_extractor,
    to_actuated,
)
from gesture_sim.metrics.summary import (  # noqa: F401 (re-exported)
    COUPLING_KEYS,
    DECISIVE_KEYS,
    TABLE_METRICS,
    comparisons,
    coupling_verdicts,
    format_table,
    format_verdicts,
    summarise_rows,
)

#: Every method ``evaluate`` knows, in table order.
EVAL_METHODS = (*METHODS, "real", "mismatched")
#: Methods run by default (``real`` only where a reference is given).
DEFAULT_METHODS = ("controller", "levine09", "random", "real", "mismatched")
#: Pipeline methods (run through :class:`~gesture_sim.pipeline.GesturePipeline`).
PIPELINE_METHODS = METHODS
#: The pipeline method the ``mismatched`` condition runs (on another input's audio): the product.
MISMATCHED_METHOD = "controller"
#: The first seconds of every run are not scored: the body moves from the standing rest pose
#: to the first clip's pose there, whatever the method (a start transient, not a gesture).
WARMUP_S = 1.0
#: What the ``bc_beat2`` figure is (``info`` of the JSON report).
BC_BEAT2_INFO = {
    "definition": "PantoMatrix/PantoMatrix emage_evaltools/mertic.py BC + train_emage_audio.py "
                  "evaluation_fn (commit 0bbb03df)",
    "threshold": rl.BEAT2_THRESHOLD, "skip_s": rl.BEAT2_SKIP_S, "sigma_s": rl.BEAT2_SIGMA_S,
    "mean_speed": "per point, of the library's real co-speech motion",
    "points": list(BEAT_POINTS),
}


def disc_layout() -> dict[str, list[int]]:
    """Joint indices (in :data:`POINT_NAMES`) of the discriminator's window features: the
    hands, the other gesturing points of :data:`BEAT_POINTS` and the shoulders (scale)."""
    return {"hands": [POINT_NAMES.index(j) for j in HAND_POINTS],
            "joints": [POINT_NAMES.index(j) for j in BEAT_POINTS if j not in HAND_POINTS],
            "shoulders": [POINT_NAMES.index("left_shoulder"),
                          POINT_NAMES.index("right_shoulder")]}


def reference_mean_speed(reference: Sequence[np.ndarray], fps: float) -> np.ndarray:
    """Per-point mean speed (m/s), ``(J,)``, over all frames of the real clips ``(T_c, J, 3)``
    (speeds per clip, :func:`~gesture_sim.metrics.motion.joint_speeds`); a point at rest in
    all of them gets 1e-6 so that BEAT2 BC's division stays defined."""
    parts = [mm.joint_speeds(c, fps) for c in reference if len(c) >= 2]
    if not parts:
        raise GestureSimError("the library has no real co-speech clip of 2 frames or more")
    return np.maximum(np.concatenate(parts).mean(axis=0), 1e-6)


def disc_info(ev: Evaluator) -> dict[str, Any]:
    """The discriminator's settings and real-side size (``info`` of the JSON report)."""
    return {"window_s": rl.WINDOW_S, "hop_s": rl.HOP_S, "folds": rl.N_FOLDS,
            "min_windows": rl.MIN_WINDOWS, "features": int(ev.real_windows.features.shape[1]),
            "real_windows": len(ev.real_windows), "real": "the library's co-speech clips "
            "(as FGD), posed kinematically on the standing body"}



# ------------------------------------------------------------------------------------------
# Running methods
# ------------------------------------------------------------------------------------------


@dataclass
class MotionRun:
    """The motion of one method on one audio file with one seed.

    Attributes:
        method, audio, seed: what was run (audio: the input's name).
        positions: (K, 12, 3) joint positions (m) at :data:`EVAL_FPS`, pelvis heading frame.
        switch_frames: frames (at 30 fps) where a new segment starts (None for real motion).
        physics: :func:`physics_metrics` figures (dict) of the run.
        run: the pipeline's :class:`~gesture_sim.feed.RunResult` (pipeline methods).
        wall_s: wall-clock seconds of the run.
    """

    method: str
    audio: str
    seed: int
    positions: np.ndarray
    switch_frames: np.ndarray | None
    physics: dict
    run: object | None = None
    wall_s: float = 0.0
    extra: dict = field(default_factory=dict)


def target_switches(library, log) -> np.ndarray:
    """Frames (at 30 fps, from the control-step times) where the target jumps to another place
    in the clips: the played (clip, clip frame) moves backwards or more than two frames ahead of
    the previous step's, or to another clip (rest counts as its own place). Continuing a segment
    at any playback rate, holding, or passing to its successor in the same clip is no switch.
    Shape ``(K,)``."""
    segs = np.asarray(log.segments, dtype=int)
    if len(segs) < 2:
        return np.zeros(0, dtype=int)
    frames = np.asarray(log.frames, dtype=int)
    clip = np.array([library.segments[s].clip if s >= 0 else -1 for s in segs])
    start = np.array([library.segments[s].start if s >= 0 else 0 for s in segs])
    cf = start + frames
    step = cf[1:] - cf[:-1]
    jump = (clip[1:] != clip[:-1]) | (step < 0) | (step > 2)
    times = np.asarray(log.step_times, dtype=float)[1:][jump]
    return np.round(times * EVAL_FPS).astype(int)


class Evaluator:
    """Loads the library, model and policy once, then runs and scores methods.

    Args:
        library: library folder (default: the shipped one); model: model folder (default
            ``<library>/model``).
    """

    def __init__(self, library: str | os.PathLike[str] | None = None,
                 model: str | os.PathLike[str] | None = None, physics: bool = True) -> None:
        from gesture_sim.loading import load_stack

        stack = load_stack(library, model)       # checks that the model fits the library
        #: (library, model) as given: what a worker process of ``evaluate(run_jobs=...)`` loads
        self.source = (library, model)
        self.library_dir = stack.library_dir
        self.library = stack.library
        self.model = stack.model
        self.control_library = stack.control_library
        self.policy = stack.policy
        self._graph = None                         # the MIMiC graph, loaded when first needed
        self.fk = PointFK()
        self.extractor, self.extractor_origin = load_extractor(
            self.library_dir, self.library, self.fk)
        ref_clips = cospeech_clips(self.library)
        self.reference_clips = [self.library.clips[i].name for i in ref_clips]
        self.reference = clip_positions(self.library, self.fk, ref_clips)
        self.reference_fps = float(self.library.fps)
        #: joint indices of the discriminator's window features (:func:`disc_layout`)
        self.disc_layout = disc_layout()
        #: the real co-speech motion's discriminator windows (3 s, hop 1.5 s)
        self.real_windows = rl.window_set(self.reference, self.reference_fps,
                                          **self.disc_layout)
        #: per-point mean speed (m/s) of the real co-speech motion: BEAT2 BC's "dataset" speed
        self.reference_mean_speed = reference_mean_speed(self.reference, self.reference_fps)
        self._retargeter = None
        #: extra keyword arguments for every GesturePipeline (e.g. ``temperature``)
        self.pipeline_options: dict[str, Any] = {}
        #: False: score the kinematic targets on the standing body instead of the simulated
        #: body (fast, for sweeps; physics figures are then absent)
        self.physics = physics

    # -------------------------------------------------------------------- runs
    def run_pipeline(self, method: str, inp: AudioInput, seed: int) -> MotionRun:
        """Run a pipeline method (with physics) on ``inp``."""
        from gesture_sim.feed import run_file
        from gesture_sim.metrics.physics import physics_metrics
        from gesture_sim.pipeline import GesturePipeline

        if method not in PIPELINE_METHODS:
            raise GestureSimError(f"{method!r} is not a pipeline method")
        if method_spec(method).graph and self._graph is None:
            from gesture_sim.control.mimic import load_graph

            self._graph = load_graph(self.control_library, self.library_dir)
        pipe = GesturePipeline(self.library, self.model, self.policy, method=method, seed=seed,
                               physics=self.physics, control_library=self.control_library,
                               graph=self._graph, **self.pipeline_options)
        # decoded once, by load_input
        result = run_file(pipe, y=inp.samples, sr=SAMPLE_RATE, name=str(inp.path),
                          words=inp.words,    # read only by a method that reads words
                          stress=inp.stress)  # or plans ahead
        switches = target_switches(self.library, pipe.log)
        head: dict[str, Any] = {}
        if self.physics:
            trace = pipe.trace()
            pos = trace_positions(trace, self.fk)
            phys = physics_metrics(trace).to_dict()
            head = self._head(pipe, trace, inp.duration)
        else:
            pos = self.fk.standing(np.asarray(pipe.log.targets, dtype=float))
            phys = {}
        segs = np.asarray(pipe.log.segments)
        extra = {"head": head, "selection": {
            "distinct_segments": float(len(np.unique(segs[segs >= 0]))),
            "switches_per_min": 60.0 * len(switches) / max(inp.duration, 1e-9)}}
        return MotionRun(method, inp.name, seed, pos, switches, phys, run=result,
                         wall_s=result.wall, extra=extra)

    def _head(self, pipe: Any, trace: Any, duration: float) -> dict[str, Any]:
        """The simulated head's angular speed (rad/s) at the trace times, and the face
        signals' rates per minute (blinks, nods, brow raises), for :meth:`score`."""
        from gesture_sim.metrics.face import head_speed, signal_kinds
        from gesture_sim.signals.ruth import SIGNAL_JOINTS

        m = pipe.model_mj
        dadr = m.jnt_dofadr[[m.joint(n).id for n in SIGNAL_JOINTS]]
        events = list(getattr(pipe.log, "signals", ()))
        per_min = 60.0 / max(duration, 1e-9)

        kinds = signal_kinds(events)

        def rate(word: str) -> float:
            return per_min * kinds.count(word)

        return {"times": np.asarray(trace.time) - trace.time[0],
                "speed": head_speed(np.asarray(trace.qvel)[:, dadr]),
                "rates": {"blinks_per_min": rate("blink"), "nods_per_min": rate("nod"),
                          "brow_raises_per_min": rate("brow")}}

    def retarget_reference(self, path: str | os.PathLike[str]) -> np.ndarray:
        """Joint targets ``(T, n_act)`` at 30 fps of a motion file, legs at the standing pose."""
        from gesture_sim.motion.build import read_motion
        from gesture_sim.motion.retarget import Retargeter
        from gesture_sim.motion.skeleton import resample

        if self._retargeter is None:
            self._retargeter = Retargeter()
        rt = self._retargeter
        motion = resample(read_motion(path, rt.model), EVAL_FPS)
        result = rt.retarget(motion)
        q = to_actuated(np.asarray(result.qpos, dtype=float), rt.joint_names)
        from gesture_sim.sim.humanoid import ACTUATED_JOINTS

        return legs_zeroed(q, ACTUATED_JOINTS)

    def run_real(self, inp: AudioInput, seed: int, targets: np.ndarray | None = None
                 ) -> MotionRun:
        """Track the input's retargeted motion capture with the same physics."""
        import time

        from gesture_sim.metrics.physics import physics_metrics
        from gesture_sim.sim.targets import TargetStream
        from gesture_sim.sim.tracking import HumanoidSim

        if inp.reference is None:
            raise GestureSimError(f"{inp.name}: no reference motion for the 'real' method")
        t0 = time.perf_counter()
        q = self.retarget_reference(inp.reference) if targets is None else targets
        sim = HumanoidSim(seed=seed)
        sim.reset()
        duration = min(inp.duration, (len(q) - 1) / EVAL_FPS)
        trace = sim.run(TargetStream(q, rate=EVAL_FPS), duration=duration)
        pos = trace_positions(trace, self.fk)
        phys = physics_metrics(trace).to_dict()
        return MotionRun("real", inp.name, seed, pos, None, phys,
                         wall_s=time.perf_counter() - t0)

    # -------------------------------------------------------------------- scores
    def score(self, run: MotionRun, inp: AudioInput, warmup_s: float = WARMUP_S
              ) -> dict[str, float]:
        """Every metric of ``run`` against the audio ``inp`` (cut to the shorter of the two),
        leaving out the first ``warmup_s`` seconds of both (:data:`WARMUP_S`)."""
        k0 = int(round(warmup_s * EVAL_FPS))
        n = min(len(run.positions), int(math.floor(inp.duration * EVAL_FPS)) + 1)
        if n - k0 < 2 * FGD_WINDOW // 2 + 4:
            raise GestureSimError(
                f"{inp.name}: too short to score ({inp.duration:.1f} s; at least "
                f"{warmup_s + 1.3:.1f} s needed)")
        t0 = k0 / EVAL_FPS
        p = run.positions[k0:n]
        n_audio = min(len(inp.samples), int(round(n / EVAL_FPS * SAMPLE_RATE)))
        audio = inp.samples[int(round(t0 * SAMPLE_RATE)):n_audio]
        f0 = inp.f0_hz[int(round(t0 / mm.FRAME_STEP_S)):]
        inten = inp.intensity_db[int(round(t0 / mm.FRAME_STEP_S)):]
        beat = [POINT_NAMES.index(j) for j in BEAT_POINTS]
        hands = [POINT_NAMES.index(j) for j in HAND_POINTS]
        switches = None
        if run.switch_frames is not None:
            switches = [int(f) - k0 for f in run.switch_frames if k0 <= f < n]
        ref = np.concatenate(self.reference) if len(self.reference) > 1 else self.reference[0]
        out = mm.summarise_motion(
            p, EVAL_FPS, audio, upper_body=beat, hands=hands, f0_hz=f0,
            reference=None, switch_frames=switches, window=FGD_WINDOW, root_joint=0,
            seed=run.seed)
        # Audio beats and coupling on the tracker's frames (rather than recomputed envelopes).
        dur = (len(p) - 1) / EVAL_FPS
        onsets = inp.onsets[(inp.onsets >= t0) & (inp.onsets <= t0 + dur)] - t0
        beats = mm.beat_consistency(onsets, EVAL_FPS, positions=p, joints=beat)
        chance = bc_chance(onsets, p, beat, dur)
        out.update(bc=beats.bc, beat_align=beats.beat_align, n_audio_beats=float(onsets.size),
                   motion_beats_per_s=beats.motion_beats_per_s, bc_chance=chance,
                   bc_excess=beats.bc - chance)
        speed = mm.joint_speeds(p, EVAL_FPS)[:, hands].mean(axis=1)
        m = min(len(inten), int(math.floor(dur / mm.FRAME_STEP_S)) + 1)
        c = mm.prosody_coupling(speed, EVAL_FPS, inten[:m], f0[:m])
        if inp.stress is not None:
            out.update(stress_timing(inp.stress - t0, speed, dur))
        head = run.extra.get("head") or {}
        if head and inp.accents is not None:
            keep = (head["times"] >= t0) & (head["times"] <= t0 + dur)
            out.update(head_timing(inp.accents - t0, head["times"][keep] - t0,
                                   head["speed"][keep], dur))
            if run.method != "mismatched":
                out.update(head["rates"])
        out.update(r_intensity=c.r_intensity, r_intensity_best=c.r_intensity_best,
                   lag_intensity_s=c.lag_intensity_s, r_f0d_best=c.r_f0d_best,
                   lag_f0d_s=c.lag_f0d_s, accent_hit_rate=c.accent_hit_rate,
                   accent_hit_excess=c.accent_hit_excess,
                   n_accents=float(c.n_accents))
        # Distribution terms against the library's real co-speech motion.
        own = mm.motion_windows(p, FGD_WINDOW, root_joint=0)
        ref_w = library_windows(self.reference)
        out["hellinger_speed"] = mm.speed_hellinger(p, EVAL_FPS, ref, self.reference_fps)
        if len(own) >= 2:
            out["fgd"] = self.extractor.fgd(own, ref_w)
            out["feature_diversity"] = mm.feature_diversity(self.extractor.transform(own),
                                                            seed=run.seed)
        # Realism: the discriminator against the same real motion (left out below
        # rl.MIN_WINDOWS windows, 13.5 s), and BC by the BEAT2 tools' rule.
        gen = rl.window_set(p, EVAL_FPS, **self.disc_layout)
        if len(gen) >= rl.MIN_WINDOWS and len(self.real_windows) >= rl.MIN_WINDOWS:
            disc = rl.discriminator_accuracy(self.real_windows, gen, seed=run.seed)
            out.update(disc_accuracy=disc.accuracy, disc_windows=float(len(gen)))
        b2 = rl.bc_beat2(onsets, EVAL_FPS, positions=p, joints=beat,
                         mean_speed=self.reference_mean_speed)
        if np.isfinite(b2.bc):
            out.update(bc_beat2=b2.bc, bc_beat2_motion_beats_per_s=b2.motion_beats_per_s)
        ph = run.physics
        for key in ("hand_error_rms_mm", "foot_skate_mm_s", "ground_penetration_max_mm",
                    "min_pelvis_height_ratio"):
            v = ph.get(key)
            out[key] = float("nan") if v is None else float(v)
        out["fell"] = float(bool(ph.get("fell")))
        out.update(run.extra.get("selection", {}))
        return {k: float(v) for k, v in out.items()}

    def reference_figures(self) -> dict[str, float]:
        """The reference motion's own figures (jerk, acceleration, diversity, FGD floor)."""
        ref = np.concatenate(self.reference)
        w = library_windows(self.reference)
        perm = np.random.default_rng(0).permutation(len(w))
        half = len(w) // 2
        return {
            "mean_jerk": mm.mean_jerk(ref, self.reference_fps),
            "mean_acceleration": mm.mean_acceleration(ref, self.reference_fps),
            "l1div": mm.l1_diversity(ref - ref[:, :1]),
            "feature_diversity": mm.feature_diversity(self.extractor.transform(w), seed=0),
            "fgd_split_half": self.extractor.fgd(w[perm[:half]], w[perm[half:]]),
            "windows": float(len(w)),
            "disc_accuracy_split": rl.real_split_accuracy(
                self.reference, self.reference_fps, **self.disc_layout).accuracy,
            "disc_windows": float(len(self.real_windows)),
        }


# ------------------------------------------------------------------------------------------
# A whole evaluation
# ------------------------------------------------------------------------------------------


@dataclass
class EvalResult:
    """Rows of scores and their summary.

    Attributes:
        rows: one dict per (audio, method, seed): ``audio``, ``method``, ``seed``, ``wall_s``
            and ``metrics`` (name -> float).
        inputs: per audio: name, path, duration_s, reference (or None).
        methods, seeds: what was run. reference: the reference motion's own figures.
        runs: the :class:`MotionRun` of seed 0 per (audio, method), for plots (not in JSON).
        info: extractor origin, reference clips, points. timing: seconds.
        reference_positions: the real co-speech motion (list of (T, 12, 3)), for plots.
    """

    rows: list[dict]
    inputs: list[dict]
    methods: list[str]
    seeds: list[int]
    reference: dict[str, float]
    runs: dict[tuple[str, str], MotionRun] = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    timing: dict = field(default_factory=dict)
    reference_positions: list[np.ndarray] = field(default_factory=list)

    def summary(self) -> dict[str, dict[str, dict[str, float]]]:
        """Per method and metric: ``mean``, ``sd`` (over all seeds and files), ``seed_sd`` (the
        mean over files of the sd over seeds: the seed spread) and ``n``."""
        return summarise_rows(self.rows, self.methods)

    def to_dict(self) -> dict:
        return jsonable({
            "methods": self.methods, "seeds": self.seeds, "inputs": self.inputs,
            "summary": self.summary(), "reference": self.reference, "info": self.info,
            "timing": self.timing, "rows": self.rows,
            "comparisons": comparisons(self.summary()),
            "verdicts": coupling_verdicts(self.summary()),
        })


def match_references(audio: Sequence[str | os.PathLike[str]],
                     references: Sequence[str | os.PathLike[str]],
                     kind: str = "motion") -> dict[int, Path]:
    """Pair each reference file (a motion, or a TextGrid with ``kind="TextGrid"``) with an
    audio file: by equal file stem, or, with a single audio and a single reference, with each
    other. Returns ``{audio index: path}``."""
    refs = [Path(r) for r in references]
    for r in refs:
        if not r.is_file():
            raise GestureSimError(f"{r}: no such {kind} file")
    option = "--textgrid" if kind == "TextGrid" else "--reference"
    if len(audio) == 1 and len(refs) == 1:
        return {0: refs[0]}
    if len(audio) == 1 and len(refs) > 1:
        raise GestureSimError(
            f"{option}: {len(refs)} {kind} files ({', '.join(r.name for r in refs[:3])}"
            f"{', ...' if len(refs) > 3 else ''}) for the one audio file {Path(audio[0]).name}; "
            f"give one {option} per audio file")
    stems = [Path(a).stem for a in audio]
    out: dict[int, Path] = {}
    for r in refs:
        if r.stem not in stems:
            raise GestureSimError(
                f"reference {r.name} matches no audio file by name (expected one of "
                f"{', '.join(s + '.*' for s in stems)})")
        i = stems.index(r.stem)
        if i in out:
            raise GestureSimError(
                f"{option}: {out[i]} and {r} are both for {Path(audio[i]).name}; give one "
                f"{option} per audio file")
        out[i] = r
    return out


def evaluate(
    audio: Sequence[str | os.PathLike[str]], references: Sequence[str | os.PathLike[str]] = (),
    methods: Sequence[str] = DEFAULT_METHODS, seeds: int | Sequence[int] = 3,
    evaluator: Evaluator | None = None, on_step: Callable[[str], None] | None = None,
    textgrids: Sequence[str | os.PathLike[str]] = (),
    run_jobs: Callable[[list[tuple[str, Callable[..., Any], tuple]],
                        Callable[[int, Any], None]], list[Any]] | None = None,
    in_worker: Callable[[MotionRun], None] | None = None,
) -> EvalResult:
    """Run every method on every audio file with every seed and score them.

    Args:
        audio: speech files. references: motion files paired by :func:`match_references`
            (they enable ``real`` on their audio). textgrids: word/phone alignments paired the
            same way (they add the stroke-to-stress timing figures).
        methods: subset of :data:`EVAL_METHODS`; ``mismatched`` reuses the controller's runs.
        seeds: a count (seeds 0 .. N-1) or explicit seeds.
        evaluator: a loaded :class:`Evaluator` (built with the default library otherwise).
        on_step: called with a short description after each run (progress bar).
        run_jobs: run the (method, seed, file) runs elsewhere (``eval --jobs``/``--dask``):
            called once with ``[(label, fn, args), ...]`` and ``on_done(index, value)`` (to be
            called here as each finishes), it returns ``[fn(*args), ...]`` in that order
            (raising on a failure). Each call is :func:`run_job`, which loads its own
            :class:`Evaluator` once per process and returns the run; the runs are scored here,
            as they arrive, by ``evaluator`` (so the figures do not depend on the workers'
            BLAS threads). The rows are the same as a serial run's (same seeds), only
            ``wall_s`` and the timing differ, and the runs carry no pipeline
            (``MotionRun.run`` is None).
        in_worker: with ``run_jobs``, called in the worker with each first-seed pipeline run
            while its pipeline is still attached (e.g. to draw its timeline figure).
    """
    import time

    unknown = [m for m in methods if m not in EVAL_METHODS]
    if unknown:
        raise GestureSimError(f"unknown method {unknown[0]!r}; choose from "
                              f"{', '.join(EVAL_METHODS)}")
    if not audio:
        raise GestureSimError("no audio files to evaluate")
    seed_list = list(range(int(seeds))) if isinstance(seeds, (int, np.integer)) else list(seeds)
    if not seed_list:
        raise GestureSimError("at least one seed is needed")
    t_start = time.perf_counter()
    ev = evaluator or Evaluator()
    t_loaded = time.perf_counter()
    refs = match_references(audio, references)
    grids = match_references(audio, textgrids, kind="TextGrid")
    import hashlib

    names: list[str] = []
    inputs: list[AudioInput] = []
    sources: list[tuple] = []      # load_input's arguments of each input (for run_jobs)
    seen: dict[str, str] = {}
    skipped: list[str] = []
    for i, a in enumerate(audio):
        inp = load_input(a, refs.get(i), grids.get(i))
        digest = hashlib.sha1(np.ascontiguousarray(inp.samples).tobytes()).hexdigest()
        if digest in seen and inp.reference is None:
            skipped.append(f"{a} (same audio as {seen[digest]})")
            continue
        seen.setdefault(digest, str(a))
        base, k = inp.name, 2
        while inp.name in names:
            inp.name = f"{base}_{k}"
            k += 1
        names.append(inp.name)
        inputs.append(inp)
        sources.append((a, refs.get(i), grids.get(i)))
    methods = [m for m in EVAL_METHODS if m in methods]
    rows: list[dict] = []
    runs: dict[tuple[str, str], MotionRun] = {}
    controller_runs: dict[tuple[str, int], MotionRun] = {}
    for inp in inputs if run_jobs is None else ():
        real_targets = None
        for method in methods:
            if method in ("mismatched",):
                continue
            if method == "real":
                if inp.reference is None:
                    continue
                if real_targets is None:
                    real_targets = ev.retarget_reference(inp.reference)
            for seed in seed_list:
                if method == "real":
                    run = ev.run_real(inp, seed, real_targets)
                elif method == MISMATCHED_METHOD and (inp.name, seed) in controller_runs:
                    run = controller_runs[(inp.name, seed)]
                else:
                    run = ev.run_pipeline(method, inp, seed)
                if method == MISMATCHED_METHOD:
                    controller_runs[(inp.name, seed)] = run
                rows.append({"audio": inp.name, "method": method, "seed": seed,
                             "wall_s": run.wall_s, "metrics": ev.score(run, inp)})
                if seed == seed_list[0]:
                    runs[(inp.name, method)] = run
                if on_step:
                    on_step(f"{inp.name} {method} seed {seed}")
    if run_jobs is not None:
        _run_parallel(ev, inputs, sources, methods, seed_list, run_jobs, in_worker, on_step,
                      rows, runs, controller_runs)
    if "mismatched" in methods:
        for i, inp in enumerate(inputs):
            other = inputs[(i + 1) % len(inputs)] if len(inputs) > 1 else rotated(
                inp, f"{inp.name}_rotated")
            for seed in seed_list:
                run = controller_runs.get((inp.name, seed))
                if run is None:
                    run = ev.run_pipeline(MISMATCHED_METHOD, inp, seed)
                    controller_runs[(inp.name, seed)] = run
                mis = MotionRun("mismatched", inp.name, seed, run.positions, run.switch_frames,
                                run.physics, wall_s=0.0,
                                extra={**run.extra, "audio_scored": other.name})
                rows.append({"audio": inp.name, "method": "mismatched", "seed": seed,
                             "scored_against": other.name, "wall_s": 0.0,
                             "metrics": ev.score(mis, other)})
                if seed == seed_list[0]:
                    runs[(inp.name, "mismatched")] = mis
                if on_step:
                    on_step(f"{inp.name} mismatched seed {seed}")
    present = [m for m in methods if any(r["method"] == m for r in rows)]
    return EvalResult(
        rows=rows,
        inputs=[{"name": x.name, "path": str(x.path), "duration_s": x.duration,
                 "reference": str(x.reference) if x.reference else None,
                 "n_onsets": int(x.onsets.size)} for x in inputs],
        methods=present, seeds=seed_list, reference=ev.reference_figures(), runs=runs,
        info={"points": list(POINT_NAMES), "beat_points": list(BEAT_POINTS),
              "hand_points": list(HAND_POINTS), "fps": EVAL_FPS,
              "fgd_extractor": ev.extractor_origin, "reference_clips": ev.reference_clips,
              "library": str(ev.library_dir), "warmup_s": WARMUP_S,
              "skipped_duplicates": skipped, "discriminator": disc_info(ev),
              "bc_beat2": BC_BEAT2_INFO},
        timing={"load_s": t_loaded - t_start, "total_s": time.perf_counter() - t_start,
                "audio_s": float(sum(x.duration for x in inputs))},
        reference_positions=list(ev.reference),
    )


def _run_parallel(ev: Evaluator, inputs: list[AudioInput], sources: list[tuple],
                  methods: list[str], seed_list: list[int], run_jobs: Callable[..., list[Any]],
                  in_worker: Callable[[MotionRun], None] | None,
                  on_step: Callable[[str], None] | None, rows: list[dict],
                  runs: dict[tuple[str, str], MotionRun],
                  controller_runs: dict[tuple[str, int], MotionRun]) -> None:
    """:func:`evaluate`'s runs through ``run_jobs``: the same runs, rows in the same order."""
    plan: list[tuple[int, str, int, bool]] = []   # (input, method, seed, makes a row)
    for i, inp in enumerate(inputs):
        for method in methods:
            if method == "mismatched" or (method == "real" and inp.reference is None):
                continue
            plan += [(i, method, seed, True) for seed in seed_list]
    if "mismatched" in methods and MISMATCHED_METHOD not in methods:
        plan += [(i, MISMATCHED_METHOD, seed, False) for i in range(len(inputs))
                 for seed in seed_list]
    calls = []
    for i, method, seed, shown in plan:
        hook = in_worker if (shown and seed == seed_list[0] and method in PIPELINE_METHODS) \
            else None
        calls.append((f"{inputs[i].name} {method} seed {seed}", run_job,
                      (ev.source, ev.physics, dict(ev.pipeline_options), *sources[i],
                       inputs[i].name, method, seed, hook)))

    scores: dict[int, dict[str, float]] = {}

    def done(k: int, run: MotionRun) -> None:
        if plan[k][3]:
            scores[k] = ev.score(run, inputs[plan[k][0]])   # here, while the workers go on
            if on_step:
                on_step(calls[k][0])

    results = run_jobs(calls, done)
    for k, ((i, method, seed, shown), run) in enumerate(zip(plan, results, strict=True)):
        inp = inputs[i]
        if method == MISMATCHED_METHOD:
            controller_runs[(inp.name, seed)] = run
        if not shown:
            continue
        rows.append({"audio": inp.name, "method": method, "seed": seed,
                     "wall_s": run.wall_s, "metrics": scores[k]})
        if seed == seed_list[0]:
            runs[(inp.name, method)] = run


#: A worker process's loaded evaluators, inputs and retargeted references (:func:`run_job`).
_WORKER_CACHE: dict[tuple, Any] = {}


def run_job(source: tuple, physics: bool, pipeline_options: dict,
            audio: str | os.PathLike[str], reference: str | os.PathLike[str] | None,
            textgrid: str | os.PathLike[str] | None, name: str, method: str, seed: int,
            in_worker: Callable[[MotionRun], None] | None = None) -> MotionRun:
    """One (method, seed, file) run of :func:`evaluate` in a worker process.

    The :class:`Evaluator` (``source`` = (library, model), ``physics``), the loaded input and the
    retargeted reference motion are loaded once per process; ``in_worker(run)`` is called while
    the run still has its pipeline. Returns the run without it (``run.run`` is None: the
    pipeline does not leave the process)."""
    key = ("evaluator", repr(source), bool(physics))
    if key not in _WORKER_CACHE:
        _WORKER_CACHE[key] = Evaluator(*source, physics=physics)
    ev: Evaluator = _WORKER_CACHE[key]
    ev.pipeline_options = dict(pipeline_options)
    ikey = ("input", str(audio), str(reference), str(textgrid))
    if ikey not in _WORKER_CACHE:
        _WORKER_CACHE[ikey] = load_input(audio, reference, textgrid)
    inp: AudioInput = _WORKER_CACHE[ikey]
    inp.name = name
    if method == "real":
        rkey = ("targets", key, str(reference))
        if rkey not in _WORKER_CACHE:
            _WORKER_CACHE[rkey] = ev.retarget_reference(inp.reference)
        run = ev.run_real(inp, seed, _WORKER_CACHE[rkey])
    else:
        run = ev.run_pipeline(method, inp, seed)
    if in_worker is not None and run.run is not None:
        in_worker(run)
    run.run = None
    return run


def n_runs(n_audio: int, n_with_reference: int, methods: Sequence[str], n_seeds: int) -> int:
    """Number of ``on_step`` calls :func:`evaluate` will make (for a progress bar)."""
    per = sum(1 for m in methods if m in PIPELINE_METHODS + ("mismatched",))
    return n_seeds * (per * n_audio + (n_with_reference if "real" in methods else 0))
