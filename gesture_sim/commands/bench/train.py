"""``gesture-sim bench train``: what training costs at 5, 15, 30 and 60 minutes of corpus.

Builds, for each asked length, a synthetic corpus from the real motion/speech pairs given with
``--pair`` (for cost only, not for quality) and trains everything on it, timing each stage and
measuring its peak memory: import (read + retarget + prosody), segmentation, HMM (state choice +
fit), CRF, successor costs, MDP solve, policy pruning, and the controller's per-decision cost with
the resulting library (median and p99).

The synthetic corpus. The real inputs are read, retargeted and their speech analysed once; the
corpus is then made in memory at the level of retargeted clips: each synthetic clip is a real
clip time-warped by a factor drawn in [0.8, 1.25] (linear interpolation of joint angles, root
position and key points; normalised-lerp of the root quaternion), every second one mirrored
left/right (the world reflected through the x-z plane, left and right key points swapped;
joint-angle columns of left/right joints swapped without their sign conventions: cost only), and
re-paired with the given speech: the syllable streams of the real recordings, concatenated with
time offsets (rotating through the recordings) and cut to the clip's length. The last clip is
cut so that the corpus has the asked length (to a frame).

Import stage. Read + retarget and prosody are timed on the real files and scaled linearly to the
corpus length (both are per file and linear in its length; writing and re-reading warped copies
would add the same per-second cost). Its peak memory is that of importing the real inputs.

Memory. Each length runs in a fresh subprocess (``--in-process`` to skip that); before each
stage the process's resident-set high-water mark is reset (``/proc/self/clear_refs``, Linux) and
read after it (``VmHWM``), so a stage's figure is the process's peak RSS during that stage,
including what earlier stages still hold. Where the reset is not available the figure is the
process's peak so far (``ru_maxrss``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gesture_sim.commands import print_json

#: Stages measured per corpus length, in order (keys of the ``stages`` dict of each row).
STAGES = ("import", "segmentation", "hmm", "crf", "inference_other", "successor_costs", "mdp",
          "pruning")
#: Environment variables that set the BLAS / OpenMP thread count of a worker.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: Time-warp factors are drawn uniformly in this range (1.25 = the clip plays 25 % slower).
WARP_RANGE = (0.8, 1.25)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train", help="training time and peak memory per stage at 5/15/30/60 min of corpus",
        description=__doc__.split("\n\n")[1])
    p.add_argument("--pair", nargs=2, action="append", metavar=("MOTION", "AUDIO"),
                   required=True, help="a real motion file (.npz / .bvh) and its speech (.wav); "
                                       "repeat for more")
    p.add_argument("--minutes", type=float, nargs="+", default=[5.0, 15.0, 30.0, 60.0],
                   help="corpus lengths in minutes (default: 5 15 30 60)")
    p.add_argument("--states", type=int, default=None,
                   help="HMM states (default: chosen by held-out likelihood, as `train` does)")
    p.add_argument("--decisions", type=int, default=2000, help="controller decisions to time")
    p.add_argument("--seed", type=int, default=0, help="seed of the warps and the re-pairing")
    p.add_argument("--threads", type=int, default=1,
                   help="BLAS/OpenMP threads of each length's subprocess (default 1: one core)")
    p.add_argument("--in-process", action="store_true",
                   help="run every length in this process (peak memory then accumulates; the "
                        "thread count is then this process's)")
    p.add_argument("--figure", metavar="PNG", default=None,
                   help="also draw time and memory of each stage against corpus length")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- memory
def _reset_peak() -> bool:
    """Reset the resident-set high-water mark of this process (Linux >= 4.0); False if not."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _peak_mb() -> float:
    """Peak resident set (MB) since the last :func:`_reset_peak` (or since the start)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class _Meter:
    """Times stages and records each one's peak RSS (see the module docstring)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.cpu_seconds: dict[str, float] = {}
        self.peak_mb: dict[str, float] = {}
        self.resettable = _reset_peak()
        self._name: str | None = None
        self._t0 = 0.0
        self._c0 = 0.0

    def start(self, name: str) -> None:
        self.stop()
        if self.resettable:
            _reset_peak()
        self._name, self._t0, self._c0 = name, time.perf_counter(), time.process_time()

    def stop(self) -> None:
        if self._name is None:
            return
        self.seconds[self._name] = self.seconds.get(self._name, 0.0) + (
            time.perf_counter() - self._t0)
        self.cpu_seconds[self._name] = self.cpu_seconds.get(self._name, 0.0) + (
            time.process_time() - self._c0)
        self.peak_mb[self._name] = max(self.peak_mb.get(self._name, 0.0), _peak_mb())
        self._name = None


