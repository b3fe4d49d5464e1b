"""Synthetic libraries and state models with realistic statistics, for tests and benchmarks.

A synthetic library is a set of smooth random joint-angle takes (sums of sinusoids, 30 fps) cut
into consecutive segments with log-normal lengths (median ~0.6 s, as produced by hand-speed
segmentation of conversational motion). Kinematic parameters, D_seg, D_sp and D_in are computed
from the joint angles the way the motion library computes them from hand positions (log length,
start pose, log velocity and displacement; D_sp from the take's predecessor/successor; D_in =
pose distance + interruption penalty = median D_sp), so the cost scales are realistic.
"""

from __future__ import annotations

import numpy as np

from gesture_sim.control.inputs import ControlLibrary, StateModel, array_fingerprint


def uniform_interrupts(length: int, k: int = 3) -> tuple[int, ...]:
    """``k`` uniformly spaced interruption offsets ``0 < f_1 < ... < f_k <= length - 1``."""
    f = [max(1, int(round(length * (j + 1) / (k + 1)))) for j in range(k)]
    for j in range(1, k):
        f[j] = max(f[j], f[j - 1] + 1)
    return tuple(min(x, length - 1) for x in f)


def _take(rng: np.random.Generator, n_frames: int, n_joints: int, fps: float) -> np.ndarray:
    """(n_frames, n_joints) smooth joint angles (rad): a few sinusoids per joint."""
    t = np.arange(n_frames) / fps
    freq = rng.uniform(0.2, 2.0, (n_joints, 4))
    amp = rng.uniform(0.05, 0.4, (n_joints, 4)) / np.sqrt(4)
    phase = rng.uniform(0, 2 * np.pi, (n_joints, 4))
    # slowly varying activity envelope: quiet and lively passages
    env = 0.4 + 0.6 * (0.5 + 0.5 * np.sin(2 * np.pi * rng.uniform(0.02, 0.1) * t
                                          + rng.uniform(0, 6.3)))
    waves = np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None])
    q = np.einsum("jk,tjk->tj", amp, waves)
    return (q * env[:, None]).astype(np.float32)


