"""MIMiC, the motion graph of Okwechime 2011 (thesis Ch. 4), as a second control layer.

The MDP (:mod:`gesture_sim.control.controller`) and MIMiC both answer *which* piece of motion
plays next; the timing layer (:class:`~gesture_sim.control.synchrony.SyncPlayer`) decides *when*.
This module builds the graph from a :class:`~gesture_sim.control.inputs.ControlLibrary`, stores
it, and chooses at run time with the interface the timing layer calls (:class:`MimicChooser`).

**Graph building** (:func:`build_graph`, thesis §4.3):

1. PCA of the poses (the library's per-frame key-point features, the thesis's "3D markers"),
   keeping 95 % of the energy (Eq. 3.1–3.2).
2. Cut points. The thesis takes the frames where the trajectory passes closest (a local minimum
   below θ) to one of N_c k-medoids of all frames. Here **the cut points are the segment
   boundaries** (each segment's first frame, plus the last frame of a clip's last segment), and
   the subsequences are the segments. Why: the timing layer, the stroke marks, the decision log
   and every metric work on segments, and a ``Decision`` names a segment; the segmentation
   already cuts where the hands slow down (hand-speed threshold crossings, Levine 2009), which is
   the thesis's "local minimum of motion" (``tools/mimic_bench.py`` measures how much slower the
   pose moves there). :func:`speed_minima` finds cut points in a raw motion the same way, for
   motions that are not segmented yet.
3. k-medoids (medoids are real cut points) of the cut-point poses in PCA space, N_c clusters;
   clusters with fewer than ``min_cluster`` cut points are pruned (their points join the next
   nearest medoid). N_c defaults to (number of subsequences) / 3.5, the mean ratio of the
   thesis's four data sets (228/61, 309/90, 230/53, 146/55). Only the *pool* (co-speech)
   segments are clustered — the motion MIMiC synthesises; tagged (emblem, acting) segments are
   assigned to the nearest medoid.
4. The subsequence table: per segment its start cluster and the cluster of its end point z, the
   next cut point in time (the successor's first frame, or its own last frame at a clip end).
5. The first-order Markov matrix between clusters by counting start → end clusters along the
   pool segments, plus a nominal ``smoothing`` count on every entry, row-normalised (§4.3.2).

**Density model** (§3.3, Eq. 3.3–3.7): Gaussian kernels on every pool frame in pose space
(widths α√λ_i) and in pose-velocity space (widths α·(√λ_i, σ_i), σ_i the std of the forward
differences Δy), summed over the ``n_neighbours`` nearest kernels found with a kd-tree
(:class:`scipy.spatial.cKDTree`, Eq. 3.5). The width factor α is chosen by held-out
log-likelihood (5 contiguous folds, so that neighbouring, nearly identical frames cannot vouch
for each other; exact kernel sums) over :data:`ALPHA_GRID` (1/16 .. 2 in steps of √2); the
thesis's fixed α = 0.25 is an option (``alpha=0.25``). On the default library the CV picks
0.71, which is also Scott's factor there. The densities enter each transition twice: the pose
density of the candidate's end point P'(z) (Eq. 4.1) and the pose-velocity density
P'(y_t, Δy_j) of the candidate's first movement applied at the current pose (the movement test
of Eq. 3.9, which guards against the reverse-motion risk the thesis names; it favours velocity
continuity, hence the source order — ``MimicChooser(motion_weight=0)`` leaves it out).

**Run time** (:class:`MimicChooser`, §4.3.3–4.4): at a cut point y_t in cluster C_t, the
candidates are the pool segments that start in C_t; each is scored

    φ_j = P(C^z_j | C_t) · P'(z_j) · P'(y_t, Δy_j) · W(C^z_j) · Λ(C^z_j) · style_j

and drawn by roulette wheel (Eq. 4.2). W is the projection mapping (Eq. 4.5–4.7) from the speech
to clusters: the input symbols are the inference model's hidden kinematic states; a segment's
symbol is the state whose output Gaussian explains its kinematic parameters (soft
responsibilities); P(C_q | state r) = Σ responsibilities of the pool segments ending in C_q /
Σ responsibilities of r — the thesis's |C_q ∩ E_r| / N_r with soft counts — and
W(q) = Σ_r b(r) P(C_q | r), the expectation of the thesis's W under the belief b. Λ is the
destination-driven look-ahead (§4.3.4): a trellis ``lookahead`` (u = 3) levels deep over the
cluster graph weighted by M · W, its most probable level-u state d*, and for each candidate the
best (max-product, dynamic programming) path from its end cluster to d*. ``style_j`` =
exp(style_gain · dial · e_j), e_j the z-scored log displacement + log velocity of the segment
(not in the thesis; the product's style dial).

Product rules the thesis does not have: decisions also at interruption frames when the timing
layer asks for an early switch (the interruption frame acts as a cut point of its nearest
cluster); a pending semantic label switches at the next decision point into a segment with that
tag (drawn by roulette over P(start cluster | C_t) · P'(y_t, Δy_j)); after rest the current cut
point is the pool start nearest the rest pose.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from gesture_sim.contracts import Decision
from gesture_sim.control.inputs import ControlLibrary, StateModel, array_fingerprint
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path

#: File name of the graph next to its library.
GRAPH_FILE = "mimic_graph.npz"
#: Version of the stored format.
FORMAT_VERSION = 1
#: The thesis's kernel width factor (all its data sets).
THESIS_ALPHA = 0.25
#: Width factors tried by the cross-validation: 1/16 .. 2 in steps of √2 (the thesis's
#: Fig. 3.3 values 0.0625, 0.25 and 1 among them).
ALPHA_GRID = tuple(round(0.0625 * 2 ** (k / 2), 4) for k in range(11))
#: Mean number of subsequences per cluster in the thesis's four MIMiC data sets.
SUBSEQ_PER_CLUSTER = 3.5
#: Arrays stored in a graph file besides ``meta``.
_ARRAYS = ("pca_mean", "pca_components", "pca_eigvals", "medoids", "medoid_point", "counts",
           "markov", "start_pose", "start_vel", "end_pose", "start_cluster", "end_cluster",
           "end_density", "interrupt_pose", "interrupt_cluster", "pool", "energy",
           "kde_centres", "kde_widths")


# ---------------------------------------------------------------------------- building blocks
@dataclass
class PCA:
    """A PCA basis: ``y = components @ (x - mean)``; eigvals (d,) descending."""

    mean: np.ndarray
    components: np.ndarray
    eigvals: np.ndarray

    def project(self, x: np.ndarray) -> np.ndarray:
        """(m, D) -> (m, d)."""
        return (np.asarray(x, float) - self.mean) @ self.components.T


def fit_pca(x: np.ndarray, energy: float = 0.95) -> tuple[PCA, float]:
    """PCA of the rows of ``x`` (N, D) keeping the fewest components with >= ``energy`` of the
    variance (Eq. 3.1–3.2). Returns the basis and the energy kept."""
    x = np.asarray(x, float)
    mean = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    lam = s ** 2 / len(x)
    total = lam.sum()
    if total <= 0:
        return PCA(mean, vt[:1], np.maximum(lam[:1], 1e-12)), 1.0
    cum = np.cumsum(lam) / total
    d = int(np.searchsorted(cum, energy - 1e-12) + 1)
    d = min(max(d, 1), len(lam))
    # a deterministic sign: the largest-magnitude entry of each component positive
    comps = vt[:d] * np.sign(vt[:d][np.arange(d), np.argmax(np.abs(vt[:d]), axis=1)])[:, None]
    return PCA(mean, comps, np.maximum(lam[:d], 1e-12)), float(cum[d - 1])


def speed_minima(y: np.ndarray, min_gap: int = 2) -> np.ndarray:
    """Cut points of a raw motion: frames where the pose speed (central difference of the
    ``(T, d)`` trajectory, per frame) has a local minimum; the first and last frames are cut
    points too. Minima closer than ``min_gap`` frames keep the slower one."""
    y = np.asarray(y, float)
    t = len(y)
    if t < 3:
        return np.arange(t)
    v = np.empty(t)
    v[1:-1] = np.linalg.norm(y[2:] - y[:-2], axis=1) / 2
    v[0], v[-1] = np.linalg.norm(y[1] - y[0]), np.linalg.norm(y[-1] - y[-2])
    idx = [i for i in range(1, t - 1) if v[i] <= v[i - 1] and v[i] < v[i + 1]]
    kept: list[int] = []
    for i in idx:
        if kept and i - kept[-1] < min_gap:
            if v[i] < v[kept[-1]]:
                kept[-1] = i
            continue
        kept.append(i)
    return np.array(sorted({0, *kept, t - 1}), dtype=np.int64)


def _pdist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None] - 2 * a @ b.T
    return np.sqrt(np.maximum(sq, 0.0))


def kmedoids(x: np.ndarray, k: int, seed: int = 0, n_init: int = 5,
             max_iter: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """k-medoids (Voronoi iteration, k-medoids++ starts) of the rows of ``x`` (m, d), L2.

    Returns the medoid row indices (k,), ascending, and each row's cluster (m,) (index into the
    medoids). The best of ``n_init`` seeded starts (lowest total distance) is kept, so the
    result is a deterministic function of the arguments.
    """
    x = np.asarray(x, float)
    m = len(x)
    k = int(min(max(k, 1), m))
    dist = _pdist(x, x)
    rng = np.random.default_rng(seed)
    best: tuple[float, np.ndarray] | None = None
    for _ in range(n_init):
        med = [int(rng.integers(m))]
        for _ in range(1, k):
            d2 = dist[:, med].min(axis=1) ** 2
            if d2.sum() <= 0:
                rest = np.setdiff1d(np.arange(m), med)
                med.append(int(rest[rng.integers(len(rest))]))
            else:
                med.append(int(rng.choice(m, p=d2 / d2.sum())))
        med_a = np.array(med)
        for _ in range(max_iter):
            lab = np.argmin(dist[:, med_a], axis=1)
            new = med_a.copy()
            for c in range(k):
                members = np.nonzero(lab == c)[0]
                if len(members):
                    new[c] = members[np.argmin(dist[np.ix_(members, members)].sum(axis=1))]
            if np.array_equal(new, med_a):
                break
            med_a = new
        cost = float(dist[:, med_a].min(axis=1).sum())
        if best is None or cost < best[0] - 1e-12:
            best = (cost, med_a)
    med_a = np.unique(best[1])
    return med_a, np.argmin(dist[:, med_a], axis=1)


def prune_clusters(x: np.ndarray, medoids: np.ndarray, min_size: int) -> tuple[np.ndarray,
                                                                                np.ndarray]:
    """Drop the medoids of clusters with fewer than ``min_size`` members, smallest first
    (their points join the next nearest medoid). Returns (medoids, labels)."""
    x = np.asarray(x, float)
    med = np.asarray(medoids)
    while True:
        lab = np.argmin(_pdist(x, x[med]), axis=1)
        sizes = np.bincount(lab, minlength=len(med))
        if len(med) <= 1 or sizes.min() >= min_size:
            return med, lab
        med = np.delete(med, int(np.argmin(sizes)))


def markov_matrix(src: np.ndarray, dst: np.ndarray, n: int,
                  smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """Counts (n, n) of ``src[i] -> dst[i]`` and the row-stochastic matrix after adding
    ``smoothing`` to every entry (§4.3.2)."""
    counts = np.zeros((n, n))
    np.add.at(counts, (np.asarray(src), np.asarray(dst)), 1.0)
    sm = counts + smoothing
    return counts, sm / sm.sum(axis=1, keepdims=True)


class KernelDensity:
    """Sum of isotropic Gaussians (in whitened units) over the ``n_neighbours`` nearest kernels.

    Args:
        centres: (N, D) kernel centres; widths: (D,) kernel standard deviations per dimension.
    :meth:`density` is the thesis's P' (Eq. 3.5: the mean kernel value over the neighbours, in
    [0, 1]); :meth:`log_pdf` is the normalised log density (for the cross-validation).
    """

    def __init__(self, centres: np.ndarray, widths: np.ndarray, n_neighbours: int = 32) -> None:
        self.centres = np.asarray(centres, float)
        self.widths = np.maximum(np.asarray(widths, float), 1e-9)
        self.k = int(min(n_neighbours, len(self.centres)))
        self.tree = cKDTree(self.centres / self.widths)

    def _d2(self, x: np.ndarray) -> np.ndarray:
        d, _ = self.tree.query(np.atleast_2d(np.asarray(x, float)) / self.widths, k=self.k)
        d = np.asarray(d).reshape(len(np.atleast_2d(x)), self.k)
        return d * d

    def log_density(self, x: np.ndarray) -> np.ndarray:
        """(m,) log P'(x) (Eq. 3.5), computed stably."""
        q = -0.5 * self._d2(x)
        top = q.max(axis=1)
        return top + np.log(np.exp(q - top[:, None]).mean(axis=1))

    def density(self, x: np.ndarray) -> np.ndarray:
        return np.exp(self.log_density(x))

    def log_pdf(self, x: np.ndarray) -> np.ndarray:
        """(m,) log of the normalised mixture ``(1/N) Σ_i N(x; c_i, diag(widths²))`` (the
        kernels beyond the nearest ``n_neighbours`` neglected)."""
        dim = self.centres.shape[1]
        norm = -np.log(self.widths).sum() - 0.5 * dim * np.log(2 * np.pi)
        return self.log_density(x) + np.log(self.k / len(self.centres)) + norm


