"""The gesture-controller MDP and its value iteration (Gesture Controllers §7.2, Appendix A).

State and actions. A segment ``a`` of length ``L_a`` has ``K`` interruption frames and ``K + 1``
decision points ``F[a, 0..K]`` (the interruption frames, then the last frame ``L_a - 1``). At the
decision point ``(a, k)`` with hidden state ``i`` the controller chooses what plays from the next
frame on: *continue* (``k < K`` only) to the next decision point of ``a``, or *switch* to frame 0 of
any other segment ``a'``. Between decision points frames play automatically.

Costs and time (semi-MDP, discount λ per frame). A choice that plays ``τ`` frames before the next
decision point costs its smoothness term ``S`` at once, then ``Σ_{g=1..τ} λ^g (P^g η_a)(i)`` for the
frames (``P`` is the hidden-state transition matrix per frame, ``η_a`` the fit cost per frame), and
continues with ``λ^τ (P^τ U)(i)`` where ``U`` is the optimal value at the next decision point.
Continuing from ``k`` plays ``τ = F[a,k+1] − F[a,k]`` frames; switching to ``a'`` plays frames
``0..F[a',0]``, ``τ = F[a',0] + 1``. This is the Appendix A recursion with a consistent frame
count (the paper's λ exponents and sum limits are garbled in the source).

Like the paper's discrete MDP over hidden states, the value is computed as if the hidden state
were known at each decision point (a QMDP-style approximation); at run time the controller takes
``argmin_{a'} Σ_i b(i) V(a', a, k, i)`` with the current belief ``b``.

Structure used for speed. The value of switching to ``a'`` depends on the current ``(a, k)`` only
through the state-independent switch cost: ``V(a', a, k, i) = S(a, k, a') + W(a', i)`` where
``W(a', i)`` is the expected value of playing ``a'`` from frame 0 under state ``i``. The iteration
therefore stores only ``U`` (n, K+1, S) and ``W`` (n, S); the stored policy keeps this decomposed
form too (value rows plus per-point switch costs, :mod:`gesture_sim.control.policy`). One
Bellman sweep costs one min-plus product ``min_{a'} S(a, k, a') + W(a', i)`` — O(n² (K+1) S),
vectorised in chunks — plus O(n K S²) for the propagation. Value iteration is accelerated by
*modified policy iteration* (Puterman 1994 §6.5): after each full Bellman sweep (policy
improvement) the greedy policy is evaluated by cheap O(n K S²) sweeps, so only ~10–20 min-plus
products are needed instead of hundreds. The stopping rule is the standard one:
λ/(1−λ) · ‖B U − U‖∞ ≤ tolerance guarantees ‖U − U*‖∞ ≤ tolerance (every choice plays at least
one frame, so the Bellman operator B is a λ-contraction).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gesture_sim.control.costs import frame_distances
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.errors import GestureSimError

#: Policy codes in :class:`ValueSolution.policy` besides a segment index.
CONTINUE = -1
FIXED = -2


@dataclass
class Structure:
    """Decision points and sub-segment lengths of a library.

    Attributes:
        frames: (n, K+1) decision frames (offsets).
        tau_entry: (n,) frames played after switching into a segment: ``F[a, 0] + 1``.
        tau_cont: (n, K) frames played when continuing from point k: ``F[a, k+1] - F[a, k]``.
        valid: (n, K+1) bool, decision points where the controller can be (an interruption frame
            equal to the last frame is not one: the last frame decides).
    """

    frames: np.ndarray
    tau_entry: np.ndarray
    tau_cont: np.ndarray
    valid: np.ndarray

    @classmethod
    def from_library(cls, lib: ControlLibrary) -> Structure:
        f = lib.decision_frames()
        valid = np.concatenate([lib.valid_interrupts(), np.ones((lib.n_segments, 1), bool)], 1)
        return cls(frames=f, tau_entry=f[:, 0] + 1, tau_cont=np.diff(f, axis=1), valid=valid)

    @property
    def n_points(self) -> int:
        return int(self.frames.shape[1])

    def point_of_frame(self, a: int, f: int) -> int:
        """The decision point at frame ``f`` of segment ``a``, or -1 if none.

        With repeated frames (an interruption frame on the last frame) the last point wins.
        """
        hits = np.nonzero(self.frames[a] == f)[0]
        return int(hits[-1]) if len(hits) else -1


def propagators(trans: np.ndarray, discount: float, max_tau: int) -> tuple[np.ndarray, np.ndarray]:
    """Discounted multi-step transition sums.

    Args:
        trans: (S, S) row-stochastic P[i, j] = P(j | i) per frame.
        discount: λ per frame.
        max_tau: largest number of frames needed.

    Returns:
        G (max_tau+1, S, S) with ``G[τ] = Σ_{g=1..τ} λ^g P^g`` and D (max_tau+1, S, S) with
        ``D[τ] = λ^τ P^τ`` (``G[0] = 0``, ``D[0] = I``).
    """
    s = len(trans)
    g = np.zeros((max_tau + 1, s, s))
    d = np.zeros((max_tau + 1, s, s))
    d[0] = np.eye(s)
    for t in range(1, max_tau + 1):
        d[t] = discount * (d[t - 1] @ trans)
        g[t] = g[t - 1] + d[t]
    return g, d


@dataclass
class Pieces:
    """Per-segment fixed costs and propagators of the sub-segments (one tone).

    Attributes:
        c_entry: (n, S) fit cost of the frames played after switching in: ``G[τ_entry] η_a``.
        p_entry: (n, S, S) ``D[τ_entry]``.
        c_cont: (n, K, S) fit cost of continuing from point k: ``G[τ_cont] η_a``.
        p_cont: (n, K, S, S) ``D[τ_cont]``.
        g, d: the propagator tables of :func:`propagators`.
    """

    c_entry: np.ndarray
    p_entry: np.ndarray
    c_cont: np.ndarray
    p_cont: np.ndarray
    g: np.ndarray
    d: np.ndarray

    @classmethod
    def build(cls, st: Structure, eta: np.ndarray, trans: np.ndarray, discount: float,
              max_tau: int | None = None) -> Pieces:
        """Pieces for fit costs ``eta`` (n, S) (already weighted) and transition ``trans``."""
        need = int(st.frames[:, -1].max()) + 1      # longest sub-segment incl. semantic entries
        g, d = propagators(trans, discount, max(need, max_tau or 0))
        c_entry = np.einsum("aij,aj->ai", g[st.tau_entry], eta)
        c_cont = np.einsum("akij,aj->aki", g[st.tau_cont], eta)
        return cls(c_entry=c_entry, p_entry=d[st.tau_entry], c_cont=c_cont,
                   p_cont=d[st.tau_cont], g=g, d=d)

    def entry_values(self, u: np.ndarray) -> np.ndarray:
        """W (n, S): value of switching into each segment at frame 0, given U (n, K+1, S)."""
        return self.c_entry + np.einsum("aij,aj->ai", self.p_entry, u[:, 0])

    def continue_values(self, u_next: np.ndarray, k: int) -> np.ndarray:
        """(n, S): value of continuing from point k, given U at point k+1 (n, S)."""
        return self.c_cont[:, k] + np.einsum("aij,aj->ai", self.p_cont[:, k], u_next)


@dataclass
class ValueSolution:
    """A solved value function (one tone, one label state).

    Attributes:
        u: (n, K+1, S) optimal value at each decision point and hidden state.
        w: (n, S) value of switching into each segment (without the switch cost).
        cont: (n, K, S) value of continuing from each interruption point (without extras).
        policy: (n, K+1, S) greedy choice per state: a segment index, CONTINUE or FIXED.
        iterations: full Bellman sweeps (policy improvements).
        eval_sweeps: cheap policy-evaluation sweeps.
        residual: last Bellman residual ‖B U − U‖∞.
        error_bound: λ/(1−λ) · residual, a bound on ‖U − U*‖∞.
        seconds: wall time.
    """

    u: np.ndarray
    w: np.ndarray
    cont: np.ndarray
    policy: np.ndarray
    iterations: int
    eval_sweeps: int
    residual: float
    error_bound: float
    seconds: float


def _best_switch(s_k: np.ndarray, wt: np.ndarray, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """min / argmin over a' of ``s_k[a, a'] + wt[i, a']``: (n, S) values and indices."""
    n, s = s_k.shape[0], wt.shape[0]
    best = np.empty((n, s))
    arg = np.empty((n, s), dtype=np.int64)
    for lo in range(0, n, chunk):
        vals = s_k[lo:lo + chunk, None, :] + wt[None, :, :]        # (c, S, n)
        idx = np.argmin(vals, axis=2)
        arg[lo:lo + chunk] = idx
        best[lo:lo + chunk] = np.take_along_axis(vals, idx[..., None], axis=2)[..., 0]
    return best, arg


def solve_values(
    st: Structure, pieces: Pieces, s_dec: np.ndarray, discount: float, tolerance: float = 1e-6,
    switch_extra: np.ndarray | None = None, cont_extra: np.ndarray | None = None,
    fixed: np.ndarray | None = None, method: str = "mpi", max_iterations: int = 100_000,
    u0: np.ndarray | None = None, chunk: int | None = None,
) -> ValueSolution:
    """Solve ``U = B U`` by value iteration (``method="vi"``) or modified policy iteration ("mpi").

    Bellman operator, per decision point (a, k) and hidden state i:
    ``U(a,k,i) = min( cont(a,k,i) + cont_extra[a]                        (k < K),
                      min_{a'} s_dec[a,k,a'] + switch_extra[a'] + W(a',i),
                      fixed[a,k,i] )``
    with ``W = c_entry + D[τ_entry] U[:, 0]`` and ``cont(a,k) = c_cont + D[τ_cont] U[:, k+1]``.

    Args:
        st: decision structure; pieces: fit costs and propagators (one tone).
        s_dec: (n, K+1, n) weighted switch costs (+inf where not allowed).
        discount: λ per frame (for the stopping rule).
        tolerance: stop when λ/(1−λ) ‖BU − U‖∞ <= tolerance.
        switch_extra: (n,) extra cost of switching into each segment (e.g. C_sem), +inf = never.
        cont_extra: (n,) extra cost of continuing each segment, +inf = never.
        fixed: (n, K+1, S) value of extra options with known values (e.g. semantic entries).
        method: "mpi" (default) or "vi" (plain value iteration).
        u0: optional starting U.
        chunk: rows per block of the min-plus product (default: ~8 MB blocks).

    Returns:
        the :class:`ValueSolution`.
    """
    t0 = time.perf_counter()
    n, kp1 = st.frames.shape
    s = pieces.c_entry.shape[1]
    k_int = kp1 - 1
    sw_extra = np.zeros(n) if switch_extra is None else np.asarray(switch_extra, float)
    c_extra = np.zeros(n) if cont_extra is None else np.asarray(cont_extra, float)
    chunk = chunk or max(1, int(1_000_000 // max(1, n * s)))
    zero_tau = st.tau_cont == 0
    u = np.zeros((n, kp1, s)) if u0 is None else np.array(u0, dtype=float)
    factor = discount / (1.0 - discount)

    def bellman(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        w = pieces.entry_values(u)
        wt = (w + sw_extra[:, None]).T.copy()                       # (S, n)
        new = np.empty_like(u)
        pol = np.empty(u.shape, dtype=np.int64)
        cont = np.empty((n, k_int, s))
        for k in range(k_int, -1, -1):
            best, arg = _best_switch(s_dec[:, k, :], wt, chunk)
            val, p = best, arg
            if fixed is not None:
                fx = fixed[:, k]
                take = fx < val
                val, p = np.where(take, fx, val), np.where(take, FIXED, p)
            if k < k_int:
                nxt = np.where(zero_tau[:, k, None], new[:, k + 1], u[:, k + 1])
                cv = pieces.continue_values(nxt, k)
                cont[:, k] = cv
                cv = cv + c_extra[:, None]
                take = cv <= val
                val, p = np.where(take, cv, val), np.where(take, CONTINUE, p)
            new[:, k], pol[:, k] = val, p
        return new, pol, w, cont

    def evaluate(u: np.ndarray, pol: np.ndarray) -> np.ndarray:
        w = pieces.entry_values(u)
        new = np.empty_like(u)
        rows = np.arange(n)[:, None]
        cols = np.arange(s)[None, :]
        for k in range(k_int, -1, -1):
            p = pol[:, k]
            tgt = np.maximum(p, 0)
            val = s_dec[rows, k, tgt] + sw_extra[tgt] + w[tgt, cols]
            if fixed is not None:
                val = np.where(p == FIXED, fixed[:, k], val)
            if k < k_int:
                nxt = np.where(zero_tau[:, k, None], new[:, k + 1], u[:, k + 1])
                cv = pieces.continue_values(nxt, k) + c_extra[:, None]
                val = np.where(p == CONTINUE, cv, val)
            new[:, k] = val
        return new

    iterations = 0
    sweeps = 0
    residual = np.inf
    pol = np.zeros(u.shape, dtype=np.int64)
    w = cont = None
    while iterations < max_iterations:
        new, pol, w, cont = bellman(u)
        iterations += 1
        residual = float(np.max(np.abs(new - u)))
        u = new
        if not np.isfinite(residual):
            if np.any(~np.isfinite(u)) and iterations > 1:
                raise GestureSimError(
                    "value iteration diverged: some decision point has no finite option")
            continue
        if factor * residual <= tolerance:
            break
        if method == "mpi":
            for _ in range(200):
                nu = evaluate(u, pol)
                sweeps += 1
                d = float(np.max(np.abs(nu - u)))
                u = nu
                if factor * d <= 0.1 * tolerance:
                    break
    else:
        raise GestureSimError(f"value iteration did not converge in {max_iterations} sweeps")
    # W and cont consistent with the returned U (one more propagation, no min)
    w = pieces.entry_values(u)
    cont = (np.stack([pieces.continue_values(u[:, k + 1], k) for k in range(k_int)], axis=1)
            if k_int else np.zeros((n, 0, s)))
    return ValueSolution(u=u, w=w, cont=cont, policy=pol, iterations=iterations,
                         eval_sweeps=sweeps, residual=residual,
                         error_bound=factor * residual, seconds=time.perf_counter() - t0)


@dataclass
class SemanticEntries:
    """Mid-clip entries into the segments matching one semantic label (§8.1, Appendix A iii).

    The value of an entry decomposes into its jump cost ``smooth[a, k, j]`` and a value that
    depends only on the target and the entry frame: the *rows*, one per distinct
    (target, entry frame) pair used anywhere (``row[a, k, j]`` indexes them).

    Attributes:
        targets: (M,) indices of the matching segments.
        frame: (n, K+1, M) entry frame f_sem(a, k) into each target (offset from its start).
        smooth: (n, K+1, M) weighted cost of the jump (+inf into the current segment itself).
        next_point: (n, K+1, M) decision point k̂ of the target reached after the entry.
        tau: (n, K+1, M) frames played from the entry to k̂ (inclusive).
        row: (n, K+1, M) index of the (target, entry frame) row of each entry.
        row_target: (R,) position in ``targets`` of each row; row_frame: (R,) its entry frame;
        row_tau: (R,) frames played to its next decision point; row_next: (R,) that point k̂.
    """

    targets: np.ndarray
    frame: np.ndarray
    smooth: np.ndarray
    next_point: np.ndarray
    tau: np.ndarray
    row: np.ndarray
    row_target: np.ndarray
    row_frame: np.ndarray
    row_tau: np.ndarray
    row_next: np.ndarray

    @classmethod
    def build(cls, lib: ControlLibrary, st: Structure, targets: np.ndarray, fraction: float,
              smooth_weight: float) -> SemanticEntries:
        """f_sem(a, k) = argmin over f < fraction·L of the pose cost from frame F[a,k] of a."""
        n, kp1 = st.frames.shape
        m = len(targets)
        src = np.stack([lib.features(a)[st.frames[a]] for a in range(n)])      # (n, K+1, d)
        flat = src.reshape(n * kp1, -1)
        frame = np.zeros((n, kp1, m), dtype=np.int64)
        smooth = np.zeros((n, kp1, m))
        nxt = np.zeros((n, kp1, m), dtype=np.int64)
        tau = np.zeros((n, kp1, m), dtype=np.int64)
        for j, b in enumerate(targets):
            length = int(lib.lengths[b])
            max_f = max(1, min(length, int(np.ceil(fraction * length))))
            dist = frame_distances(lib, flat, int(b), max_f).reshape(n, kp1, max_f)
            f = np.argmin(dist, axis=2)
            frame[:, :, j] = f
            smooth[:, :, j] = smooth_weight * np.take_along_axis(dist, f[..., None], 2)[..., 0]
            smooth[b, :, j] = np.inf
            fb = st.frames[b]
            # first decision point at or after the entry frame (valid points only)
            cand = np.where(st.valid[b][None, None, :] & (fb[None, None, :] >= f[..., None]),
                            np.arange(kp1)[None, None, :], kp1)
            kh = cand.min(axis=2)
            nxt[:, :, j] = kh
            tau[:, :, j] = fb[kh] - f + 1
        # distinct (target, entry frame) pairs; tau and k̂ depend only on the pair
        width = int(frame.max(initial=0)) + 1
        key = (np.arange(m)[None, None, :] * width + frame).ravel()
        uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
        return cls(targets=np.asarray(targets, np.int64), frame=frame, smooth=smooth,
                   next_point=nxt, tau=tau, row=inv.reshape(frame.shape).astype(np.int64),
                   row_target=uniq // width, row_frame=uniq % width,
                   row_tau=tau.ravel()[first], row_next=nxt.ravel()[first])

    @property
    def n_rows(self) -> int:
        return int(len(self.row_target))

    def row_values(self, pieces: Pieces, eta: np.ndarray, u_after: np.ndarray) -> np.ndarray:
        """(R, S): value of each (target, entry frame) row, without the jump cost.

        ``G[τ̂] η_target + D[τ̂] U_after[target, k̂]`` (fit of the frames played to the next
        decision point k̂, then the label-free value there).
        """
        b = self.targets[self.row_target]
        fit = np.einsum("rij,rj->ri", pieces.g[self.row_tau], eta[b])
        fut = np.einsum("rij,rj->ri", pieces.d[self.row_tau], u_after[b, self.row_next])
        return fit + fut

    def values(self, pieces: Pieces, eta: np.ndarray, u_after: np.ndarray) -> np.ndarray:
        """(n, K+1, M, S): cost of each semantic entry, then ``U`` of the label-free problem.

        ``smooth + G[τ̂] η_target + D[τ̂] U_after[target, k̂]``.
        """
        return self.smooth[..., None] + self.row_values(pieces, eta, u_after)[self.row]
