"""Training the inference layer from motion + speech pairs (Gesture Controllers §6.1).

Per pair: the motion is retargeted onto the humanoid, segmented into gesture phases and given
its six kinematic parameters exactly as the motion library does
(:mod:`gesture_sim.motion.segmentation`, :mod:`gesture_sim.motion.kinematics`); the speech goes
through the causal prosody tracker. Then, over all pairs:

1. the speaker normaliser is seeded on all training syllables; per-step inputs X (n, 3) come
   from the causal :func:`~gesture_sim.inference.features.step_inputs`, outputs Y (n, 6) from
   the segment playing at each step;
2. the prosody mixture (K clusters) is fitted to X;
3. the number of HMM states is chosen by held-out likelihood (last 25 % of each take held out),
   then the HMM is refitted on everything; its posteriors γ, ξ are fixed;
4. the CRF is trained against them (window W);
5. the Levine 2009 baseline is counted over the same states;
6. optionally (``TrainSettings.dcnf``) the DCNF of Chiu 2014 is trained against the same
   posteriors (:func:`fit_dcnf_to_hmm`).

Large data. Up to ``TrainSettings.exact_steps`` steps (:data:`EXACT_TRAINING_STEPS`, 10 minutes
at 30 Hz) training runs exactly as described. Above it, three things change so that an hour of
corpus trains in minutes (BENCHMARKS.md, "Training cost"): the prosody mixture is
fitted on ``sample_steps`` steps drawn at random, the number of states is chosen on
contiguous blocks of at most ``sample_steps`` training steps drawn across the takes
(:func:`selection_subsample`; the held-out tails of those takes score it), and the CRF's
objective runs over all sequences at once (:class:`~gesture_sim.inference.crf.BatchedChains`,
the same objective up to rounding). The final HMM is fitted on all steps with ``hmm_restarts``
restarts as below the threshold, unless ``large_hmm_restarts`` asks for another number (2 saves
35–40 CPU s at 30 minutes but lost 0.077 nats per step of training likelihood there).
The summary has a ``large_data_path`` entry (what was subsampled) only when that path ran.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, Syllable
from gesture_sim.errors import GestureSimError
from gesture_sim.inference import fitlog
from gesture_sim.inference.clusters import ProsodyClusters, fit_clusters
from gesture_sim.inference.crf import fit_crf, window_features
from gesture_sim.inference.dcnf import DCNFSettings, dcnf_inputs, fit_dcnf_selected, pad_input
from gesture_sim.inference.features import (
    StepSettings,
    step_inputs,
    step_outputs,
    step_segment_index,
)
from gesture_sim.inference.hmm import KinematicHMM, choose_n_states, fit_hmm
from gesture_sim.inference.levine09 import train_levine09
from gesture_sim.inference.model import GestureModel, make_normalizer


@dataclass
class MotionTake:
    """A segmented motion take.

    Attributes:
        fps: frame rate (Hz).
        n_frames: number of frames.
        segments: (m, 2) frame ranges ``[start, end)``.
        raw_params: (m, 6) raw kinematic parameters (SI units, see motion.kinematics).
        source: where it came from.
        qpos: (n_frames, n_joints) the retargeted joint angles (rad; m for slides), columns
            ``joint_names``: what the Levine 2009 baseline's head and lower-body sections are
            segmented from (``None``: the one-stream baseline).
        joint_names: the columns of ``qpos``.
    """

    fps: float
    n_frames: int
    segments: np.ndarray
    raw_params: np.ndarray
    source: str = ""
    qpos: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()


@dataclass
class TrainingTake:
    """One motion + speech pair, reduced to what training needs."""

    motion: MotionTake
    syllables: list[Syllable]
    audio_duration_s: float
    name: str = ""

    @property
    def duration_s(self) -> float:
        """The span covered by both motion and audio (s)."""
        return min(self.motion.n_frames / self.motion.fps, self.audio_duration_s)


@dataclass
class TrainSettings:
    """Hyperparameters of training."""

    n_states: int | None = None              # None: choose by held-out likelihood
    state_candidates: tuple[int, ...] = (3, 4, 5, 6, 8, 10)
    n_clusters: int = 8
    window: int = 4
    hmm_restarts: int = 4
    crf_l2: float = 1.0
    crf_max_iter: int = 400
    held_out_fraction: float = 0.25
    seed: int = 0
    steps: StepSettings = field(default_factory=StepSettings)
    dcnf: bool = False                       # also train the DCNF (Chiu 2014)
    dcnf_settings: DCNFSettings = field(default_factory=DCNFSettings)
    exact_steps: int | None = None           # None: EXACT_TRAINING_STEPS
    sample_steps: int = 18000                # large data: subsample for clusters, state choice
    large_hmm_restarts: int | None = None    # large data: final HMM's restarts (None: as above)


#: Above this many training steps (10 minutes at 30 Hz) training takes the large-data path
#: (module docstring); at or below it, the exact path (the shipped model: about 1900 steps).
EXACT_TRAINING_STEPS = 18000
#: Shortest block (steps, 30 s at 30 Hz) of the state-count choice's subsample.
SELECTION_MIN_BLOCK = 900


#: Motion and speech of one pair may differ by this share of the longer one (and by 1 s).
PAIR_MISMATCH_SHARE = 0.1


def check_pair_duration(motion_s: float, audio_s: float, what: str) -> None:
    """Refuse a pair whose motion and speech (durations in s) differ by more than
    :data:`PAIR_MISMATCH_SHARE` of the longer one and 1 s: they are not recordings of the same
    take. ``what`` names the pair in the error."""
    if abs(motion_s - audio_s) > max(1.0, PAIR_MISMATCH_SHARE * max(motion_s, audio_s)):
        raise GestureSimError(
            f"{what}: the motion lasts {motion_s:.1f} s but the speech {audio_s:.1f} s; a pair "
            "must be the motion and speech of the same take")


def load_motion_take(path: str | Path, segmentation: Any = None) -> MotionTake:
    """Read a BVH or SMPL-X npz, retarget it and segment it as the motion library does."""
    from gesture_sim.motion.kinematics import raw_parameters
    from gesture_sim.motion.retarget import KEYPOINTS, Retargeter, heading_frame
    from gesture_sim.motion.segmentation import segment_clip

    path = Path(path)
    if not path.is_file():
        raise GestureSimError(f"motion file not found: {path}")
    retargeter = Retargeter()
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        from gesture_sim.motion.bvh import read_bvh

        motion = read_bvh(path)
    elif suffix == ".npz":
        from gesture_sim.motion.smplx import humanoid_rest_offsets, read_smplx

        motion = read_smplx(path, humanoid_rest_offsets(retargeter.model))
    else:
        raise GestureSimError(f"unsupported motion file {path} (expected .bvh or SMPL-X .npz)")
    res = retargeter.retarget(motion)
    hands = [KEYPOINTS.index("left_hand"), KEYPOINTS.index("right_hand")]
    world = res.keypoints[:, hands]
    hand_pos = heading_frame(res.root_pos, res.root_quat, world)
    hand_height = world[..., 2]
    segs = np.array(segment_clip(hand_pos, res.fps, segmentation), dtype=int).reshape(-1, 2)
    if len(segs) < 2:
        raise GestureSimError(f"motion {path} is too short or too still to segment")
    raw = raw_parameters(hand_pos, hand_height, res.fps, segs)
    return MotionTake(float(res.fps), int(len(hand_pos)), segs, raw, str(path),
                      qpos=np.asarray(res.qpos, dtype=np.float32),
                      joint_names=tuple(retargeter.joint_names))


def motion_take_from_analysis(analysis: Any, source: str = "") -> MotionTake:
    """The training take of a motion file already analysed for a library
    (:class:`~gesture_sim.motion.build.ClipAnalysis`: retargeted, resampled to the library's
    rate, segmented and parametrised), so that one reading of the file feeds both the library
    and the inference layer. For a source at the library's frame rate this is exactly what
    :func:`load_motion_take` gives for the file (both cut the same hand key points in the
    heading frame); at another rate the analysis has been resampled and the take follows it.

    Raises:
        GestureSimError: fewer than two segments (as :func:`load_motion_take`).
    """
    segs = np.asarray(analysis.segments, dtype=int).reshape(-1, 2)
    name = source or analysis.clip.name
    if len(segs) < 2:
        raise GestureSimError(f"motion {name} is too short or too still to segment")
    return MotionTake(float(analysis.clip.fps), int(analysis.clip.n_frames), segs,
                      np.asarray(analysis.raw, dtype=float), name,
                      qpos=np.asarray(analysis.clip.qpos, dtype=np.float32),
                      joint_names=tuple(analysis.joint_names))


def load_pair(motion_path: str | Path, audio_path: str | Path,
              motion: MotionTake | None = None) -> TrainingTake:
    """Motion take + causal prosody of its speech; ``motion``: the take already made (e.g. by
    :func:`motion_take_from_analysis`), so the motion file is not read again."""
    from gesture_sim.audio.prosody import analyze_file

    motion = motion if motion is not None else load_motion_take(motion_path)
    analysis = analyze_file(audio_path)
    return TrainingTake(motion, list(analysis.syllables), len(analysis.samples) / SAMPLE_RATE,
                        name=Path(audio_path).stem)


@dataclass
class PreparedTake:
    """Per-step arrays of one take."""

    x: np.ndarray            # (n, 3) prosody features
    y: np.ndarray            # (n, 6) normalised kinematic parameters
    seg_index: np.ndarray    # (n,) segment playing at each step
    params: np.ndarray       # (m, 6) normalised parameters per segment
    take: TrainingTake


def prepare_takes(
    takes: Sequence[TrainingTake], settings: StepSettings, normalizer_seed: dict,
    param_normalisation: dict,
) -> list[PreparedTake]:
    """X and Y per take; the normaliser starts from the seed for each take and adapts online."""
    from gesture_sim.motion.kinematics import normalise

    out = []
    for take in takes:
        n = int(np.floor(take.duration_s * settings.rate_hz))
        x = step_inputs(take.syllables, n, make_normalizer(normalizer_seed), settings)
        params = normalise(take.motion.raw_params, param_normalisation)
        y = step_outputs(take.motion.segments, params, take.motion.fps, n, settings.rate_hz)
        idx = step_segment_index(take.motion.segments, take.motion.fps, n, settings.rate_hz)
        out.append(PreparedTake(x, y, idx, params, take))
    return out


def data_fingerprint(prepared: Sequence[PreparedTake], settings: StepSettings) -> str:
    """16 hex digits of sha256 over the per-step X, Y and the step settings."""
    h = hashlib.sha256(repr(sorted(settings.to_dict().items())).encode())
    for p in prepared:
        h.update(np.ascontiguousarray(np.nan_to_num(p.x, nan=-999.0)).tobytes())
        h.update(np.ascontiguousarray(p.y).tobytes())
    return h.hexdigest()[:16]


def split_held_out(arrays: Sequence[np.ndarray], fraction: float) -> tuple[list, list]:
    """First ``1 - fraction`` of each sequence for training, the rest held out."""
    train, held = [], []
    for a in arrays:
        cut = int(round(len(a) * (1.0 - fraction)))
        train.append(a[:cut])
        held.append(a[cut:])
    return train, held


def selection_subsample(
    train: Sequence[np.ndarray], held_out: Sequence[np.ndarray], max_steps: int, seed: int = 0,
    min_block: int = SELECTION_MIN_BLOCK,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Contiguous blocks of at most ``max_steps`` training steps in all, drawn across the takes.

    Each block has ``max(min_block, max_steps // len(train))`` steps (a whole training part
    when shorter) at a random offset in its take's training part; the takes are spread evenly
    over the list (all of them when the budget allows). The held-out parts returned are those
    of the takes used, whole. Deterministic for a seed.
    """
    n = len(train)
    block = max(int(min_block), int(max_steps) // max(n, 1))
    n_use = min(n, max(1, int(max_steps) // block))
    chosen = np.unique(np.round(np.linspace(0, n - 1, n_use)).astype(int))
    rng = np.random.default_rng(seed)
    sub_train, sub_held = [], []
    for i in chosen:
        y = train[i]
        if len(y) > block:
            start = int(rng.integers(0, len(y) - block + 1))
            y = y[start:start + block]
        sub_train.append(y)
        sub_held.append(held_out[i])
    return sub_train, sub_held


def fit_crf_to_hmm(
    hmm: KinematicHMM, clusters: ProsodyClusters, prepared: Sequence[PreparedTake],
    settings: StepSettings, window: int, l2: float, max_iter: int, batched: bool = False,
):
    """CRF trained against the HMM posteriors of ``prepared`` takes; returns (crf, info).

    ``batched``: the large-data objective (:func:`~gesture_sim.inference.crf.fit_crf`)."""
    pad = clusters.membership(settings.silence())
    phis, gammas, xis = [], [], []
    for p in prepared:
        g, xi, _ = hmm.posteriors(p.y)
        phis.append(window_features(clusters.memberships(p.x), window, pad))
        gammas.append(g)
        xis.append(xi)
    return fit_crf(phis, gammas, xis, l2=l2, max_iter=max_iter, batched=batched)


def fit_dcnf_to_hmm(
    hmm: KinematicHMM, clusters: ProsodyClusters, prepared: Sequence[PreparedTake],
    settings: StepSettings, dcnf_settings: DCNFSettings | None = None,
):
    """DCNF trained against the HMM posteriors of ``prepared`` takes; returns (dcnf, info).

    Its number of Adam steps is chosen on the last 25 % of each take, then it is refitted on
    all of them (:func:`~gesture_sim.inference.dcnf.fit_dcnf_selected`).
    """
    silence = settings.silence()
    pad = pad_input(silence, clusters.membership(silence))
    inputs = [dcnf_inputs(p.x, clusters.memberships(p.x), silence) for p in prepared]
    return fit_dcnf_selected(inputs, [p.y for p in prepared], hmm, pad, dcnf_settings)


def segment_labels(hmm: KinematicHMM, prepared: PreparedTake) -> np.ndarray:
    """HMM state holding most posterior mass over each segment's steps (m,)."""
    gamma, _, _ = hmm.posteriors(prepared.y)
    m = len(prepared.take.motion.segments)
    mass = np.zeros((m, hmm.n_states))
    np.add.at(mass, prepared.seg_index, gamma)
    labels = mass.argmax(axis=1)
    # Segments with no step (past the end of the audio): the state that best explains them.
    empty = mass.sum(axis=1) == 0
    if np.any(empty):
        labels[empty] = hmm.emission_log_likelihood(prepared.params[empty]).argmax(axis=1)
    return labels


def levine09_sections(prepared: Sequence[PreparedTake], rate_hz: float, baseline: Any
                      ) -> dict | None:
    """The Levine 2009 head and lower-body sections
    (:func:`~gesture_sim.inference.levine09_sections.train_sections`) over the same syllables
    as ``baseline`` (its discretiser statistics), when every take's motion carries its joint
    angles (``motion.qpos`` (T, n_joints) and ``motion.joint_names``); None otherwise (the
    one-stream model)."""
    motions = [p.take.motion for p in prepared]
    if not motions or any(getattr(m, "qpos", None) is None or not getattr(m, "joint_names", ())
                          for m in motions):
        return None
    from gesture_sim.inference.levine09_sections import train_sections

    return train_sections(
        [p.take.syllables for p in prepared], [np.asarray(m.qpos) for m in motions],
        tuple(motions[0].joint_names), [m.fps for m in motions], rate_hz,
        [len(p.y) / rate_hz for p in prepared], baseline.stats, baseline.silence_chunk_s)


def train_model(
    takes: Sequence[TrainingTake], settings: TrainSettings | None = None,
    param_normalisation: dict | None = None, library_fingerprint: str | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> GestureModel:
    """Train the whole inference layer; see the module docstring.

    Args:
        takes: training pairs.
        settings: hyperparameters (defaults when ``None``).
        param_normalisation: the motion library's ``{"names", "B", "W"}``; fitted on the
            training segments when ``None``.
        library_fingerprint: recorded with the model when a library's normalisation is used.
        on_stage: called with a short description as each stage starts (progress display).
    """
    from gesture_sim.inference.normalize import SpeakerNormalizer
    from gesture_sim.motion.kinematics import fit_normalisation

    cfg = settings or TrainSettings()
    stage = on_stage or (lambda _s: None)
    if not takes:
        raise GestureSimError("training needs at least one motion/audio pair")
    t0 = time.perf_counter()
    all_syllables = [s for t in takes for s in t.syllables]
    if len(all_syllables) < 20:
        raise GestureSimError(
            f"the training speech has only {len(all_syllables)} syllables; need at least 20")
    seed = SpeakerNormalizer.from_syllables(all_syllables).to_dict()
    if param_normalisation is None:
        raw = np.concatenate([t.motion.raw_params for t in takes])
        param_normalisation = fit_normalisation(raw)
    stage("per-step features")
    prepared = prepare_takes(takes, cfg.steps, seed, param_normalisation)
    n_steps = int(sum(len(p.y) for p in prepared))
    exact_steps = EXACT_TRAINING_STEPS if cfg.exact_steps is None else cfg.exact_steps
    large = n_steps > exact_steps
    stage(f"prosody clusters (K={cfg.n_clusters})")
    x_all = np.concatenate([p.x for p in prepared])
    if large and len(x_all) > cfg.sample_steps:
        rows = np.random.default_rng(cfg.seed).choice(len(x_all), cfg.sample_steps,
                                                      replace=False)
        x_fit = x_all[np.sort(rows)]
    else:
        x_fit = x_all
    clusters = fit_clusters(x_fit, cfg.n_clusters, seed=cfg.seed)
    ys = [p.y for p in prepared]
    curve: dict[int, float] = {}
    with fitlog.collect() as em_fits:   # EM's convergence reports, counted, not printed
        if cfg.n_states is None:
            train_y, held_y = split_held_out(ys, cfg.held_out_fraction)
            if large:
                train_y, held_y = selection_subsample(train_y, held_y, cfg.sample_steps,
                                                      seed=cfg.seed)
            stage(f"choosing HMM states among {list(cfg.state_candidates)}")
            n_states, curve = choose_n_states(train_y, held_y, cfg.state_candidates,
                                              n_restarts=max(1, cfg.hmm_restarts - 1),
                                              seed=cfg.seed)
        else:
            n_states = cfg.n_states
        stage(f"kinematic HMM (S={n_states})")
        restarts = (cfg.large_hmm_restarts if large and cfg.large_hmm_restarts is not None
                    else cfg.hmm_restarts)
        hmm, hmm_ll = fit_hmm(ys, n_states, n_restarts=restarts, seed=cfg.seed)
    stage(f"remapped CRF (W={cfg.window})")
    crf, info = fit_crf_to_hmm(hmm, clusters, prepared, cfg.steps, cfg.window, cfg.crf_l2,
                               cfg.crf_max_iter, batched=large)
    stage("Levine 2009 baseline")
    baseline = train_levine09(
        [p.take.syllables for p in prepared], [p.take.motion.segments for p in prepared],
        [segment_labels(hmm, p) for p in prepared], n_states,
        [p.take.motion.fps for p in prepared],
        cfg.steps.rate_hz, [len(p.y) / cfg.steps.rate_hz for p in prepared],
        silence_chunk_s=cfg.steps.silence_hold_s,
    )
    baseline.sections = levine09_sections(prepared, cfg.steps.rate_hz, baseline)
    dcnf = None
    if cfg.dcnf:
        stage(f"DCNF (W={cfg.dcnf_settings.window}, layers {list(cfg.dcnf_settings.hidden)})")
        dcnf, dcnf_info = fit_dcnf_to_hmm(hmm, clusters, prepared, cfg.steps, cfg.dcnf_settings)
    summary = {
        "pairs": [p.take.name or p.take.motion.source for p in prepared],
        "steps": n_steps,
        "seconds_of_data": n_steps / cfg.steps.rate_hz,
        "segments": int(sum(len(p.take.motion.segments) for p in prepared)),
        "syllables": len(all_syllables),
        "states": n_states,
        "clusters": cfg.n_clusters,
        "window": cfg.window,
        "held_out_loglik_per_step": {str(k): v for k, v in curve.items()},
        "hmm_train_loglik_per_step": hmm_ll / n_steps,
        "hmm_em_fits": em_fits.to_dict(),
        "crf_objective_per_step": info.objective_per_step,
        "crf_iterations": info.iterations,
        "crf_converged": info.converged,
        "training_seconds": time.perf_counter() - t0,
    }
    if large:
        summary["large_data_path"] = {
            "exact_steps": exact_steps, "cluster_fit_steps": len(x_fit),
            "selection_train_steps": int(sum(len(y) for y in train_y)) if curve else None,
            "selection_held_out_steps": int(sum(len(y) for y in held_y)) if curve else None,
            "hmm_restarts": restarts, "crf_batched": True}
    if dcnf is not None:
        summary["dcnf"] = {"iterations": dcnf_info.iterations,
                           "objective_per_step": dcnf_info.objective_per_step,
                           "valid_loglik_per_step": dcnf_info.valid_loglik_per_step,
                           "seconds": dcnf_info.seconds}
    return GestureModel(
        hmm=hmm, clusters=clusters, crf=crf, settings=cfg.steps, normalizer_seed=seed,
        param_normalisation=param_normalisation,
        fingerprint=data_fingerprint(prepared, cfg.steps), baseline=baseline,
        library_fingerprint=library_fingerprint, summary=summary, dcnf=dcnf,
    )