def exact_log_pdf(centres: np.ndarray, widths: np.ndarray, x: np.ndarray,
                  chunk: int = 512) -> np.ndarray:
    """(m,) log of ``(1/N) Σ_i N(x; c_i, diag(widths²))`` summed over every kernel."""
    c = np.asarray(centres, float) / widths
    x = np.asarray(x, float) / widths
    norm = -np.log(widths).sum() - 0.5 * c.shape[1] * np.log(2 * np.pi) - np.log(len(c))
    out = np.empty(len(x))
    cc = (c * c).sum(1)
    for s in range(0, len(x), chunk):
        xs = x[s:s + chunk]
        q = -0.5 * np.maximum((xs * xs).sum(1)[:, None] + cc[None] - 2 * xs @ c.T, 0.0)
        top = q.max(axis=1)
        out[s:s + chunk] = top + np.log(np.exp(q - top[:, None]).sum(axis=1)) + norm
    return out


def cv_alpha(points: np.ndarray, base_widths: np.ndarray, alphas=ALPHA_GRID,
             folds: int = 5) -> dict[float, float]:
    """Mean held-out log-likelihood per point for each width factor α (kernel widths
    α · base_widths), with ``folds`` contiguous folds of the ``(N, D)`` points and the exact
    kernel sum (the nearest-neighbour truncation would favour narrow kernels)."""
    n = len(points)
    edges = np.linspace(0, n, folds + 1).astype(int)
    out: dict[float, float] = {}
    for a in alphas:
        ll = []
        for f in range(folds):
            test = np.arange(edges[f], edges[f + 1])
            train = np.setdiff1d(np.arange(n), test)
            if len(train) == 0 or len(test) == 0:
                continue
            ll.append(exact_log_pdf(points[train], a * np.asarray(base_widths, float),
                                    points[test]))
        out[float(a)] = float(np.concatenate(ll).mean())
    return out


