"""Offline synthesis by dynamic programming (Gesture Controllers §7.1), to compare with online.

With the whole utterance known, the smoothed beliefs γ_t (forward–backward) are available and the
best sequence of (segment, frame) pairs minimises

    cost = Σ_t γ_t · η_{a_t}  +  Σ_switches S(a, k -> a')

(undiscounted, the same fit weights and switch costs as the MDP) under the same rules: frames
play in order, a segment may be left only at an interruption frame or its last frame, and a
switch enters frame 0 of another segment. The recurrence

    Q_t(a, 0) = γ_t·η_a + min_{(b, k), b != a} Q_{t-1}(b, F[b, k]) + S(b, k, a)
    Q_t(a, f) = γ_t·η_a + Q_{t-1}(a, f - 1)                          (f >= 1)

is evaluated for all frames at once (O(T · n² (K+1)) for the switches, vectorised), and the
optimum is recovered by backtracking. :func:`sequence_cost` evaluates the same objective for
any sequence (e.g. the online controller's), so online and offline choices can be compared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.control.mdp import Structure
from gesture_sim.errors import GestureSimError


@dataclass
class OfflineResult:
    """The optimal sequence: per step the segment and frame offset, and its total cost."""

    segments: np.ndarray
    frames: np.ndarray
    cost: float


def offline_synthesis(lib: ControlLibrary, eta: np.ndarray, s_dec: np.ndarray,
                      gamma: np.ndarray) -> OfflineResult:
    """The minimum-cost sequence for beliefs ``gamma`` (T, S).

    Args:
        lib: the library.
        eta: (n, S) weighted fit cost per frame (e.g. ``policy.eta`` blended over tones).
        s_dec: (n, K+1, n) weighted switch costs
            (:func:`~gesture_sim.control.costs.successor_costs`).
        gamma: (T, S) beliefs per step (smoothed, rows sum to 1).
    """
    gamma = np.asarray(gamma, dtype=float)
    if gamma.ndim != 2 or gamma.shape[1] != eta.shape[1] or len(gamma) == 0:
        raise GestureSimError(f"gamma must be (T, {eta.shape[1]}), got {gamma.shape}")
    st = Structure.from_library(lib)
    n, kp1 = st.frames.shape
    lengths = lib.lengths
    base = np.concatenate([[0], np.cumsum(lengths)[:-1]])            # global index of frame 0
    total = int(lengths.sum())
    seg_of = np.repeat(np.arange(n), lengths)
    not_first = np.ones(total, bool)
    not_first[base] = False
    pts = (base[:, None] + st.frames)[st.valid]                       # global frames of points
    pt_seg = np.repeat(np.arange(n), kp1)[st.valid.reshape(-1)]
    s_pts = s_dec.reshape(n * kp1, n)[st.valid.reshape(-1)]            # (P, n)
    steps = len(gamma)
    back = np.empty((steps, n), dtype=np.int64)
    cost_t = gamma @ eta.T                                            # (T, n)
    q = np.full(total, np.inf)
    q[base] = cost_t[0]
    back[0] = -1
    for t in range(1, steps):
        prev = q
        q = np.empty(total)
        q[not_first] = prev[np.nonzero(not_first)[0] - 1]
        cand = prev[pts][:, None] + s_pts                              # (P, n)
        cand[pt_seg[:, None] == np.arange(n)[None, :]] = np.inf
        j = np.argmin(cand, axis=0)
        q[base] = cand[j, np.arange(n)]
        back[t] = j
        q += cost_t[t][seg_of]
    g = int(np.argmin(q))
    best = float(q[g])
    if not np.isfinite(best):
        raise GestureSimError("no feasible gesture sequence for this library and length")
    segs = np.empty(steps, dtype=np.int64)
    frames = np.empty(steps, dtype=np.int64)
    for t in range(steps - 1, -1, -1):
        a = int(seg_of[g])
        f = g - int(base[a])
        segs[t], frames[t] = a, f
        if t == 0:
            break
        g = int(pts[back[t, a]]) if f == 0 else g - 1
    return OfflineResult(segments=segs, frames=frames, cost=best)


def sequence_cost(lib: ControlLibrary, eta: np.ndarray, s_dec: np.ndarray, gamma: np.ndarray,
                  segments: np.ndarray, frames: np.ndarray) -> float:
    """The §7.1 objective of a given sequence (``inf`` if it breaks the transition rules)."""
    st = Structure.from_library(lib)
    segments, frames = np.asarray(segments), np.asarray(frames)
    cost = float(np.sum(np.einsum("ts,ts->t", np.asarray(gamma, float), eta[segments])))
    for t in range(1, len(segments)):
        a, f, b, g = segments[t - 1], frames[t - 1], segments[t], frames[t]
        if a == b and g == f + 1:
            continue
        if g != 0 or a == b:
            return float("inf")
        ks = np.nonzero((st.frames[a] == f) & st.valid[a])[0]
        if len(ks) == 0:
            return float("inf")
        cost += float(s_dec[a, ks[-1], b])
    return cost


def agreement(online_segments: np.ndarray, offline_segments: np.ndarray) -> float:
    """Fraction of steps on which the online and offline sequences play the same segment."""
    a, b = np.asarray(online_segments), np.asarray(offline_segments)
    return float(np.mean(a == b)) if len(a) else 1.0