def synthetic_library(
    duration_s: float, fps: float = 30.0, seed: int = 0, n_joints: int = 12,
    median_len_s: float = 0.6, take_s: float = 60.0, n_interrupts: int = 3,
    tag_fraction: float = 0.03, tags: tuple[str, ...] = ("wave", "point"),
) -> ControlLibrary:
    """A synthetic :class:`ControlLibrary` about ``duration_s`` seconds long.

    Args:
        duration_s: total length of all segments (s).
        fps: frame rate (Hz).
        seed: random seed (the library is a deterministic function of all arguments).
        n_joints: number of joint-angle columns.
        median_len_s: median segment length (s); lengths are log-normal (sigma 0.45), 4..60 frames.
        take_s: length of each source take (s); segments are consecutive within a take.
        n_interrupts: interruption frames per segment.
        tag_fraction: fraction of segments given each tag in ``tags`` (at least one each).
    """
    rng = np.random.default_rng(seed)
    total = int(round(duration_s * fps))
    med = median_len_s * fps
    lengths: list[int] = []
    take_id: list[int] = []
    starts: list[int] = []
    takes: list[np.ndarray] = []
    remaining = total
    tk = 0
    while remaining > 0:
        take_frames = min(remaining, int(take_s * fps))
        seg_l: list[int] = []
        acc = 0
        while acc < take_frames:
            ln = int(np.clip(round(med * np.exp(0.45 * rng.standard_normal())), 4, 60))
            ln = min(ln, take_frames - acc) if take_frames - acc >= 4 else ln
            seg_l.append(ln)
            acc += ln
        takes.append(_take(rng, acc, n_joints, fps))
        pos = 0
        for ln in seg_l:
            lengths.append(ln)
            take_id.append(tk)
            starts.append(pos)
            pos += ln
        remaining -= acc
        tk += 1
    n = len(lengths)
    lengths_a = np.array(lengths, dtype=np.int64)
    take_a = np.array(take_id)
    starts_a = np.array(starts, dtype=np.int64)
    qpos = [takes[take_a[i]][starts_a[i]:starts_a[i] + lengths_a[i]] for i in range(n)]

    # kinematic parameters from the joint angles (log scale, then z-scored like W_X/B_X)
    raw = np.empty((n, 6))
    for i, q in enumerate(qpos):
        q = q.astype(float)
        v = np.gradient(q, 1 / fps, axis=0) if len(q) > 1 else np.zeros_like(q)
        a = np.gradient(v, 1 / fps, axis=0) if len(q) > 1 else np.zeros_like(q)
        sp = np.linalg.norm(v, axis=1)
        raw[i] = (len(q) / fps, np.linalg.norm(q - q[0], axis=1).mean() + 1e-3, sp.mean() + 1e-3,
                  np.linalg.norm(a, axis=1).mean() + 1e-2,
                  (np.linalg.norm(a, axis=1) / np.maximum(sp, 0.05) ** 2).mean() + 1e-2,
                  np.exp(q[:, 0].mean()))
    logs = np.log(raw)
    params = (logs - np.median(logs, axis=0)) / np.maximum(logs.std(axis=0), 1e-6)

    interrupts = np.array([uniform_interrupts(int(ln), n_interrupts) for ln in lengths_a],
                          dtype=np.int64)
    first = np.stack([q[0] for q in qpos]).astype(float)
    last = np.stack([q[-1] for q in qpos]).astype(float)
    inter = np.stack([q[interrupts[i]] for i, q in enumerate(qpos)]).astype(float)  # (n, K, J)
    pose_w = 10.0 / np.sqrt(n_joints)

    def pdist(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        sq = (x * x).sum(1)[:, None] + (y * y).sum(1)[None] - 2 * x @ y.T
        return np.sqrt(np.maximum(sq, 0.0))

    loglen = np.log(lengths_a.astype(float))
    dyn = params[:, [1, 2]]
    d_seg = (np.abs(loglen[:, None] - loglen[None]) + pose_w * pdist(first, first)
             + 0.5 * pdist(dyn, dyn))
    np.fill_diagonal(d_seg, 0.0)
    same_next = np.r_[take_a[1:] == take_a[:-1], False]
    succ = np.where(same_next, np.arange(n) + 1, -1)
    pred = np.r_[-1, np.where(take_a[1:] == take_a[:-1], np.arange(n - 1), -1)]
    fallback = pose_w * pdist(last, first)
    term1 = np.where(succ[:, None] >= 0, d_seg[np.maximum(succ, 0), :], fallback)
    term2 = np.where(pred[None, :] >= 0, d_seg[:, np.maximum(pred, 0)], fallback)
    d_sp = term1 + term2
    penalty = float(np.median(d_sp))
    d_in = (pose_w * pdist(inter.reshape(n * n_interrupts, -1), first) + penalty
            ).reshape(n, n_interrupts, n)

    tag_list: list[list[str]] = [[] for _ in range(n)]
    for tag in tags:
        k = max(1, int(round(tag_fraction * n)))
        for i in rng.choice(n, size=min(k, n), replace=False):
            tag_list[int(i)].append(tag)

    fp = array_fingerprint(lengths_a, params, d_sp, extra=f"synthetic:{duration_s}:{fps}:{seed}")
    return ControlLibrary(
        lengths=lengths_a, interrupt_frames=interrupts, params=params, d_sp=d_sp, d_in=d_in,
        tags=tuple(tuple(t) for t in tag_list), fps=fps, fingerprint=fp, starts=starts_a,
        segment_qpos=lambda i: qpos[i], frame_features=lambda i: qpos[i].astype(float),
        pose_scale=pose_w, interrupt_penalty=penalty,
        joint_names=tuple(f"joint{j}" for j in range(n_joints)),
    )


def synthetic_model(
    library: ControlLibrary, n_states: int = 8, seed: int = 0, switch_rate_hz: float = 1.0,
) -> StateModel:
    """A :class:`StateModel` whose states cover the library's parameter distribution.

    Means are spread over the library's parameters (k-means++-style picks), covariances are a
    third of the library covariance, and the transition matrix keeps a state for about
    ``1 / switch_rate_hz`` seconds (one step = one frame at ``library.fps``).
    """
    rng = np.random.default_rng(seed)
    x = library.params
    idx = [int(rng.integers(len(x)))]
    for _ in range(1, n_states):
        d2 = np.min(((x[:, None, :] - x[idx][None]) ** 2).sum(-1), axis=1)
        idx.append(int(rng.choice(len(x), p=d2 / d2.sum())))
    means = x[idx] * 0.8
    cov = np.cov(x.T) / 3 + 0.02 * np.eye(6)
    covs = np.repeat(cov[None], n_states, axis=0)
    eps = switch_rate_hz / library.fps
    other = rng.dirichlet(np.ones(n_states), size=n_states)
    np.fill_diagonal(other, 0.0)
    other /= other.sum(axis=1, keepdims=True)
    trans = (1 - eps) * np.eye(n_states) + eps * other
    return StateModel(means=means, covs=covs, transition=trans)