# ---------------------------------------------------------------------------- the graph
@dataclass
class MotionGraph:
    """A MIMiC graph over a library's segments (see the module docstring).

    Arrays (n segments, N_c clusters, d PCA dims, K interruption frames):
        pca_mean (D,), pca_components (d, D), pca_eigvals (d,): the pose space.
        medoids (N_c, d): medoid poses; medoid_point (N_c,): the segment whose first frame is the
            medoid (or ``-1 - i`` for the end point of segment i).
        counts, markov (N_c, N_c): transition counts and the smoothed Markov matrix.
        start_pose, end_pose (n, d): the segments' cut points z (end = next cut point in time);
            start_vel (n, d): their first forward difference Δy.
        start_cluster, end_cluster (n,): clusters of the start and end cut points.
        end_density (n,): log P'(z) of the end cut point (pose KDE).
        interrupt_pose (n, K, d), interrupt_cluster (n, K): interruption frames as cut points.
        pool (n,) bool: the segments clustered (co-speech); energy (n,): style score.
        kde_centres (N, 2d), kde_widths (2d,): the pose-velocity kernels (pose = first d).
    """

    pca_mean: np.ndarray
    pca_components: np.ndarray
    pca_eigvals: np.ndarray
    medoids: np.ndarray
    medoid_point: np.ndarray
    counts: np.ndarray
    markov: np.ndarray
    start_pose: np.ndarray
    start_vel: np.ndarray
    end_pose: np.ndarray
    start_cluster: np.ndarray
    end_cluster: np.ndarray
    end_density: np.ndarray
    interrupt_pose: np.ndarray
    interrupt_cluster: np.ndarray
    pool: np.ndarray
    energy: np.ndarray
    kde_centres: np.ndarray
    kde_widths: np.ndarray
    meta: dict = field(default_factory=dict)

    @property
    def n_clusters(self) -> int:
        return int(len(self.medoids))

    @property
    def n_segments(self) -> int:
        return int(len(self.start_cluster))

    @property
    def dims(self) -> int:
        return int(self.pca_components.shape[0])

    @property
    def library_fingerprint(self) -> str:
        return str(self.meta.get("library_fingerprint", ""))

    def pca(self) -> PCA:
        return PCA(self.pca_mean, self.pca_components, self.pca_eigvals)

    def motion_kde(self, n_neighbours: int | None = None) -> KernelDensity:
        """The pose-velocity density P'(y, Δy) (2d dims)."""
        return KernelDensity(self.kde_centres, self.kde_widths,
                             n_neighbours or int(self.meta.get("n_neighbours", 32)))

    def pose_kde(self, n_neighbours: int | None = None) -> KernelDensity:
        """The pose density P'(y) (d dims)."""
        d = self.dims
        return KernelDensity(self.kde_centres[:, :d], self.kde_widths[:d],
                             n_neighbours or int(self.meta.get("n_neighbours", 32)))

    # ------------------------------------------------------------------ storage
    def check(self, library: ControlLibrary) -> None:
        """Raise :class:`GestureSimError` if this graph is not for ``library``."""
        if self.library_fingerprint != library.fingerprint:
            raise GestureSimError(
                f"motion graph was built for library {self.library_fingerprint}, not "
                f"{library.fingerprint}; rebuild it with `gesture-sim library graph`")

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the graph to ``path`` (.npz, compressed) atomically."""
        meta = dict(self.meta, format_version=FORMAT_VERSION)
        arrays = {k: getattr(self, k) for k in _ARRAYS}
        with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str],
             library_fingerprint: str | None = None) -> MotionGraph:
        """Read a graph; refuse another format version, another library or a damaged file."""
        import zipfile

        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            meta = json.loads(str(arrays.pop("meta")))
        except FileNotFoundError as exc:
            raise GestureSimError(f"no motion graph at {path}; build it with "
                                  "`gesture-sim library graph LIBRARY`") from exc
        except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
            raise GestureSimError(f"{path}: damaged motion graph ({type(exc).__name__}); "
                                  "rebuild it with `gesture-sim library graph`") from exc
        if meta.get("format_version") != FORMAT_VERSION:
            raise GestureSimError(f"motion graph {path} has format {meta.get('format_version')},"
                                  f" expected {FORMAT_VERSION}; rebuild it")
        missing = [k for k in _ARRAYS if k not in arrays]
        if missing:
            raise GestureSimError(f"motion graph {path} lacks {', '.join(missing)}; rebuild it")
        if library_fingerprint is not None and meta.get("library_fingerprint") != \
                library_fingerprint:
            raise GestureSimError(
                f"motion graph {path} was built for library {meta.get('library_fingerprint')}, "
                f"not {library_fingerprint}; rebuild it with `gesture-sim library graph`")
        return cls(meta=meta, **{k: arrays[k] for k in _ARRAYS})


def _segment_frames(library: ControlLibrary, i: int) -> np.ndarray:
    return np.asarray(library.features(i), dtype=float)


def build_graph(library: ControlLibrary, n_clusters: int | None = None, energy: float = 0.95,
                smoothing: float = 0.05, alpha: float | str = "cv", n_neighbours: int = 32,
                min_cluster: int = 2, seed: int = 0) -> MotionGraph:
    """Build the MIMiC graph of ``library`` (see the module docstring).

    Args:
        library: the control library (needs per-frame features or joint poses).
        n_clusters: N_c (default: pool segments / :data:`SUBSEQ_PER_CLUSTER`, at least 2).
        energy: PCA energy kept (thesis: 0.95).
        smoothing: nominal count added to every Markov entry before normalising.
        alpha: kernel width factor, or ``"cv"`` to choose it by held-out likelihood over
            :data:`ALPHA_GRID`.
        n_neighbours: kernels summed per density query (N_n of Eq. 3.5).
        min_cluster: clusters with fewer cut points are pruned.
        seed: seeds the k-medoids starts.
    """
    t0 = time.perf_counter()
    n, k_int = library.n_segments, library.n_interrupts
    pool = np.asarray(library.cospeech, dtype=bool).copy()
    frames = [_segment_frames(library, i) for i in range(n)]
    pool_idx = np.nonzero(pool)[0]
    pose_all = np.concatenate([frames[i] for i in pool_idx])
    pca, kept = fit_pca(pose_all, energy)
    ys = [pca.project(f) for f in frames]
    d = pca.components.shape[0]
    succ = np.asarray(library.successors, dtype=np.int64)

    start_pose = np.stack([y[0] for y in ys])
    end_own = np.stack([y[-1] for y in ys])
    has_next = (succ >= 0) & (succ < n)
    end_pose = np.where(has_next[:, None], start_pose[np.clip(succ, 0, n - 1)], end_own)
    start_vel = np.stack([y[1] - y[0] for y in ys])

    # cut points clustered: the pool segments' first frames, plus the end points of pool
    # segments whose successor is not a pool segment (a clip's last subsequence)
    tail = [i for i in pool_idx if not (has_next[i] and pool[succ[i]])]
    cut_pose = np.concatenate([start_pose[pool_idx], end_own[tail]])
    cut_id = np.concatenate([pool_idx, -1 - np.asarray(tail, dtype=np.int64)])
    n_sub = len(pool_idx)
    nc = int(n_clusters) if n_clusters else max(2, int(round(n_sub / SUBSEQ_PER_CLUSTER)))
    med, _ = kmedoids(cut_pose, nc, seed=seed)
    med, _ = prune_clusters(cut_pose, med, min_cluster)
    medoids = cut_pose[med]

    def nearest(p: np.ndarray) -> np.ndarray:
        return np.argmin(_pdist(np.atleast_2d(p), medoids), axis=1)

    start_cluster = nearest(start_pose)
    end_cluster = np.where(has_next, start_cluster[np.clip(succ, 0, n - 1)], nearest(end_own))
    counts, markov = markov_matrix(start_cluster[pool_idx], end_cluster[pool_idx],
                                   len(medoids), smoothing)

    inter = library.interrupt_frames
    interrupt_pose = np.stack([ys[i][inter[i]] for i in range(n)]) if k_int else \
        np.zeros((n, 0, d))
    interrupt_cluster = (nearest(interrupt_pose.reshape(-1, d)).reshape(n, k_int) if k_int
                         else np.zeros((n, 0), np.int64))

    # density model over the pool frames: pose and forward-difference velocity (Eq. 3.6)
    vel = [np.vstack([np.diff(ys[i], axis=0), ys[i][-1:] - ys[i][-2:-1]]) for i in pool_idx]
    pts = np.hstack([np.concatenate([ys[i] for i in pool_idx]), np.concatenate(vel)])
    base = np.concatenate([np.sqrt(pca.eigvals), np.maximum(pts[:, d:].std(axis=0), 1e-9)])
    t_cv = time.perf_counter()
    cv = {}
    if alpha == "cv":
        cv = cv_alpha(pts, base)
        a = max(cv, key=cv.get)
    else:
        a = float(alpha)
        if not a > 0:
            raise GestureSimError(f"kernel width factor must be > 0, got {alpha}")
    t_cv = time.perf_counter() - t_cv
    widths = a * base
    pose_kde = KernelDensity(pts[:, :d], widths[:d], n_neighbours)
    end_density = pose_kde.log_density(end_pose)

    p = np.asarray(library.params, float)
    e = p[:, 1] + p[:, 2]                              # log displacement + log velocity
    mu, sd = e[pool].mean(), max(e[pool].std(), 1e-9)
    energy_score = (e - mu) / sd

    build_s = time.perf_counter() - t0
    sizes = np.bincount(start_cluster[pool_idx], minlength=len(medoids))
    meta = {
        "library_fingerprint": library.fingerprint,
        "settings": {"n_clusters": nc, "energy": energy, "smoothing": smoothing,
                     "alpha": alpha, "n_neighbours": n_neighbours, "min_cluster": min_cluster,
                     "seed": seed},
        "alpha": a, "alpha_cv": {str(k): v for k, v in cv.items()},
        "scott_factor": float(len(pts) ** (-1.0 / (pts.shape[1] + 4))),
        "n_neighbours": n_neighbours, "pca_dims": d, "pca_energy": kept,
        "n_subsequences": n_sub, "n_cut_points": len(cut_pose), "n_clusters": len(medoids),
        "pool_starts_per_cluster": sizes.tolist(), "kernels": len(pts),
        "build_s": build_s, "cv_s": t_cv,
    }
    g = MotionGraph(
        pca_mean=pca.mean, pca_components=pca.components, pca_eigvals=pca.eigvals,
        medoids=medoids, medoid_point=cut_id[med], counts=counts, markov=markov,
        start_pose=start_pose, start_vel=start_vel, end_pose=end_pose,
        start_cluster=start_cluster.astype(np.int64), end_cluster=end_cluster.astype(np.int64),
        end_density=end_density, interrupt_pose=interrupt_pose,
        interrupt_cluster=interrupt_cluster.astype(np.int64), pool=pool, energy=energy_score,
        kde_centres=pts.astype(np.float32), kde_widths=widths, meta=meta)
    g.meta["graph_fingerprint"] = array_fingerprint(*(getattr(g, k) for k in _ARRAYS))
    return g


def graph_path(library_dir: str | os.PathLike[str]) -> Path:
    """Where a library's graph is stored: ``<library_dir>/mimic_graph.npz``."""
    return Path(library_dir) / GRAPH_FILE