# ----------------------------------------------------------------------------- the corpus
@dataclass
class SourceClip:
    """A retargeted real clip (world frame) at the library frame rate.

    Attributes:
        name: file stem.
        fps: frame rate (Hz).
        qpos: (T, J) joint angles (rad / m), columns ``joint_names``.
        root_pos: (T, 3) pelvis position (m); root_quat: (T, 4) orientation (w, x, y, z).
        keypoints: (T, K, 3) world key points (m), order of
            :data:`gesture_sim.motion.retarget.KEYPOINTS`.
    """

    name: str
    fps: float
    qpos: np.ndarray
    root_pos: np.ndarray
    root_quat: np.ndarray
    keypoints: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(len(self.qpos))


@dataclass
class Speech:
    """The syllables of one real recording and its length (s)."""

    syllables: list
    duration_s: float


@dataclass
class SyntheticTake:
    """One clip of the synthetic corpus and the speech paired with it.

    Attributes:
        clip: the warped (and maybe mirrored) clip.
        syllables: the re-paired speech's syllables, times from the clip's start (s).
        source: index of the real clip; factor: time-warp factor; mirrored: whether mirrored.
    """

    clip: SourceClip
    syllables: list
    source: int
    factor: float
    mirrored: bool


def _swap_lr(names: tuple[str, ...] | list[str]) -> np.ndarray:
    """Permutation of ``names`` that swaps each ``left``/``right`` name with its twin."""
    index = {n: i for i, n in enumerate(names)}
    perm = np.arange(len(names))
    for i, n in enumerate(names):
        for a, b in (("left", "right"), ("right", "left"), ("l_", "r_"), ("r_", "l_")):
            if a in n:
                twin = n.replace(a, b, 1)
                if twin in index:
                    perm[i] = index[twin]
                break
    return perm


def mirror_clip(clip: SourceClip, joint_names: tuple[str, ...]) -> SourceClip:
    """The clip reflected through the world x-z plane (y -> -y), left and right swapped.

    Key points and the root are mirrored exactly (a point p -> diag(1, -1, 1) p; a rotation
    R -> M R M, i.e. the quaternion (w, x, y, z) -> (w, -x, y, -z)); the joint-angle columns of
    left/right joints are only swapped (their sign conventions are not mirrored: cost only).
    """
    from gesture_sim.motion.retarget import KEYPOINTS

    m = np.array([1.0, -1.0, 1.0])
    kp = clip.keypoints[:, _swap_lr(KEYPOINTS)] * m
    quat = clip.root_quat * np.array([1.0, -1.0, 1.0, -1.0])
    return replace(clip, name=clip.name + "_mirror", qpos=clip.qpos[:, _swap_lr(joint_names)],
                   root_pos=clip.root_pos * m, root_quat=quat, keypoints=kp)


def warp_clip(clip: SourceClip, factor: float) -> SourceClip:
    """The clip resampled to ``round(factor * T)`` frames (``factor`` > 1 plays slower).

    Linear interpolation of joint angles, root position and key points; the root quaternion is
    interpolated linearly (hemisphere-aligned) and renormalised.
    """
    n = clip.n_frames
    m = max(2, int(round(factor * n)))
    t = np.linspace(0.0, n - 1, m)
    i0 = np.minimum(np.floor(t).astype(np.int64), n - 2)
    w = (t - i0)

    def lerp(x: np.ndarray) -> np.ndarray:
        ww = w.reshape((-1,) + (1,) * (x.ndim - 1))
        return (1.0 - ww) * x[i0] + ww * x[i0 + 1]

    q0, q1 = clip.root_quat[i0], clip.root_quat[i0 + 1]
    q1 = np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0, -q1, q1)
    q = (1.0 - w[:, None]) * q0 + w[:, None] * q1
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return replace(clip, name=f"{clip.name}_w{factor:.3f}", qpos=lerp(clip.qpos),
                   root_pos=lerp(clip.root_pos), root_quat=q, keypoints=lerp(clip.keypoints))


