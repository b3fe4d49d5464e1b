"""The remapped conditional random field (Gesture Controllers §6.1, digest §5).

A linear-chain CRF over the kinematic HMM's S hidden states with

* transition features ``1{q_{t-1}=i} 1{q_t=j}`` (weights ``trans`` (S, S)),
* observation features ``1{q_t=i} P(x_{t-w} in C_k)`` for the causal lags ``w = 0..W-1``
  (weights ``obs`` (S, W, K)); the paper's window of size W = 4 is δ ∈ {-3..0}.

Training is "remapped": the HMM's posterior over state paths (marginals γ (n, S) and summed
pairwise marginals ξ (S, S)) is held fixed and the CRF maximises the expected conditional
log-likelihood ``E_{γ,ξ}[log P(Q | X)]`` minus an L2 penalty, by L-BFGS with the analytic
gradient ``E_HMM[F] - E_CRF[F] - l2 θ``. At run time :class:`CRFFilter` runs the forward
recursion one step at a time in log space and returns the normalised belief.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from gesture_sim.inference.chain import _shifted_exp, forward_backward, log_forward_step


def window_features(memberships: np.ndarray, window: int, pad: np.ndarray) -> np.ndarray:
    """Stack the causal window of cluster memberships.

    Args:
        memberships: (n, K) per-step memberships P(x_t in C_k).
        window: W >= 0, number of steps (the current one and W-1 before it); W = 0 gives no
            observation features (a transitions-only chain, the evaluation's floor).
        pad: (K,) membership used for steps before the start of the stream (the silence input's).

    Returns:
        (n, W, K): entry ``[t, w]`` is the membership at step ``t - w`` (``pad`` if negative).
    """
    m = np.asarray(memberships, dtype=float)
    n, k = m.shape
    if window == 0:
        return np.zeros((n, 0, k))
    padded = np.vstack([np.broadcast_to(pad, (window - 1, k)), m])
    out = np.empty((n, window, k))
    for w in range(window):
        out[:, w] = padded[window - 1 - w: window - 1 - w + n]
    return out


@dataclass
class RemappedCRF:
    """Weights of the remapped CRF.

    Attributes:
        trans: (S, S) transition weights λ, rows = previous state.
        obs: (S, W, K) observation weights μ, lag w = 0 is the current step.
    """

    trans: np.ndarray
    obs: np.ndarray

    @property
    def n_states(self) -> int:
        return int(self.trans.shape[0])

    @property
    def window(self) -> int:
        return int(self.obs.shape[1])

    @property
    def n_clusters(self) -> int:
        return int(self.obs.shape[2])

    def unary(self, phi: np.ndarray) -> np.ndarray:
        """Observation potentials (n, S) of window features ``phi`` (n, W, K)."""
        return phi.reshape(len(phi), -1) @ self.obs.reshape(self.n_states, -1).T

    def posteriors(self, phi: np.ndarray) -> np.ndarray:
        """Offline smoothed marginals γ (n, S) by forward-backward (for the offline DP)."""
        zeros = np.zeros(self.n_states)
        return forward_backward(zeros, self.trans, self.unary(phi)).gamma

    def expected_log_likelihood(
        self, phi: np.ndarray, gamma: np.ndarray, xi_sum: np.ndarray,
    ) -> float:
        """``E_{γ,ξ}[log P(Q | X)]`` (a sum over steps) of a target path distribution."""
        unary = self.unary(phi)
        post = forward_backward(np.zeros(self.n_states), self.trans, unary)
        return float(np.sum(xi_sum * self.trans) + np.sum(gamma * unary) - post.log_z)

    def transition_matrix(self) -> np.ndarray:
        """Normalised transition matrix (S, S): ``[i, j] = P(q_{t+1}=j | q_t=i) ∝ exp(λ_ij)``.

        Rows sum to 1 (the digest's column-stochastic T is its transpose). Predict a belief b
        (S,) n steps ahead with ``b @ np.linalg.matrix_power(T, n)``.
        """
        z = self.trans - self.trans.max(axis=1, keepdims=True)
        p = np.exp(z)
        return p / p.sum(axis=1, keepdims=True)

    def new_filter(self, pad: np.ndarray) -> CRFFilter:
        """An online forward filter; ``pad`` (K,) is the membership before the stream starts."""
        return CRFFilter(self, pad)

    def to_arrays(self, prefix: str = "crf_") -> dict[str, np.ndarray]:
        return {f"{prefix}trans": self.trans, f"{prefix}obs": self.obs}

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str = "crf_") -> RemappedCRF:
        return cls(np.asarray(arrays[f"{prefix}trans"], dtype=float),
                   np.asarray(arrays[f"{prefix}obs"], dtype=float))


class CRFFilter:
    """Online forward filtering of a :class:`RemappedCRF`, one control step at a time.

    ``step(window)`` takes the memberships of the causal window (W, K) — row 0 the current
    step, row w the step w before — and returns the belief α_t (S,), summing to 1. The
    recursion is ``log α_t(j) = logsumexp_i(log α_{t-1}(i) + λ_ij) + Σ_{w,k} μ_jwk m_wk``,
    renormalised each step; the first step uses the observation potential alone.
    """

    def __init__(self, crf: RemappedCRF, pad: np.ndarray) -> None:
        self.crf = crf
        self.pad = np.asarray(pad, dtype=float)
        self._exp_trans, self._col_max = _shifted_exp(crf.trans)
        self._obs_flat = np.ascontiguousarray(crf.obs.reshape(crf.n_states, -1).T)  # (W*K, S)
        self._history = np.broadcast_to(self.pad, (crf.window, crf.n_clusters)).copy()
        self._log_alpha: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the past: the next step is the first of a stream."""
        self._log_alpha = None
        self._history[:] = self.pad

    @property
    def belief(self) -> np.ndarray:
        """The current belief (S,); uniform before the first step."""
        if self._log_alpha is None:
            return np.full(self.crf.n_states, 1.0 / self.crf.n_states)
        return np.exp(self._log_alpha)

    def step(self, memberships_window: np.ndarray) -> np.ndarray:
        """Advance one step with the window's memberships (W, K); returns the belief (S,)."""
        unary = np.asarray(memberships_window, dtype=float).reshape(-1) @ self._obs_flat
        if self._log_alpha is None:
            la = unary
        else:
            la = log_forward_step(self._log_alpha, self._exp_trans, self._col_max) + unary
        m = np.max(la)
        la = la - (m + np.log(np.sum(np.exp(la - m))))
        self._log_alpha = la
        return np.exp(la)

    def step_membership(self, membership: np.ndarray) -> np.ndarray:
        """Advance one step given only the current membership (K,); the filter keeps the window."""
        self._history[1:] = self._history[:-1]
        self._history[0] = membership
        return self.step(self._history)


@dataclass
class CRFTrainingInfo:
    """What the optimiser did."""

    n_steps: int
    iterations: int
    objective_per_step: float
    converged: bool
    message: str
    seconds: float
    history: list[float] = field(default_factory=list)


def _unpack(theta: np.ndarray, s: int, w: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    return theta[: s * s].reshape(s, s), theta[s * s:].reshape(s, w, k)


def objective_and_gradient(
    theta: np.ndarray, phis: Sequence[np.ndarray], gammas: Sequence[np.ndarray],
    xis: Sequence[np.ndarray], n_states: int, l2: float | np.ndarray,
) -> tuple[float, np.ndarray]:
    """Negative regularised expected conditional log-likelihood and its gradient.

    ``f(θ) = -Σ_seq E_{γ,ξ}[log P_θ(Q | X)] + ½ Σ l2_j θ_j²``, summed (not averaged) over
    steps; ``l2`` is a scalar or one weight per parameter.

    Args:
        theta: flat parameters, ``trans`` (S*S) then ``obs`` (S*W*K).
        phis: per sequence, window features (n, W, K).
        gammas: per sequence, target marginals (n, S).
        xis: per sequence, target summed pairwise marginals (S, S).
    """
    s = n_states
    _, w, k = phis[0].shape
    trans, obs = _unpack(theta, s, w, k)
    obs_flat = obs.reshape(s, -1)
    value = 0.0
    g_trans = np.zeros((s, s))
    g_obs = np.zeros((s, w * k))
    zeros = np.zeros(s)
    for phi, gamma, xi in zip(phis, gammas, xis, strict=True):
        flat = phi.reshape(len(phi), -1)
        unary = flat @ obs_flat.T
        post = forward_backward(zeros, trans, unary)
        value += float(np.sum(xi * trans) + np.sum(gamma * unary) - post.log_z)
        g_trans += xi - post.xi_sum
        g_obs += (gamma - post.gamma).T @ flat
    grad = np.concatenate([g_trans.ravel(), g_obs.ravel()])
    f = -value + 0.5 * float(np.sum(l2 * theta * theta))
    return f, -grad + l2 * theta


class BatchedChains:
    """All training sequences of the CRF laid out side by side, for a batched objective.

    The sequences are sorted by length (longest first) and padded to ``(T, B, ...)``, so one
    scaled forward-backward recursion runs over all of them at once: the Python loop has T
    (the longest sequence's) iterations instead of the sum of all lengths. It computes the same
    objective and gradient as :func:`objective_and_gradient`, up to floating-point rounding
    (the large-data path of training; the exact path keeps the per-sequence routine).
    """

    def __init__(self, phis: Sequence[np.ndarray], gammas: Sequence[np.ndarray],
                 xis: Sequence[np.ndarray]) -> None:
        lengths = np.array([len(p) for p in phis])
        order = np.argsort(-lengths, kind="stable")
        self.lengths = lengths[order]
        b = len(phis)
        t = int(self.lengths[0])
        s = gammas[0].shape[1]
        wk = int(np.prod(phis[0].shape[1:]))
        self.n_states = s
        self.flat = np.zeros((t, b, wk))
        self.gamma = np.zeros((t, b, s))
        self.mask = np.zeros((t, b), dtype=bool)
        for j, i in enumerate(order):
            n = int(lengths[i])
            self.flat[:n, j] = np.asarray(phis[i]).reshape(n, -1)
            self.gamma[:n, j] = gammas[i]
            self.mask[:n, j] = True
        self.xi = np.sum(np.asarray(xis), axis=0)
        self.active = self.mask.sum(axis=1)           # sequences still running at each step
        self.target_obs = self.gamma.reshape(-1, s).T @ self.flat.reshape(-1, wk)   # (S, WK)
        self._phis, self._gammas, self._xis = phis, gammas, xis

    def objective_and_gradient(self, theta: np.ndarray, l2: float | np.ndarray
                               ) -> tuple[float, np.ndarray]:
        """As :func:`objective_and_gradient` over the same sequences."""
        s = self.n_states
        t_len, b, wk = self.flat.shape
        trans = theta[: s * s].reshape(s, s)
        obs_flat = theta[s * s:].reshape(s, wk)
        unary = self.flat @ obs_flat.T                                   # (T, B, S)
        t_max = float(np.max(trans))
        if not (np.isfinite(t_max) and np.all(np.isfinite(unary))):
            return self._exact(theta, l2)
        e = np.exp(trans - t_max)
        u_max = np.max(unary, axis=2)
        u = np.exp(unary - u_max[..., None])
        a = np.zeros((t_len, b, s))
        c = np.ones((t_len, b))
        x = u[0]
        c[0] = x.sum(axis=1)
        a[0] = x / c[0][:, None]
        active = self.active
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for t in range(1, t_len):          # under-flow is caught below (the exact routine)
                k = active[t]
                x = (a[t - 1, :k] @ e) * u[t, :k]
                ck = x.sum(axis=1)
                c[t, :k] = ck
                a[t, :k] = x / ck[:, None]
        if not (np.all(c > 0) and np.all(np.isfinite(c))):
            return self._exact(theta, l2)
        beta = np.zeros((t_len, b, s))
        beta[t_len - 1, :active[t_len - 1]] = 1.0
        ub = u[1:] / c[1:, :, None]
        e_t = np.ascontiguousarray(e.T)
        for t in range(t_len - 1, 0, -1):
            k = active[t]
            beta[t - 1, :k] = (ub[t - 1, :k] * beta[t, :k]) @ e_t
            beta[t - 1, k:active[t - 1]] = 1.0                           # last step of those
        log_z = float(np.sum(np.log(c)) + np.sum(u_max[self.mask])
                      + np.sum(self.lengths - 1) * t_max)
        gamma = a * beta
        norm = gamma.sum(axis=2, keepdims=True)
        gamma /= np.where(norm > 0, norm, 1.0)
        xi_sum = (a[:-1].reshape(-1, s).T @ (ub * beta[1:]).reshape(-1, s)) * e
        value = float(np.sum(self.xi * trans) + np.sum(self.gamma * unary) - log_z)
        g_trans = self.xi - xi_sum
        g_obs = self.target_obs - gamma.reshape(-1, s).T @ self.flat.reshape(-1, wk)
        grad = np.concatenate([g_trans.ravel(), g_obs.ravel()])
        f = -value + 0.5 * float(np.sum(l2 * theta * theta))
        return f, -grad + l2 * theta

    def _exact(self, theta: np.ndarray, l2: float | np.ndarray) -> tuple[float, np.ndarray]:
        """The per-sequence routine (log space where the scaled form under-flows)."""
        return objective_and_gradient(theta, self._phis, self._gammas, self._xis,
                                      self.n_states, l2)


def _recorder(history: list[float]):
    """An L-BFGS callback that records the objective without re-evaluating it."""

    def callback(intermediate_result) -> None:
        history.append(float(intermediate_result.fun))

    return callback


def fit_crf(
    phis: Sequence[np.ndarray], gammas: Sequence[np.ndarray], xis: Sequence[np.ndarray],
    l2: float = 1.0, max_iter: int = 300, tol: float = 1e-7,
    init: RemappedCRF | None = None, l2_trans: float = 0.01, batched: bool = False,
) -> tuple[RemappedCRF, CRFTrainingInfo]:
    """Train the CRF by L-BFGS against fixed target posteriors (one entry per sequence).

    Args:
        phis: window features (n, W, K) per sequence.
        gammas: HMM marginals (n, S) per sequence.
        xis: HMM summed pairwise marginals (S, S) per sequence.
        l2: L2 penalty on the observation weights μ (the objective is a sum over steps, so
            its effect shrinks as data grows).
        l2_trans: L2 penalty on the transition weights λ (few, and they must grow large for
            the sticky chains of gesture phases, so they are barely penalised).
        max_iter: L-BFGS iterations at most.
        tol: relative tolerance on the objective (scipy's ``ftol``).
        init: starting weights (zeros when ``None``).
        batched: evaluate the objective over all sequences at once (:class:`BatchedChains`:
            the same objective up to rounding, much faster for many sequences); the default is
            the per-sequence :func:`objective_and_gradient`.
    """
    s = gammas[0].shape[1]
    _, w, k = phis[0].shape
    n_total = int(sum(len(p) for p in phis))
    theta0 = (np.zeros(s * s + s * w * k) if init is None else
              np.concatenate([init.trans.ravel(), init.obs.ravel()]))
    history: list[float] = []
    penalty = np.concatenate([np.full(s * s, l2_trans), np.full(s * w * k, l2)])

    chains = BatchedChains(phis, gammas, xis) if batched else None

    def fun(theta: np.ndarray) -> tuple[float, np.ndarray]:
        if chains is not None:
            f, g = chains.objective_and_gradient(theta, penalty)
        else:
            f, g = objective_and_gradient(theta, phis, gammas, xis, s, penalty)
        return f / n_total, g / n_total

    t0 = time.perf_counter()
    res = minimize(
        fun, theta0, jac=True, method="L-BFGS-B",
        options={"maxiter": max_iter, "ftol": tol, "gtol": 1e-6},
        callback=_recorder(history),
    )
    trans, obs = _unpack(res.x, s, w, k)
    info = CRFTrainingInfo(
        n_steps=n_total, iterations=int(res.nit), objective_per_step=float(res.fun),
        converged=bool(res.success), message=str(res.message),
        seconds=time.perf_counter() - t0, history=history,
    )
    return RemappedCRF(trans.copy(), obs.copy()), info