def load_graph(library: ControlLibrary, library_dir: str | os.PathLike[str],
               build_if_missing: bool = True, **settings) -> MotionGraph:
    """The graph stored next to the library; built (with ``settings``) and saved there when it
    is missing or was built for another library (if the folder is writable)."""
    path = graph_path(library_dir)
    if path.exists():
        try:
            return MotionGraph.load(path, library.fingerprint)
        except GestureSimError:
            if not build_if_missing:
                raise
    elif not build_if_missing:
        raise GestureSimError(f"no motion graph at {path}; build it with "
                              f"`gesture-sim library graph {library_dir}`")
    graph = build_graph(library, **settings)
    if os.access(path.parent, os.W_OK):
        graph.save(path)
    return graph


# ---------------------------------------------------------------------------- run time
def projection_mapping(graph: MotionGraph, library: ControlLibrary,
                       model: StateModel) -> np.ndarray:
    """(S, N_c) P(C_q | state r) (Eq. 4.5 with soft counts): the responsibility of each hidden
    state for each pool segment's kinematic parameters, summed over the segments ending in
    cluster q, normalised per state."""
    from scipy.stats import multivariate_normal

    pool = np.nonzero(graph.pool)[0]
    x = np.asarray(library.params, float)[pool]
    ll = np.stack([multivariate_normal(m, c, allow_singular=True).logpdf(x)
                   for m, c in zip(model.means, model.covs, strict=True)], axis=1)  # (m, S)
    ll = np.atleast_2d(ll)
    resp = np.exp(ll - ll.max(axis=1, keepdims=True))
    resp /= resp.sum(axis=1, keepdims=True)
    onehot = np.zeros((len(pool), graph.n_clusters))
    onehot[np.arange(len(pool)), graph.end_cluster[pool]] = 1.0
    joint = resp.T @ onehot                                        # (S, N_c)
    tot = joint.sum(axis=1, keepdims=True)
    return np.where(tot > 0, joint / np.maximum(tot, 1e-300), 1.0 / graph.n_clusters)


