"""Perceptual distances between library segments (Gesture Controllers §7.1, Levine 2009 §2.3).

- ``D_seg(a, b)``: segment length (log), initial pose, and a signature of the dynamics (per-axis
  log velocity and log displacement of the hands); symmetric, zero on the diagonal.
- ``D_sp(a_i, a_j) = D_seg(succ(a_i), a_j) + D_seg(a_i, pred(a_j))``: the discontinuity of
  playing a_j after a_i, where succ/pred are the neighbours in the source take. A missing
  neighbour (first/last segment of a take) falls back to the pose distance between the last
  frame of a_i and the first frame of a_j. ``D_sp(a, succ(a)) = 0``.
- ``D_in(a_i, k, a_j)``: pose distance between interruption frame k of a_i and the first frame of
  a_j, plus an interruption penalty (default: the median of D_sp, as the digest suggests).

Everything is vectorised over the library (``scipy.spatial.distance.cdist``); a library of a few
thousand segments takes well under a second.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial.distance import cdist


@dataclass(frozen=True)
class DistanceWeights:
    """Weights of the D_seg terms.

    Attributes:
        length: per unit of |log(len_a / len_b)|.
        pose: per metre of RMS key-point distance between poses.
        dynamics: per unit of Euclidean distance between dynamics signatures.
        interrupt_penalty: added to every D_in; ``None`` = median of D_sp.
    """

    length: float = 1.0
    pose: float = 10.0
    dynamics: float = 0.5
    interrupt_penalty: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class SegmentDistances:
    """Distances between the n segments of a library.

    Attributes:
        d_seg: (n, n) D_seg, symmetric, zero diagonal.
        d_sp: (n, n) D_sp[i, j] = cost of playing segment j after segment i has finished.
        d_in: (n, 3, n) D_in[i, k, j] = cost of switching from interruption frame k of segment i
            to the first frame of segment j.
        interrupt_penalty: the penalty included in ``d_in``.
    """

    d_seg: np.ndarray
    d_sp: np.ndarray
    d_in: np.ndarray
    interrupt_penalty: float


def pose_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """RMS key-point distance (m) between every pose of ``a`` and every pose of ``b``.

    Args:
        a: (n, K, 3) poses as key-point positions (m); b: (m, K, 3).

    Returns:
        (n, m) RMS over the K key points of the Euclidean distance.
    """
    k = a.shape[1]
    return cdist(a.reshape(len(a), -1), b.reshape(len(b), -1)) / np.sqrt(k)


def segment_distance(
    lengths: np.ndarray, start_pose: np.ndarray, signature: np.ndarray,
    weights: DistanceWeights = DistanceWeights(),
) -> np.ndarray:
    """D_seg between all pairs of segments.

    Args:
        lengths: (n,) segment lengths (frames or seconds; only ratios matter).
        start_pose: (n, K, 3) key points at each segment's first frame (m).
        signature: (n, S) dynamics signatures (see
            :func:`gesture_sim.motion.kinematics.dynamics_signature`).

    Returns:
        (n, n) symmetric, zero on the diagonal.
    """
    log_len = np.log(np.asarray(lengths, dtype=float))[:, None]
    d = weights.length * cdist(log_len, log_len, "cityblock")
    d += weights.pose * pose_distance(start_pose, start_pose)
    d += weights.dynamics * cdist(signature, signature)
    np.fill_diagonal(d, 0.0)
    return 0.5 * (d + d.T)


def successor_predecessor_distance(
    d_seg: np.ndarray, predecessor: np.ndarray, successor: np.ndarray,
    end_pose: np.ndarray, start_pose: np.ndarray, weights: DistanceWeights = DistanceWeights(),
) -> np.ndarray:
    """D_sp[i, j] = D_seg[succ(i), j] + D_seg[i, pred(j)], with a pose fallback for -1.

    Args:
        d_seg: (n, n) from :func:`segment_distance`.
        predecessor, successor: (n,) segment indices in the source take, -1 if none.
        end_pose, start_pose: (n, K, 3) key points at each segment's last and first frame (m).

    Returns:
        (n, n); D_sp[i, succ(i)] = 0.
    """
    predecessor = np.asarray(predecessor, dtype=int)
    successor = np.asarray(successor, dtype=int)
    fallback = weights.pose * pose_distance(end_pose, start_pose)  # (n, n): end i -> start j
    term1 = np.where(successor[:, None] >= 0, d_seg[np.maximum(successor, 0), :], fallback)
    term2 = np.where(predecessor[None, :] >= 0, d_seg[:, np.maximum(predecessor, 0)], fallback)
    return term1 + term2


def interruption_distance(
    interrupt_pose: np.ndarray, start_pose: np.ndarray, penalty: float,
    weights: DistanceWeights = DistanceWeights(),
) -> np.ndarray:
    """D_in[i, k, j] = pose distance(frame k of i, first frame of j) + penalty.

    Args:
        interrupt_pose: (n, 3, K, 3) key points at the three interruption frames (m).
        start_pose: (n, K, 3).
        penalty: the interruption penalty.

    Returns:
        (n, 3, n).
    """
    n, r = interrupt_pose.shape[:2]
    flat = interrupt_pose.reshape(n * r, *interrupt_pose.shape[2:])
    d = weights.pose * pose_distance(flat, start_pose) + penalty
    return d.reshape(n, r, len(start_pose))


def compute_distances(
    lengths: np.ndarray, start_pose: np.ndarray, end_pose: np.ndarray,
    interrupt_pose: np.ndarray, signature: np.ndarray, predecessor: np.ndarray,
    successor: np.ndarray, weights: DistanceWeights = DistanceWeights(),
) -> SegmentDistances:
    """All three distance tables of a library (shapes as in the functions above)."""
    d_seg = segment_distance(lengths, start_pose, signature, weights)
    d_sp = successor_predecessor_distance(d_seg, predecessor, successor, end_pose, start_pose,
                                          weights)
    penalty = (float(np.median(d_sp)) if weights.interrupt_penalty is None
               else float(weights.interrupt_penalty))
    d_in = interruption_distance(interrupt_pose, start_pose, penalty, weights)
    return SegmentDistances(d_seg=d_seg, d_sp=d_sp, d_in=d_in, interrupt_penalty=penalty)