def cut_clip(clip: SourceClip, n_frames: int) -> SourceClip:
    """The first ``n_frames`` frames of a clip."""
    return replace(clip, qpos=clip.qpos[:n_frames], root_pos=clip.root_pos[:n_frames],
                   root_quat=clip.root_quat[:n_frames], keypoints=clip.keypoints[:n_frames])


def repaired_speech(speech: list[Speech], first: int, seconds: float) -> list:
    """Syllables of the recordings ``first, first+1, ...`` (cyclically) played back to back and
    cut to ``seconds`` (a syllable ending after the cut is dropped)."""
    out = []
    t = 0.0
    j = first
    while t < seconds:
        sp = speech[j % len(speech)]
        for s in sp.syllables:
            if t + s.t_end > seconds:
                break
            out.append(replace(s, t_start=s.t_start + t, t_end=s.t_end + t,
                               t_emitted=s.t_emitted + t))
        t += sp.duration_s
        j += 1
    return out


def synthetic_corpus(sources: list[SourceClip], speech: list[Speech], joint_names: tuple[str, ...],
                     seconds: float, seed: int = 0) -> list[SyntheticTake]:
    """Clips of total length ``seconds`` (to one frame) made from the real ``sources``.

    Clip j warps source ``j mod len(sources)`` by a factor drawn uniformly in
    :data:`WARP_RANGE`, mirrors every second pass over the sources, and pairs it with the speech
    starting at recording ``j mod len(speech)``; the last clip is cut to the remaining length
    (never shorter than 2 s: then the one before is lengthened by it).
    """
    from gesture_sim.errors import GestureSimError

    if not sources or not speech:
        raise GestureSimError("the synthetic corpus needs at least one motion and one speech")
    fps = sources[0].fps
    target = int(round(seconds * fps))
    rng = np.random.default_rng(seed)
    takes: list[SyntheticTake] = []
    total = 0
    j = 0
    while total < target:
        src = j % len(sources)
        mirrored = (j // len(sources)) % 2 == 1
        factor = float(rng.uniform(*WARP_RANGE))
        clip = sources[src]
        if mirrored:
            clip = mirror_clip(clip, joint_names)
        clip = warp_clip(clip, factor)
        left = target - total
        if clip.n_frames > left:
            clip = cut_clip(clip, left)
        if clip.n_frames < 2 * fps and takes:          # too short: fold into the previous one
            takes[-1] = _lengthen(takes[-1], clip.n_frames, joint_names, speech)
            total += clip.n_frames
            break
        takes.append(SyntheticTake(clip=replace(clip, name=f"synthetic_{j:04d}_{clip.name}"),
                                   syllables=repaired_speech(speech, j, clip.n_frames / fps),
                                   source=src, factor=factor, mirrored=mirrored))
        total += clip.n_frames
        j += 1
    return takes


def _lengthen(take: SyntheticTake, extra: int, joint_names: tuple[str, ...],
              speech: list[Speech]) -> SyntheticTake:
    """The take with ``extra`` frames more (its clip extended by a slower warp)."""
    clip = take.clip
    n = clip.n_frames + extra
    longer = warp_clip(clip, n / clip.n_frames)
    longer = cut_clip(longer, n) if longer.n_frames > n else longer
    return replace(take, clip=replace(longer, name=clip.name),
                   syllables=repaired_speech(speech, take.source, longer.n_frames / clip.fps))


# ----------------------------------------------------------------------------- one length
def import_sources(pairs: list[tuple[str, str]], fps: float = 30.0
                   ) -> tuple[list[SourceClip], list[Speech], tuple[str, ...], dict[str, float]]:
    """Read, retarget and analyse the real pairs.

    Returns:
        the clips, the speech, the humanoid's joint names and the timings
        ``{"motion_s", "speech_s", "seconds_of_motion"}`` (s).
    """
    from gesture_sim.audio.prosody import analyze_file
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.motion.build import read_motion
    from gesture_sim.motion.retarget import Retargeter
    from gesture_sim.motion.skeleton import resample

    t0 = time.perf_counter()
    rt = Retargeter()
    clips = []
    for motion_path, _ in pairs:
        res = rt.retarget(resample(read_motion(motion_path, rt.model), fps))
        clips.append(SourceClip(
            name=os.path.splitext(os.path.basename(motion_path))[0], fps=fps,
            qpos=np.asarray(res.qpos, float), root_pos=np.asarray(res.root_pos, float),
            root_quat=np.asarray(res.root_quat, float),
            keypoints=np.asarray(res.keypoints, float)))
    t1 = time.perf_counter()
    speech = []
    for _, audio_path in pairs:
        a = analyze_file(audio_path)
        speech.append(Speech(list(a.syllables), len(a.samples) / SAMPLE_RATE))
    t2 = time.perf_counter()
    seconds = float(sum(c.n_frames for c in clips) / fps)
    return clips, speech, tuple(rt.joint_names), {
        "motion_s": t1 - t0, "speech_s": t2 - t1, "seconds_of_motion": seconds}


def segment_corpus(takes: list[SyntheticTake], joint_names: tuple[str, ...]):
    """Segment and parametrise the corpus as :func:`~gesture_sim.motion.build.build_library`
    does, and make the inference layer's training takes.

    Returns:
        (MotionLibrary, list of :class:`~gesture_sim.inference.train.TrainingTake`).
    """
    from gesture_sim.inference.train import MotionTake, TrainingTake
    from gesture_sim.motion.kinematics import (
        fit_normalisation,
        interruption_frames,
        normalise,
        raw_parameters,
    )
    from gesture_sim.motion.library import Clip, MotionLibrary, Segment
    from gesture_sim.motion.retarget import heading_frame
    from gesture_sim.motion.segmentation import SegmentationSettings, segment_clip

    settings = SegmentationSettings()
    clips, ranges, raws, train_takes = [], [], [], []
    for t in takes:
        c = t.clip
        kp = heading_frame(c.root_pos, c.root_quat, c.keypoints)
        segs = segment_clip(kp[:, :2], c.fps, settings)
        raw = raw_parameters(kp[:, :2], kp[:, :2, 2], c.fps, segs)
        ranges.append(segs)
        raws.append(raw)
        clips.append(Clip(name=c.name, fps=c.fps, qpos=c.qpos.astype(np.float32),
                          root_pos=c.root_pos.astype(np.float32),
                          root_quat=c.root_quat.astype(np.float32), source="synthetic",
                          licence="CC BY-NC 4.0", keypoints=kp.astype(np.float32)))
        motion = MotionTake(c.fps, c.n_frames, np.asarray(segs, int).reshape(-1, 2), raw, c.name)
        train_takes.append(TrainingTake(motion, t.syllables, c.n_frames / c.fps, name=c.name))
    norm = fit_normalisation(np.concatenate(raws))
    segments = []
    for ci, (segs, raw) in enumerate(zip(ranges, raws, strict=True)):
        params = normalise(raw, norm)
        first = len(segments)
        for k, (a, b) in enumerate(segs):
            segments.append(Segment(
                index=first + k, clip=ci, start=a, end=b, params=params[k].astype(np.float32),
                predecessor=first + k - 1 if k > 0 else -1,
                successor=first + k + 1 if k < len(segs) - 1 else -1,
                interrupt_frames=interruption_frames(b - a)))
    lib = MotionLibrary(fps=clips[0].fps, joint_names=joint_names, clips=clips,
                        segments=segments, param_normalisation=norm)
    return lib, train_takes


def measure_length(pairs: list[tuple[str, str]], minutes: float, states: int | None = None,
                   decisions: int = 2000, seed: int = 0,
                   on_stage: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Build and train everything on a synthetic corpus of ``minutes``; one result row.

    Returns:
        ``{"minutes", "corpus_s", "clips", "segments", "states", "stages": {name: {"seconds",
        "peak_mb"}}, "total_s", "peak_mb", "decision_ms_median", "decision_ms_p99", ...}``.
    """
    from gesture_sim.control.controller import GestureController
    from gesture_sim.control.inputs import ControlLibrary, StateModel
    from gesture_sim.inference.train import TrainSettings, train_model
    from gesture_sim.loading import train_library_policy

    tell = on_stage or (lambda _s: None)
    meter = _Meter()
    tell("import")
    meter.start("import")
    sources, speech, joints, imp = import_sources(pairs)
    meter.stop()
    takes = synthetic_corpus(sources, speech, joints, minutes * 60.0, seed)
    corpus_s = sum(t.clip.n_frames for t in takes) / sources[0].fps
    scale = corpus_s / imp["seconds_of_motion"]
    tell("segmentation")
    meter.start("segmentation")
    library, train_takes = segment_corpus(takes, joints)
    meter.stop()

    # inference: on_stage marks the stage boundaries inside train_model
    inference_stage = {"per-step": "inference_other", "prosody clusters": "inference_other",
                       "choosing HMM": "hmm", "kinematic HMM": "hmm", "remapped CRF": "crf",
                       "Levine 2009": "inference_other", "DCNF": "inference_other"}

    def on_inference(text: str) -> None:
        name = next((v for k, v in inference_stage.items() if text.startswith(k)),
                    "inference_other")
        tell(name)
        meter.start(name)

    cfg = TrainSettings(n_states=states, seed=seed)
    model = train_model(train_takes, cfg, param_normalisation=library.param_normalisation,
                        library_fingerprint=library.fingerprint, on_stage=on_inference)
    meter.stop()

    tell("successor_costs")
    meter.start("successor_costs")
    lib = ControlLibrary.from_motion_library(library)
    state_model = StateModel.from_inference(model)
    meter.stop()
    tell("mdp")
    meter.start("mdp")              # the policy's own timings split this into its stages below
    policy = train_library_policy(lib, state_model)
    meter.stop()
    t_mdp = meter.seconds.pop("mdp")
    c_mdp = meter.cpu_seconds.pop("mdp")
    peak_policy = meter.peak_mb.pop("mdp")
    succ = float(policy.meta.get("successor_seconds", 0.0))
    table = float(policy.meta["table_seconds"])
    busy = c_mdp / max(t_mdp, 1e-9)         # the policy's share of a core, to split its CPU time
    meter.seconds["successor_costs"] += succ
    meter.seconds["mdp"] = t_mdp - succ - table
    meter.seconds["pruning"] = table
    meter.cpu_seconds["successor_costs"] += succ * busy
    meter.cpu_seconds["mdp"] = (t_mdp - succ - table) * busy
    meter.cpu_seconds["pruning"] = table * busy
    meter.peak_mb["mdp"] = meter.peak_mb["pruning"] = peak_policy
    meter.peak_mb["successor_costs"] = max(meter.peak_mb["successor_costs"], peak_policy)

    # the import: the real inputs' cost, scaled to the corpus
    meter.seconds["import"] = (imp["motion_s"] + imp["speech_s"]) * scale
    meter.cpu_seconds["import"] *= scale

    tell("controller")
    ctl = GestureController(policy, lib)
    rng = np.random.default_rng(seed)
    pts = np.argwhere(np.diff(policy.offsets[0]) > 0)[:, 0]
    pick = pts[rng.integers(len(pts), size=decisions)]
    beliefs = rng.dirichlet(np.ones(policy.n_states), size=decisions)
    times = np.empty(decisions)
    for i, (j, b) in enumerate(zip(pick, beliefs, strict=True)):
        seg, k = divmod(int(j), policy.n_points)
        t0 = time.perf_counter()
        ctl.decide_at(b, seg, k, 0.0)
        times[i] = time.perf_counter() - t0
    stages = {name: {"seconds": float(meter.seconds.get(name, 0.0)),
                     "cpu_seconds": float(meter.cpu_seconds.get(name, 0.0)),
                     "peak_mb": float(meter.peak_mb.get(name, 0.0))} for name in STAGES}
    return {
        "minutes": minutes, "corpus_s": corpus_s, "clips": len(takes),
        "segments": lib.n_segments, "states": state_model.n_states,
        "labels": len(policy.labels) - 1, "tones": len(policy.tones),
        "syllables": int(sum(len(t.syllables) for t in takes)),
        "stages": stages, "total_s": float(sum(s["seconds"] for s in stages.values())),
        "total_cpu_s": float(sum(s["cpu_seconds"] for s in stages.values())),
        "peak_mb": float(max(s["peak_mb"] for s in stages.values())),
        "peak_reset_per_stage": meter.resettable,
        "import_measured": {**imp, "scale": scale},
        "mdp_iterations": policy.meta["iterations"],
        "pruned_fraction": policy.meta["pruned_fraction"],
        "successor_kept_fraction": policy.meta.get("successor_kept_fraction", 1.0),
        "decision_ms_median": float(np.median(times) * 1e3),
        "decision_ms_p99": float(np.percentile(times, 99) * 1e3),
    }


# ----------------------------------------------------------------------------- driver
def _worker(argv: list[str]) -> int:
    """``python -m gesture_sim.commands.bench.train --worker JSON``: one length.

    Prints one JSON line on stdout: the result row, or ``{"error": MESSAGE}`` (exit 2) when the
    run fails; it never prints a traceback. It ends with its parent, however the parent ends
    (:func:`gesture_sim.interrupt.end_with_parent`): nobody is left to read its result.
    """
    import signal

    from gesture_sim import interrupt
    from gesture_sim.errors import GestureSimError

    spec = json.loads(argv[0])
    for s in (signal.SIGINT, signal.SIGTERM):   # the parent decides; a signal ends it quietly
        signal.signal(s, signal.SIG_DFL)
    interrupt.end_with_parent(int(spec.get("parent_pid", os.getppid())))
    try:
        row: dict[str, Any] = _measure_with_bar(spec)
        code = 0
    except GestureSimError as exc:
        row, code = {"error": " ".join(str(exc).split())}, 2
    except MemoryError:
        row, code = {"error": "out of memory"}, 2
    except Exception as exc:  # noqa: BLE001 - reported to the parent as one line
        first = (str(exc).splitlines() or [""])[0][:300]
        row, code = {"error": f"internal error: {type(exc).__name__}: {first}"}, 1
    try:
        sys.stdout.write(json.dumps(row) + "\n")
        sys.stdout.flush()
    except (BrokenPipeError, OSError):   # the parent is gone: nobody to tell
        os._exit(1)
    return code


def _measure_with_bar(spec: dict) -> dict[str, Any]:
    """:func:`measure_length` with a progress bar over its stages (on stderr)."""
    from gesture_sim.progress import progress

    names = (*STAGES[:-1], "controller")     # pruning is timed inside the MDP stage
    with progress(total=len(names), desc=f"{spec['minutes']:g} min", unit="stage") as bar:
        seen: list[str] = []

        def tell(name: str) -> None:
            if name not in seen:
                seen.append(name)
                bar.set_description(f"{spec['minutes']:g} min: {name}")
                bar.update(1)

        return measure_length([tuple(p) for p in spec["pairs"]], spec["minutes"],
                              spec["states"], spec["decisions"], spec["seed"], on_stage=tell)


def _in_subprocess(spec: dict) -> dict:
    """One length in a fresh interpreter (:func:`_worker`); its row, or GestureSimError.

    The worker runs in its own session (a terminal's Ctrl-C reaches this process only, whose
    interruption kills it on the way out) and ends with this process if it is killed outright.
    """
    from gesture_sim.errors import GestureSimError

    env = dict(os.environ)
    for var in THREAD_VARIABLES:
        env[var] = str(spec.get("threads", 1))
    spec = {**spec, "parent_pid": os.getpid()}
    proc = subprocess.run([sys.executable, "-m", "gesture_sim.commands.bench.train", "--worker",
                           json.dumps(spec)], stdout=subprocess.PIPE, text=True, check=False,
                          env=env, start_new_session=True)
    lines = proc.stdout.strip().splitlines()
    try:
        row = json.loads(lines[-1]) if lines else None
    except ValueError:
        row = None
    where = f"bench train: the run at {spec['minutes']:g} min"
    if isinstance(row, dict) and "error" in row:
        raise GestureSimError(f"{where} failed: {row['error']}")
    if proc.returncode != 0 or not isinstance(row, dict):
        how = (f"was ended by signal {-proc.returncode}" if proc.returncode < 0
               else f"failed (exit {proc.returncode})")
        raise GestureSimError(f"{where} {how}")
    return row


def check_inputs(pairs: list[tuple[str, str]]) -> None:
    """Every ``--pair`` readable and of one take, before any work: the files exist, the motion
    reads and the audio decodes, and their durations agree as ``train`` demands
    (:func:`gesture_sim.inference.train.check_pair_duration`)."""
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.commands.train import check_pairs
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.inference.train import check_pair_duration
    from gesture_sim.motion.build import read_motion

    check_pairs("--pair", [list(p) for p in pairs])
    for motion_path, audio_path in pairs:
        motion = read_motion(motion_path)
        samples, _info = load_audio(audio_path)
        check_pair_duration(motion.n_frames / motion.fps, len(samples) / SAMPLE_RATE,
                            f"--pair {motion_path} {audio_path}")


def growth_exponents(rows: list[dict]) -> dict[str, float]:
    """Per stage, the slope of log(seconds) against log(corpus seconds) (1 = linear)."""
    out = {}
    if len(rows) < 2:
        return out
    x = np.log([r["corpus_s"] for r in rows])
    for name in (*STAGES, "total"):
        y = [r["total_s"] if name == "total" else r["stages"][name]["seconds"] for r in rows]
        if min(y) > 0:
            out[name] = float(np.polyfit(x, np.log(y), 1)[0])
    return out


def draw_figure(result: dict, path: str) -> None:
    """Time (log-log) and peak memory of each stage against corpus minutes, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    key = ("cpu_seconds" if rows and all("cpu_seconds" in r["stages"]["hmm"] for r in rows)
           else "seconds")
    x = [r["corpus_s"] / 60.0 for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name in STAGES:
        y = [max(r["stages"][name][key], 1e-3) for r in rows]
        ax1.plot(x, y, "o-", label=name)
        ax2.plot(x, [r["stages"][name]["peak_mb"] for r in rows], "o-", label=name)
    total = [sum(r["stages"][s][key] for s in STAGES) for r in rows]
    ax1.plot(x, total, "k--", lw=2, label="total")
    if x:
        ref = np.array([x[0], x[-1]])
        ax1.plot(ref, total[0] * ref / ref[0], ":", color="gray", label="linear")
    ax1.axhline(900, color="r", lw=0.8)
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xticks(x, [f"{v:g}" for v in x])
    ax1.minorticks_off()
    ax1.set_xlabel("corpus (minutes)")
    ax1.set_ylabel("CPU time, one thread (s)" if key == "cpu_seconds" else "wall time (s)")
    ax1.set_title("time per stage (red: 15 min)")
    ax1.legend(fontsize=7)
    ax2.axhline(4096, color="r", lw=0.8)
    ax2.set_xlabel("corpus (minutes)")
    ax2.set_ylabel("peak RSS during the stage (MB)")
    ax2.set_title("peak memory per stage (red: 4 GB)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v
    from gesture_sim.progress import progress

    pairs = [tuple(p) for p in args.pair]
    figure = None
    if args.figure is not None:
        (figure,) = v.check_outputs([v.Output("--figure", args.figure, v.PNG_EXTENSIONS)],
                                    inputs=[f for p in pairs for f in p])
    check_inputs(pairs)
    rows = []
    for minutes in progress(list(args.minutes), desc="bench train", unit="size"):
        spec = {"pairs": pairs, "minutes": float(minutes), "states": args.states,
                "decisions": args.decisions, "seed": args.seed, "threads": args.threads}
        if args.in_process:
            rows.append(_measure_with_bar(spec))
        else:
            rows.append(_in_subprocess(spec))
    out = {"pairs": [list(p) for p in pairs], "rows": rows,
           "growth_exponents": growth_exponents(rows),
           "memory": ("per stage, fresh subprocess per length" if not args.in_process
                      else "per stage, one process"),
           "threads": None if args.in_process else args.threads}
    if figure is not None:
        from gesture_sim.fileio import atomic_path

        with atomic_path(figure) as tmp:
            draw_figure(out, str(tmp))
    if args.json:
        print_json(out)
        return 0
    print(f"Training at scale: synthetic corpora from {len(pairs)} real pair(s); wall seconds "
          "(peak MB) per stage")
    head = f"{'min':>5} {'segs':>5} " + " ".join(f"{s[:11]:>14}" for s in STAGES)
    print(head + f" {'total s':>8} {'CPU s':>7} {'peak MB':>8} {'decide ms p50/p99':>18}")
    for r in rows:
        cells = " ".join(f"{r['stages'][s]['seconds']:>7.1f} ({r['stages'][s]['peak_mb']:>4.0f})"
                         for s in STAGES)
        print(f"{r['corpus_s'] / 60:>5.1f} {r['segments']:>5} {cells} {r['total_s']:>8.1f} "
              f"{r['total_cpu_s']:>7.1f} {r['peak_mb']:>8.0f} "
              f"{r['decision_ms_median']:>8.3f}/{r['decision_ms_p99']:.3f}")
    ge = out["growth_exponents"]
    if ge:
        print("growth exponent (1 = linear): "
              + ", ".join(f"{k} {v:.2f}" for k, v in ge.items()))
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--worker":
        raise SystemExit(_worker(sys.argv[2:]))
    raise SystemExit("usage: python -m gesture_sim.commands.bench.train --worker JSON")
