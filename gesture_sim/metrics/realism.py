"""Realism and beat figures beside FGD: a real-vs-generated discriminator and BEAT2's BC.

Same conventions as :mod:`gesture_sim.metrics.motion`: joint positions ``(T, J, 3)`` in metres
at ``fps`` frames per second, frame ``i`` at ``i / fps`` s; times in seconds.

1. :func:`discriminator_accuracy`: how well a small classifier tells windows of real
   co-speech motion from windows of a generated motion, scored on held-out windows.
   0.5 means the two cannot be told apart (by these features, with this much data); 1.0 means
   every held-out window is classified right.

   - **Windows**: :data:`WINDOW_S` (3 s) long, every :data:`HOP_S` (1.5 s), cut from each
     motion separately (a window never spans two clips).
   - **Features** (:func:`window_features`, :data:`FEATURE_NAMES`, 22 per window), mostly
     scale-free: for each hand (averaged over the two hands, so left/right handedness does not
     count) the log mean speed, the speed's coefficient of variation, two log percentile ratios
     (p90/p50, p50/p10), the log ratios mean |acceleration| / mean speed and mean |jerk| / mean
     |acceleration| (characteristic frequencies, 1/s), the path straightness over 0.5 s, the
     log median path curvature (1/m), the log shares of speed-signal power in five bands
     (0.3–1, 1–2, 2–4, 4–8, 8–15 Hz) and the rate of speed minima (per s, the motion-beat
     rule of BC); across the hands the correlation of their speeds and the mean and SD of
     their distance (divided by the shoulder width when shoulders are given); for each other
     gesturing joint (head, elbows, wrists in the eval) the log ratio of its mean speed to the
     hands'.
   - **Classifier**: standardisation and an L1 logistic regression (``C = 0.3``, liblinear),
     fitted per fold: linear, small and sparse, because there is little data (a minute of real
     motion gives about 40 windows): the L1 penalty lets one feature that separates the two
     (e.g. jitter's 8–15 Hz speed power) decide, where an L2 fit spread its weight over
     features that differ between stretches of the same speaker.
   - **Split**: each class's windows are put in :data:`N_FOLDS` (5) contiguous blocks in time
     (grouped cross-validation: fold ``k`` tests block ``k`` of the real motion against block
     ``k`` of the generated one); a training window that overlaps a test window of the same
     motion in time is dropped from that fold's training set, so no frame is both trained
     and tested on.
   - **Balance**: in every fold the larger class is subsampled (``numpy.random.default_rng
     (seed)``) to the smaller's count, in training and in testing; the accuracy is the share of
     all held-out windows classified right, so chance is 0.5 whatever the two amounts of motion.

   **Limits.** With a minute of each there are ~80 windows tested in all: the sampling error
   of the accuracy is about ±0.06 (binomial SE at 0.5; :attr:`DiscriminatorResult.se`), and
   the folds test different stretches of the motion, so a real motion whose first and last
   minutes differ (a speaker who warms up) scores above 0.5 against itself. It sees
   kinematics only (speeds, accelerations, paths over 3 s), not the pose or the link with
   speech; it is a linear model on hand-made features, so it finds differences in those
   statistics and nothing subtler; and a simulated body differs from kinematic mocap in
   exactly these statistics (the tracker smooths), so compare methods that all went through
   the same physics (e.g. random clips: real clips through the same body), not a method with
   the kinematic real motion it is scored against.

2. :func:`bc_beat2`: beat consistency as the BEAT2 tools compute it (EMAGE's evaluation,
   ``PantoMatrix/PantoMatrix`` ``emage_evaltools/mertic.py`` class ``BC`` and
   ``train_emage_audio.py`` ``evaluation_fn``, commit ``0bbb03df``), beside the project's own
   :func:`gesture_sim.metrics.motion.beat_consistency`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from gesture_sim.errors import GestureSimError
from gesture_sim.metrics import motion as mm

#: Discriminator window length and hop (s).
WINDOW_S = 3.0
HOP_S = 1.5
#: Contiguous blocks of the grouped cross-validation.
N_FOLDS = 5
#: Fewest windows on each side for a discriminator accuracy (below: no figure).
MIN_WINDOWS = 8
#: Inverse L1 strength of the logistic regression.
LOGISTIC_C = 0.3
#: Speed-spectrum bands (Hz) of the window features.
SPEED_BANDS_HZ = ((0.3, 1.0), (1.0, 2.0), (2.0, 4.0), (4.0, 8.0), (8.0, 15.0))
#: Floor of a band's power share before its log (a band without power is not -inf).
BAND_FLOOR = 1e-4
#: Sub-window (s) of the path-straightness feature.
STRAIGHTNESS_S = 0.5
#: Speeds below this (m/s) count as this in log ratios (a hand at rest is not infinitely slow).
SPEED_FLOOR = 1e-3

#: BEAT2 BC: kernel width (s), argrelextrema order at 30 fps, speed threshold (share of the
#: dataset's mean speed) and the seconds left out at each end of a sequence.
BEAT2_SIGMA_S = 0.3
BEAT2_ORDER_30FPS = 7
BEAT2_THRESHOLD = 0.10
BEAT2_SKIP_S = 2.0

_HAND_FEATURES = (
    "log_speed", "speed_cv", "log_p90_p50", "log_p50_p10", "log_acc_per_speed",
    "log_jerk_per_acc", "straightness", "log_curvature",
    *(f"log_band_{lo:g}_{hi:g}hz" for lo, hi in SPEED_BANDS_HZ), "minima_per_s",
)
#: Names of the per-hand features (averaged over the two hands) and the cross-hand ones; the
#: per-joint speed ratios follow as ``log_speed_ratio_<joint index>``.
FEATURE_NAMES = (*_HAND_FEATURES, "hand_speed_corr", "hand_distance", "hand_distance_sd")


# --------------------------------------------------------------------------------------------
# Window features
# --------------------------------------------------------------------------------------------


def _log_ratio(a: float, b: float) -> float:
    return float(np.log(max(a, SPEED_FLOOR) / max(b, SPEED_FLOOR)))


def _hand_features(p: np.ndarray, fps: float) -> list[float]:
    """Features of one hand's path ``p (W, 3)`` (m): see :data:`_HAND_FEATURES`."""
    dt = 1.0 / fps
    v = np.gradient(p, dt, axis=0)
    a = np.gradient(v, dt, axis=0)
    j = np.gradient(a, dt, axis=0)
    s = np.linalg.norm(v, axis=1)
    acc = np.linalg.norm(a, axis=1)
    jerk = np.linalg.norm(j, axis=1)
    mean_s = float(s.mean())
    p10, p50, p90 = np.percentile(s, [10, 50, 90])
    # straightness: |displacement| / path length over sub-windows (1 = a straight stroke)
    k = max(2, int(round(STRAIGHTNESS_S * fps)))
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    straight = []
    for i in range(0, len(p) - k, max(1, k // 2)):
        path = float(step[i : i + k].sum())
        if path > SPEED_FLOOR * k * dt:
            straight.append(float(np.linalg.norm(p[i + k] - p[i])) / path)
    # curvature |v x a| / |v|³ (1/m) where the hand moves (over a fifth of its mean speed)
    moving = s > max(0.2 * mean_s, SPEED_FLOOR)
    if moving.sum() >= 3:
        curv = np.linalg.norm(np.cross(v[moving], a[moving]), axis=1) / s[moving] ** 3
        log_curv = float(np.log(np.median(curv) + 1e-3))
    else:
        log_curv = float(np.log(1e-3))
    # speed spectrum: shares of the power of the mean-removed, Hann-windowed speed
    x = (s - mean_s) * np.hanning(len(s))
    power = np.abs(np.fft.rfft(x)) ** 2
    freqs = np.fft.rfftfreq(len(s), dt)
    total = float(power[(freqs >= SPEED_BANDS_HZ[0][0]) & (freqs < SPEED_BANDS_HZ[-1][1])].sum())
    bands = [float(np.log(max(float(power[(freqs >= lo) & (freqs < hi)].sum()) / total,
                              BAND_FLOOR))) if total > 0 else float(np.log(BAND_FLOOR))
             for lo, hi in SPEED_BANDS_HZ]
    minima = signal.argrelextrema(s, np.less, order=mm.beat_order(fps))[0]
    return [
        float(np.log(max(mean_s, SPEED_FLOOR))),
        float(s.std() / max(mean_s, SPEED_FLOOR)),
        _log_ratio(p90, p50),
        _log_ratio(p50, p10),
        _log_ratio(float(acc.mean()), mean_s),
        _log_ratio(float(jerk.mean()), float(acc.mean())),
        float(np.mean(straight)) if straight else 1.0,
        log_curv,
        *bands,
        len(minima) / (len(s) / fps),
    ]


def window_features(
    positions: np.ndarray, fps: float, *, hands: Sequence[int], joints: Sequence[int] = (),
    shoulders: Sequence[int] | None = None, window_s: float = WINDOW_S, hop_s: float = HOP_S,
) -> tuple[np.ndarray, np.ndarray]:
    """Kinematic features of the windows of one motion.

    Args:
        positions: ``(T, J, 3)`` joint positions (m) at ``fps`` (Hz).
        hands: the two hand joints (left, right).
        joints: other gesturing joints: one speed-ratio feature each.
        shoulders: optional (left, right) shoulder joints: the hand distance is then divided by
            the mean shoulder width of the window (dimensionless), else it is in metres.
        window_s, hop_s: window length and hop (s).

    Returns:
        ``(features (N, F), starts (N,))``: F = ``len(FEATURE_NAMES) + len(joints)``, starts are
        window start frames; N = 0 (features ``(0, F)``) when the motion is shorter than one
        window.
    """
    p = mm._positions(positions)
    fps = mm._check_fps(fps)
    hands = [int(h) for h in hands]
    if len(hands) != 2:
        raise GestureSimError(f"window_features needs two hand joints, got {len(hands)}")
    joints = [int(j) for j in joints]
    for j in [*hands, *joints, *(shoulders or ())]:
        if not 0 <= j < p.shape[1]:
            raise GestureSimError(f"joint {j} is not one of the motion's {p.shape[1]} joints")
    win = int(round(window_s * fps))
    hop = max(1, int(round(hop_s * fps)))
    if win < 8:
        raise GestureSimError(f"a window of {window_s} s at {fps} fps is under 8 frames")
    n_feat = len(FEATURE_NAMES) + len(joints)
    if p.shape[0] < win:
        return np.zeros((0, n_feat)), np.zeros(0, dtype=np.int64)
    starts = np.arange(0, p.shape[0] - win + 1, hop, dtype=np.int64)
    speeds = mm.joint_speeds(p, fps)
    rows = []
    for s0 in starts:
        w = p[s0 : s0 + win]
        sp = speeds[s0 : s0 + win]
        per_hand = np.mean([_hand_features(w[:, h], fps) for h in hands], axis=0)
        sl, sr = sp[:, hands[0]], sp[:, hands[1]]
        corr = float(np.corrcoef(sl, sr)[0, 1]) if sl.std() > 0 and sr.std() > 0 else 0.0
        dist = np.linalg.norm(w[:, hands[0]] - w[:, hands[1]], axis=1)
        if shoulders is not None:
            width = float(np.mean(np.linalg.norm(w[:, shoulders[0]] - w[:, shoulders[1]],
                                                 axis=1)))
            dist = dist / max(width, 1e-6)
        hand_speed = float(sp[:, hands].mean())
        ratios = [_log_ratio(float(sp[:, j].mean()), hand_speed) for j in joints]
        rows.append([*per_hand, corr, float(dist.mean()), float(dist.std()), *ratios])
    return np.asarray(rows, dtype=np.float64), starts


@dataclass(frozen=True)
class WindowSet:
    """The windows of one or more motions of one class, ready for :func:`discriminator_accuracy`.

    Attributes:
        features: ``(N, F)`` window features (:func:`window_features`).
        source: ``(N,)`` index of the motion each window was cut from.
        start_s, end_s: ``(N,)`` window start and end (s) within its motion.
        duration_s: total seconds of motion the windows were cut from.
    """

    features: np.ndarray
    source: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray
    duration_s: float

    def __len__(self) -> int:
        return int(self.features.shape[0])


def window_set(
    motions: np.ndarray | Sequence[np.ndarray], fps: float, *, hands: Sequence[int],
    joints: Sequence[int] = (), shoulders: Sequence[int] | None = None,
    window_s: float = WINDOW_S, hop_s: float = HOP_S,
) -> WindowSet:
    """Windows of one motion ``(T, J, 3)`` or a list of motions (e.g. library clips), all at
    ``fps``; see :func:`window_features` for the other arguments. Motions shorter than a window
    give no windows."""
    if isinstance(motions, np.ndarray) and motions.ndim == 3:
        motions = [motions]
    feats, src, t0, t1 = [], [], [], []
    duration = 0.0
    n_feat = len(FEATURE_NAMES) + len(joints)
    for k, m in enumerate(motions):
        f, starts = window_features(m, fps, hands=hands, joints=joints, shoulders=shoulders,
                                    window_s=window_s, hop_s=hop_s)
        duration += len(m) / fps
        feats.append(f)
        src.append(np.full(len(f), k, dtype=np.int64))
        t0.append(starts / fps)
        t1.append(starts / fps + window_s)
    if not feats:
        raise GestureSimError("window_set needs at least one motion")
    return WindowSet(np.concatenate(feats).reshape(-1, n_feat), np.concatenate(src),
                     np.concatenate(t0), np.concatenate(t1), duration)


# --------------------------------------------------------------------------------------------
# The discriminator
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DiscriminatorResult:
    """Held-out accuracy of the real-vs-generated classifier.

    Attributes:
        accuracy: share of held-out windows classified right over all folds, in [0, 1];
            0.5 = indistinguishable, NaN when there were too few windows.
        n_real, n_generated: windows available on each side.
        n_tested: held-out windows scored (both classes; balanced in every fold).
        fold_accuracies: accuracy of each fold (``N_FOLDS``; NaN for an empty fold).
        window_s, hop_s: the windows.
        n_features: features per window.
    """

    accuracy: float
    n_real: int
    n_generated: int
    n_tested: int
    fold_accuracies: tuple[float, ...] = field(default_factory=tuple)
    window_s: float = WINDOW_S
    hop_s: float = HOP_S
    n_features: int = 0

    @property
    def se(self) -> float:
        """Binomial standard error of :attr:`accuracy` (NaN when nothing was tested)."""
        if self.n_tested == 0 or not np.isfinite(self.accuracy):
            return float("nan")
        return float(np.sqrt(self.accuracy * (1.0 - self.accuracy) / self.n_tested))


def _blocks(ws: WindowSet, n_folds: int) -> np.ndarray:
    """Fold of each window: ``n_folds`` contiguous blocks of the class's windows, in order of
    (motion, start)."""
    order = np.lexsort((ws.start_s, ws.source))
    fold = np.empty(len(ws), dtype=np.int64)
    fold[order] = (np.arange(len(ws)) * n_folds) // max(len(ws), 1)
    return fold


def _purged_train(ws: WindowSet, fold: np.ndarray, k: int) -> np.ndarray:
    """Indices of the windows not in fold ``k`` that overlap no window of fold ``k`` of the
    same motion in time."""
    test = np.flatnonzero(fold == k)
    keep = []
    for i in np.flatnonzero(fold != k):
        same = test[ws.source[test] == ws.source[i]]
        if same.size and np.any((ws.start_s[same] < ws.end_s[i] - 1e-9)
                                & (ws.end_s[same] > ws.start_s[i] + 1e-9)):
            continue
        keep.append(i)
    return np.asarray(keep, dtype=np.int64)


def _balanced(a: np.ndarray, b: np.ndarray, rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray]:
    """``a`` and ``b`` (index arrays) with the larger subsampled to the smaller's size."""
    n = min(len(a), len(b))
    if len(a) > n:
        a = np.sort(rng.choice(a, n, replace=False))
    if len(b) > n:
        b = np.sort(rng.choice(b, n, replace=False))
    return a, b


def _l1_logistic():
    """An L1 logistic regression (liblinear, ``C = LOGISTIC_C``, fixed random state), spelled
    for the installed scikit-learn (``penalty`` is deprecated from 1.8 on)."""
    import sklearn
    from sklearn.linear_model import LogisticRegression

    version = tuple(int(v) for v in sklearn.__version__.split(".")[:2] if v.isdigit())
    if version >= (1, 8):
        return LogisticRegression(C=LOGISTIC_C, l1_ratio=1.0, solver="liblinear", random_state=0)
    return LogisticRegression(C=LOGISTIC_C, penalty="l1", solver="liblinear", random_state=0)


def discriminator_accuracy(
    real: WindowSet | np.ndarray | Sequence[np.ndarray],
    generated: WindowSet | np.ndarray | Sequence[np.ndarray], fps: float | None = None,
    seed: int = 0, *, hands: Sequence[int] | None = None, joints: Sequence[int] = (),
    shoulders: Sequence[int] | None = None, n_folds: int = N_FOLDS,
    min_windows: int = MIN_WINDOWS,
) -> DiscriminatorResult:
    """Held-out accuracy of a classifier telling real windows from generated ones.

    Args:
        real: the real co-speech motion: a :class:`WindowSet`, one motion ``(T, J, 3)`` or a
            list of motions (clips).
        generated: the motion to judge, in the same forms.
        fps: frame rate (Hz) of the motions given as arrays.
        seed: of the class-balancing subsampling (the classifier itself is deterministic).
        hands, joints, shoulders: joint indices of :func:`window_features` (``hands`` needed for
            motions given as arrays).
        n_folds: contiguous blocks of the grouped cross-validation.
        min_windows: fewest windows on each side; below it the accuracy is NaN.

    Returns:
        a :class:`DiscriminatorResult` (see the module docstring for what it measures).
    """
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    sets = []
    for name, x in (("real", real), ("generated", generated)):
        if isinstance(x, WindowSet):
            sets.append(x)
            continue
        if fps is None or hands is None:
            raise GestureSimError(f"discriminator_accuracy needs fps and hands for {name} "
                                  "motion given as arrays")
        sets.append(window_set(x, fps, hands=hands, joints=joints, shoulders=shoulders))
    rs, gs = sets
    if rs.features.shape[1] != gs.features.shape[1]:
        raise GestureSimError(f"real and generated windows have {rs.features.shape[1]} and "
                              f"{gs.features.shape[1]} features")
    n_folds = int(n_folds)
    if n_folds < 2:
        raise GestureSimError(f"discriminator_accuracy needs at least 2 folds, got {n_folds}")
    n_feat = int(rs.features.shape[1])
    if min(len(rs), len(gs)) < max(int(min_windows), n_folds):
        return DiscriminatorResult(float("nan"), len(rs), len(gs), 0,
                                   tuple([float("nan")] * n_folds), n_features=n_feat)
    rng = np.random.default_rng(seed)
    fr, fg = _blocks(rs, n_folds), _blocks(gs, n_folds)
    correct = tested = 0
    folds = []
    for k in range(n_folds):
        tr_r, tr_g = _balanced(_purged_train(rs, fr, k), _purged_train(gs, fg, k), rng)
        te_r, te_g = _balanced(np.flatnonzero(fr == k), np.flatnonzero(fg == k), rng)
        if len(tr_r) < 2 or len(te_r) == 0:
            folds.append(float("nan"))
            continue
        x = np.concatenate([rs.features[tr_r], gs.features[tr_g]])
        y = np.r_[np.zeros(len(tr_r)), np.ones(len(tr_g))]
        clf = make_pipeline(StandardScaler(), _l1_logistic())
        clf.fit(x, y)
        xt = np.concatenate([rs.features[te_r], gs.features[te_g]])
        yt = np.r_[np.zeros(len(te_r)), np.ones(len(te_g))]
        hits = int(np.sum(clf.predict(xt) == yt))
        correct += hits
        tested += len(yt)
        folds.append(hits / len(yt))
    acc = correct / tested if tested else float("nan")
    return DiscriminatorResult(float(acc), len(rs), len(gs), int(tested), tuple(folds),
                               n_features=n_feat)


def real_split_accuracy(
    motions: np.ndarray | Sequence[np.ndarray], fps: float, seed: int = 0, *,
    hands: Sequence[int], joints: Sequence[int] = (), shoulders: Sequence[int] | None = None,
    block_s: float = 2 * WINDOW_S,
) -> DiscriminatorResult:
    """The discriminator on real motion against itself: the floor a method is read against.

    Each motion ``(T, J, 3)`` at ``fps`` is cut into consecutive blocks of ``block_s`` seconds
    (6 s: two windows), and the blocks go alternately to the two sides (a tail shorter than a
    window is dropped); :func:`discriminator_accuracy` then tells one side from the other.
    Near 0.5 (within its sampling error) when the real motion is homogeneous over time.
    """
    if isinstance(motions, np.ndarray) and motions.ndim == 3:
        motions = [motions]
    n = max(1, int(round(block_s * fps)))
    win = int(round(WINDOW_S * fps))
    blocks = [m[i : i + n] for m in motions for i in range(0, len(m), n)
              if len(m[i : i + n]) >= win]
    return discriminator_accuracy(blocks[0::2], blocks[1::2], fps, seed, hands=hands,
                                  joints=joints, shoulders=shoulders)


# --------------------------------------------------------------------------------------------
# BEAT2's beat consistency
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Beat2BC:
    """Beat consistency as the BEAT2 tools compute it (:func:`bc_beat2`).

    Attributes:
        bc: in [0, 1]; NaN when no audio beat falls in the scored stretch (BEAT2's code would
            divide by zero there) or the motion is shorter than the two skipped ends.
        n_audio_beats: audio beats in the scored stretch.
        motion_beats_per_s: mean over the joints of motion beats per second of that stretch.
        n_frames: frames of the scored stretch (``T - 2 * skip``): BEAT2's weight when it
            averages sequences (``BC.compute(..., length=t - 120)``).
    """

    bc: float
    n_audio_beats: int
    motion_beats_per_s: float
    n_frames: int


def bc_beat2(
    audio_beats: np.ndarray, fps: float, *, positions: np.ndarray | None = None,
    speeds: np.ndarray | None = None, joints: Sequence[int] | np.ndarray | None = None,
    mean_speed: float | np.ndarray | None = None, sigma: float = BEAT2_SIGMA_S,
    threshold: float = BEAT2_THRESHOLD, skip_s: float = BEAT2_SKIP_S, order: int | None = None,
    mask_at_slice_index: bool = False,
) -> Beat2BC:
    """Beat consistency with the definition and thresholds of the BEAT2 (EMAGE) tools.

    Source: ``PantoMatrix/PantoMatrix`` @ ``0bbb03df``, ``emage_evaltools/mertic.py`` class
    ``BC`` (``load_motion``, ``GAHR``, ``compute``) as called by ``train_emage_audio.py``
    ``evaluation_fn`` ("ignore the start and end 2s"). The rule:

    1. Joint speed over the whole motion, central differences inside and one-sided at the two
       ends (``np.gradient``), divided by the dataset's mean speed (``mean_vel_smplxflame_30
       .npy`` there; ``mean_speed`` here).
    2. Motion beats of joint ``j``: the strict local minima of the normalised speed inside the
       stretch from ``skip_s`` (2 s, 60 frames at 30 fps) to ``T - skip_s``
       (``argrelextrema(vel[60:t-60, j], np.less, order=7)``: a minimum at the stretch's first
       or last frame does not count), kept where the normalised speed exceeds ``threshold``
       (0.10; the project's own BC uses 0.3 of the joint's own mean speed).
    3. Audio beats: those in ``[skip_s, T/fps - skip_s)`` (BEAT2 runs librosa's onset detector
       on that slice of the audio; here the beats are given, e.g. the project's
       :func:`~gesture_sim.metrics.motion.detect_onsets` of the whole file, cut to it).
    4. Per joint: the mean over **audio** beats of ``exp(-d² / (2 sigma²))``, ``d`` the distance
       (s) to the nearest motion beat of that joint (``GAHR(pose_bt, audio_bt)`` loops over its
       second argument, the audio beats), sigma 0.3 s; a joint without motion beats scores 0.
    5. BC: the sum over ``joints`` divided by their number (BEAT2: its 13 upper-body SMPL-X
       joints). Over several sequences BEAT2 averages BC weighted by ``T - 2 * skip`` frames
       (:attr:`Beat2BC.n_frames`).

    One detail of the original is a slip, reproduced only on request: it tests the threshold
    at the minimum's index *within the stretch* against the speed of the *whole* motion
    (``j in vel_mask[0]`` with ``j`` counted from frame 60), i.e. at the frame 2 s before
    the minimum. By default the threshold is tested at the minimum itself;
    ``mask_at_slice_index=True`` gives the original's behaviour.

    Args:
        audio_beats: ``(K,)`` audio beat times (s) on the motion's clock (frame 0 at t = 0).
        fps: motion frame rate (Hz).
        positions: ``(T, J, 3)`` joint positions (m); or give ``speeds`` ``(T, J)`` (m/s).
        joints: joints averaged (default all).
        mean_speed: the dataset's mean speed (m/s), per joint ``(J,)`` or one number; default
            each joint's own mean speed over this motion.
        sigma: kernel width (s); threshold: speed / mean speed above which a minimum is a beat;
        skip_s: seconds left out at each end; order: ``argrelextrema`` order (frames), default
            7 at 30 fps (:data:`BEAT2_ORDER_30FPS`), scaled for other rates.
    """
    if (positions is None) == (speeds is None):
        raise GestureSimError("bc_beat2 needs exactly one of positions or speeds")
    fps = mm._check_fps(fps)
    spd = (mm.joint_speeds(positions, fps) if positions is not None
           else np.asarray(speeds, dtype=np.float64))
    if spd.ndim != 2:
        raise GestureSimError(f"speeds must have shape (frames, joints), got {spd.shape}")
    n_frames, n_joints = spd.shape
    idx = np.arange(n_joints) if joints is None else np.asarray(joints, dtype=np.int64)
    if idx.size == 0 or idx.min() < 0 or idx.max() >= n_joints:
        raise GestureSimError(f"bc_beat2: joints must be among the motion's {n_joints}")
    ref = spd.mean(axis=0) if mean_speed is None else np.broadcast_to(
        np.asarray(mean_speed, dtype=np.float64), (n_joints,))
    if np.any(~np.isfinite(ref)) or np.any(ref[idx] <= 0):
        raise GestureSimError("bc_beat2: the mean speed must be positive for every joint")
    norm = spd / ref
    order = (max(1, int(round(BEAT2_ORDER_30FPS * fps / 30.0))) if order is None
             else int(order))
    k0 = int(round(skip_s * fps))
    k1 = n_frames - k0
    if k1 - k0 < 3:
        return Beat2BC(float("nan"), 0, 0.0, max(k1 - k0, 0))
    a = np.asarray(audio_beats, dtype=np.float64).ravel()
    a = a[(a >= k0 / fps) & (a < k1 / fps)] - k0 / fps
    scores, counts = [], []
    for j in idx:
        minima = signal.argrelextrema(norm[k0:k1, j], np.less, order=order)[0]
        at = minima if mask_at_slice_index else minima + k0
        beats = minima[norm[at, j] > threshold] / fps
        counts.append(len(beats))
        if a.size:
            scores.append(mm.beat_kernel_score(a, beats, sigma) if beats.size else 0.0)
    bc = float(np.sum(scores) / len(idx)) if a.size else float("nan")
    return Beat2BC(bc, int(a.size), float(np.mean(counts)) / ((k1 - k0) / fps), int(k1 - k0))