class MimicChooser:
    """MIMiC's run-time choice behind the timing layer (interface of
    :class:`~gesture_sim.control.protocols.SegmentChooser`).

    Args:
        graph: the library's :class:`MotionGraph` (checked against its fingerprint).
        library: the control library.
        seed: seeds the roulette wheel (the chooser is deterministic for a seed).
        model: the inference model's states (for the projection mapping from the belief);
            without it W is uniform (no speech input reaches the choice).
        lookahead: trellis depth u (thesis: 3); 1 turns the look-ahead off.
        style_gain: strength of the style dial's bias toward large, fast segments.
        input_floor: added to W before normalising (the thesis has no fallback when W = 0).
        motion_weight: exponent of the pose-velocity term P'(y_t, Δy_j) (1: as built; 0: the
            thesis's Eq. 4.1 with the pose density only). It favours velocity continuity and so
            the source order; lower it for more variety.
    """

    def __init__(self, graph: MotionGraph, library: ControlLibrary, seed: int = 0,
                 model: StateModel | None = None, lookahead: int = 3, style_gain: float = 1.0,
                 input_floor: float = 1e-3, motion_weight: float = 1.0) -> None:
        graph.check(library)
        if lookahead < 1:
            raise GestureSimError(f"look-ahead depth must be >= 1, got {lookahead}")
        self.graph = graph
        self.library = library
        self.seed = seed
        self.lookahead = int(lookahead)
        self.style_gain = float(style_gain)
        self.input_floor = float(input_floor)
        self.motion_weight = float(motion_weight)
        self.tags = library.all_tags()
        n, nc = library.n_segments, graph.n_clusters
        self.n_last = library.n_interrupts
        self._frames = library.decision_frames()
        self._points = library.decision_points()
        pool = np.asarray(library.cospeech, bool)
        self.pool = np.nonzero(pool)[0]
        self._by_cluster = [self.pool[graph.start_cluster[self.pool] == c] for c in range(nc)]
        self._avail = np.array([len(x) > 0 for x in self._by_cluster])
        self._log_m = np.log(graph.markov)
        self._kde = graph.motion_kde()
        self.mapping = (projection_mapping(graph, library, model) if model is not None
                        else None)
        self.n_states = model.n_states if model is not None else None
        # the rest pose's cut point: the pool start nearest the rest pose
        self._rest_seg = int(self.pool[0])
        if library.rest_pose is not None and library.segment_qpos is not None:
            q0 = np.stack([np.asarray(library.segment_qpos(int(i)))[0] for i in self.pool])
            self._rest_seg = int(self.pool[np.argmin(
                np.linalg.norm(q0 - np.asarray(library.rest_pose), axis=1))])
        self._cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self.style = 0.0
        self._style_log = np.zeros(n)
        self.reset()

    # ------------------------------------------------------------------ settings
    def reset(self) -> None:
        """Forget the pending label and the decision log; reseed the roulette."""
        self.rng = np.random.default_rng(self.seed)
        self.label = 0
        self._label_t = 0.0
        self.decisions: list[Decision] = []

    def set_style(self, dial: float) -> None:
        """The style dial in [-1, 1]: > 0 favours large, fast segments, < 0 small, slow ones."""
        self.style = float(np.clip(dial, -1.0, 1.0))
        self._style_log = self.style_gain * self.style * self.graph.energy

    def request_label(self, label: str, t: float | None = None) -> bool:
        """Ask for a semantic gesture; False if no segment carries the tag."""
        if label not in self.tags:
            return False
        self.label = self.tags.index(label) + 1
        self._label_t = 0.0 if t is None else float(t)
        return True

    def decision_point(self, segment: int, frame: int) -> int:
        """The decision point index at a frame (interruption frames 0..K-1, the last frame K),
        or -1."""
        return int(self._points[segment].get(int(frame), -1))

    # ------------------------------------------------------------------ weights
    def input_weights(self, belief: np.ndarray | None) -> np.ndarray:
        """(N_c,) W: the belief-weighted projection mapping (uniform without a model)."""
        nc = self.graph.n_clusters
        if self.mapping is None or belief is None:
            return np.full(nc, 1.0 / nc)
        b = np.asarray(belief, float).ravel()
        if b.shape != (self.n_states,):
            raise GestureSimError(f"belief has shape {b.shape}, the model has "
                                  f"{self.n_states} states")
        tot = b.sum()
        b = b / tot if tot > 0 else np.full(len(b), 1.0 / len(b))
        w = b @ self.mapping + self.input_floor
        return w / w.sum()

    def lookahead_log(self, c: int, w: np.ndarray) -> np.ndarray:
        """(N_c,) log Λ: the best path score from each cluster to the most probable level-u
        state of the trellis from cluster ``c`` (0 everywhere when u = 1)."""
        u = self.lookahead
        if u <= 1:
            return np.zeros(self.graph.n_clusters)
        g = self.graph.markov * w[None, :] * np.where(self._avail, 1.0, 1e-3)[None, :]
        alpha = np.zeros(len(g))
        alpha[c] = 1.0
        for _ in range(u):
            alpha = alpha @ g
            alpha /= alpha.sum()
        dest = int(np.argmax(alpha))
        beta = np.full(len(g), -np.inf)
        beta[dest] = 0.0
        lg = np.log(g)
        for _ in range(u - 1):
            beta = np.max(lg + beta[None, :], axis=1)
        return beta - beta.max()

    def _motion(self, key: tuple, y: np.ndarray, cand: np.ndarray) -> np.ndarray:
        """log P'(y, Δy_j) for the candidates (cached per decision point)."""
        hit = self._cache.get(key)
        if hit is not None and np.array_equal(hit[0], cand):
            return hit[1]
        q = np.hstack([np.repeat(y[None], len(cand), axis=0), self.graph.start_vel[cand]])
        val = self._kde.log_density(q)
        self._cache[key] = (cand, val)
        return val

    def _roulette(self, logw: np.ndarray) -> tuple[int, np.ndarray]:
        w = np.exp(logw - logw.max())
        p = w / w.sum()
        r = self.rng.random()
        j = int(np.searchsorted(np.cumsum(p), r * (1.0 - 1e-12), side="left"))
        return min(j, len(p) - 1), p

    # ------------------------------------------------------------------ decisions
    def _current(self, a: int, k: int) -> tuple[np.ndarray, int]:
        g = self.graph
        if a < 0:
            s = self._rest_seg
            return g.start_pose[s], int(g.start_cluster[s])
        if k >= self.n_last:
            return g.end_pose[a], int(g.end_cluster[a])
        return g.interrupt_pose[a, k], int(g.interrupt_cluster[a, k])

    def _label_decision(self, y: np.ndarray, c: int, key: tuple, t: float, kind: str,
                        a: int) -> Decision:
        tag = self.tags[self.label - 1]
        cand = self.library.segments_with_tag(tag)
        logw = (self._log_m[c, self.graph.start_cluster[cand]]
                + self.motion_weight * self._motion(key, y, cand))
        j, p = self._roulette(logw)
        seg = int(cand[j])
        costs = {"continue": 0.0, "p": float(p[j]), "candidates": float(len(cand)),
                 "label_delay": float(t - self._label_t)}
        self.label = 0
        return Decision(t=t, segment_id=seg, frame=int(self.library.starts[seg]), kind=kind,
                        costs=costs)

    def _choose(self, belief: np.ndarray, a: int, k: int, t: float, kind: str,
                exclude: int = -1) -> Decision | None:
        g = self.graph
        y, c = self._current(a, k)
        key = (a, k, self.label)
        if self.label:
            return self._label_decision(y, c, key, t, "label", a)
        cand = self._by_cluster[c]
        if exclude >= 0:
            cand = cand[cand != exclude]
        if len(cand) == 0:                    # no pool start here: the nearest cluster with one
            order = np.argsort(np.linalg.norm(g.medoids - y, axis=1))
            for c2 in order:
                cand = self._by_cluster[c2]
                cand = cand[cand != exclude] if exclude >= 0 else cand
                if len(cand):
                    break
            if len(cand) == 0:
                return None
        w = self.input_weights(belief)
        ez = g.end_cluster[cand]
        log_m = self._log_m[c, ez]
        log_w = np.log(w[ez])
        log_l = self.lookahead_log(c, w)[ez]
        logw = (log_m + g.end_density[cand] + self.motion_weight * self._motion(key, y, cand)
                + log_w + log_l + self._style_log[cand])
        j, p = self._roulette(logw)
        seg = int(cand[j])
        costs = {"continue": 0.0, "p": float(p[j]), "candidates": float(len(cand)),
                 "markov": float(np.exp(log_m[j])), "input": float(w[ez[j]]),
                 "cluster": float(c)}
        return Decision(t=t, segment_id=seg, frame=int(self.library.starts[seg]), kind=kind,
                        costs=costs)

    def decide_start(self, belief: np.ndarray, t: float) -> Decision:
        """The first segment of a stream or after rest (from the rest pose's cut point), or a
        segment with the pending label's tag."""
        d = self._choose(belief, -1, self.n_last, t, "start")
        self.decisions.append(d)
        return d

    def decide_at(self, belief: np.ndarray, a: int, k: int, t: float,
                  prefer_switch: bool = False) -> Decision:
        """The decision at decision point ``k`` of segment ``a``: at the last frame the roulette
        over the cluster of the end cut point; at an interruption frame continue, unless a label
        is pending or the timing layer prefers a switch (then the interruption frame acts as a
        cut point). ``Decision.frame`` is the clip frame to play next."""
        last = k >= self.n_last
        lib = self.library
        d = None
        if self.label and not last and self.tags[self.label - 1] in lib.tags[a]:
            # continuing a segment that carries the label satisfies it
            delay = float(t - self._label_t)
            self.label = 0
            return Decision(t=t, segment_id=a,
                            frame=int(lib.starts[a] + lib.interrupt_frames[a, k]), kind="label",
                            costs={"continue": 1.0, "label_delay": delay})
        if last or prefer_switch or self.label:
            d = self._choose(belief, a, k, t, "end" if last else "interrupt",
                             exclude=-1 if last else a)
        if d is None:
            return Decision(t=t, segment_id=a,
                            frame=int(lib.starts[a] + self._frames[a, k]),
                            kind="interrupt", costs={"continue": 1.0})
        self.decisions.append(d)
        return d
