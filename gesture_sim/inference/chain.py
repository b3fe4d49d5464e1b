"""Log-space inference on a linear chain of discrete hidden states.

One routine serves the CRF (unnormalised potentials), the generative HMM baselines and the
kinematic HMM's pairwise posteriors: a chain is given by

* ``log_init`` (S,): potential of the first state (zeros for a CRF),
* ``log_trans`` (S, S): ``log_trans[i, j]`` is the potential of the step ``q_{t-1}=i -> q_t=j``,
* ``log_unary`` (n, S): per-step potential of each state,

and the score of a path Q is ``log_init[q_0] + sum_t log_trans[q_{t-1}, q_t] + log_unary[t, q_t]``.
All recursions are in log space: each ``logsumexp`` over the previous state is computed as a
matrix product of max-shifted exponentials (stable, and vectorised over the S x S block).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ChainPosteriors:
    """Result of forward-backward on one chain.

    Attributes:
        log_z: log partition function (log of the sum of exp(score) over all paths).
        gamma: (n, S) marginals P(q_t = i).
        xi_sum: (S, S) sum over t >= 1 of the pairwise marginals P(q_{t-1} = i, q_t = j).
    """

    log_z: float
    gamma: np.ndarray
    xi_sum: np.ndarray


def _shifted_exp(log_trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``exp(log_trans - colmax)`` and ``colmax`` (S,), so no column underflows entirely."""
    col_max = np.max(log_trans, axis=0)
    col_max = np.where(np.isfinite(col_max), col_max, 0.0)
    return np.exp(log_trans - col_max), col_max


def log_forward_step(
    log_alpha_prev: np.ndarray, exp_trans: np.ndarray, col_max: np.ndarray,
) -> np.ndarray:
    """One log-space forward step without the unary term.

    Returns ``log sum_i exp(log_alpha_prev[i] + log_trans[i, j])`` (S,), where
    ``exp_trans, col_max = _shifted_exp(log_trans)``.
    """
    m = np.max(log_alpha_prev)
    with np.errstate(divide="ignore"):
        return np.log(np.exp(log_alpha_prev - m) @ exp_trans) + m + col_max


def forward_backward(
    log_init: np.ndarray, log_trans: np.ndarray, log_unary: np.ndarray,
) -> ChainPosteriors:
    """Forward-backward; the fast scaled form, or pure log space if that under-flows.

    Arguments and result as :func:`forward_backward_log`. The scaled form works on
    ``exp(log_unary - rowmax)`` and ``exp(log_trans - max)`` and normalises the forward message
    at every step, keeping ``log Z`` as a sum of log scale factors (Rabiner's scaling): exact,
    and stable unless a whole step's mass under-flows (weights beyond ~700 nats), in which
    case the log-space routine is used.
    """
    log_init = np.asarray(log_init, dtype=float)
    log_trans = np.asarray(log_trans, dtype=float)
    log_unary = np.asarray(log_unary, dtype=float)
    n, s = log_unary.shape
    i_max, t_max = float(np.max(log_init)), float(np.max(log_trans))
    if not (np.isfinite(i_max) and np.isfinite(t_max) and np.all(np.isfinite(log_unary))):
        return forward_backward_log(log_init, log_trans, log_unary)
    e = np.exp(log_trans - t_max)
    u_max = np.max(log_unary, axis=1)
    u = np.exp(log_unary - u_max[:, None])
    a = np.empty((n, s))
    c = np.empty(n)
    x = np.exp(log_init - i_max) * u[0]
    c[0] = x.sum()
    a[0] = x / c[0]
    for t in range(1, n):
        x = (a[t - 1] @ e) * u[t]
        c[t] = x.sum()
        a[t] = x / c[t]
    if not (np.all(c > 0) and np.all(np.isfinite(c))):
        return forward_backward_log(log_init, log_trans, log_unary)
    b = np.empty((n, s))
    b[-1] = 1.0
    ub = u[1:] / c[1:, None]
    for t in range(n - 1, 0, -1):
        b[t - 1] = e @ (ub[t - 1] * b[t])
    log_z = float(np.sum(np.log(c)) + np.sum(u_max) + i_max + (n - 1) * t_max)
    gamma = a * b
    gamma /= gamma.sum(axis=1, keepdims=True)
    xi_sum = (a[:-1].T @ (ub * b[1:])) * e if n > 1 else np.zeros((s, s))
    return ChainPosteriors(log_z=log_z, gamma=gamma, xi_sum=xi_sum)


def forward_backward_log(
    log_init: np.ndarray, log_trans: np.ndarray, log_unary: np.ndarray,
) -> ChainPosteriors:
    """Forward-backward in log space (the reference; slower than the scaled form).

    Args:
        log_init: (S,) first-state potential.
        log_trans: (S, S) transition potential, rows = previous state.
        log_unary: (n, S) per-step potentials, n >= 1.

    Returns:
        :class:`ChainPosteriors` (log Z, marginals, summed pairwise marginals).
    """
    log_unary = np.asarray(log_unary, dtype=float)
    n, s = log_unary.shape
    exp_trans, col_max = _shifted_exp(log_trans)
    log_alpha = np.empty((n, s))
    log_alpha[0] = log_init + log_unary[0]
    for t in range(1, n):
        log_alpha[t] = log_forward_step(log_alpha[t - 1], exp_trans, col_max) + log_unary[t]
    m = np.max(log_alpha[-1])
    log_z = float(m + np.log(np.sum(np.exp(log_alpha[-1] - m))))
    log_beta = np.zeros((n, s))
    # beta_{t-1}(i) = logsumexp_j(log_trans[i, j] + unary[t, j] + beta_t(j))
    for t in range(n - 1, 0, -1):
        v = log_unary[t] + log_beta[t] + col_max
        mv = np.max(v)
        with np.errstate(divide="ignore"):
            log_beta[t - 1] = np.log(exp_trans @ np.exp(v - mv)) + mv
    log_gamma = log_alpha + log_beta - log_z
    gamma = np.exp(log_gamma)
    gamma /= gamma.sum(axis=1, keepdims=True)
    if n > 1:
        # xi_t(i, j) = exp(alpha_{t-1}(i) + trans(i, j) + unary_t(j) + beta_t(j) - log Z),
        # summed over t as one matrix product of max-shifted exponentials.
        left = log_alpha[:-1]
        a_shift = np.max(left, axis=1)
        right = log_unary[1:] + log_beta[1:]
        b_shift = np.max(right, axis=1)
        t_max = float(np.max(log_trans))
        scale = np.exp(a_shift + b_shift + t_max - log_z)                  # (n-1,)
        a = np.exp(left - a_shift[:, None]) * scale[:, None]
        b = np.exp(right - b_shift[:, None])
        xi_sum = (a.T @ b) * np.exp(log_trans - t_max)
    else:
        xi_sum = np.zeros((s, s))
    return ChainPosteriors(log_z=log_z, gamma=gamma, xi_sum=xi_sum)


def expected_log_likelihood(
    log_init: np.ndarray, log_trans: np.ndarray, log_unary: np.ndarray,
    target_gamma: np.ndarray, target_xi_sum: np.ndarray, log_z: float,
) -> float:
    """``E_target[log P(Q)]`` of a chain whose normaliser is ``log_z``.

    The expectation is under a fixed distribution over paths given by its marginals
    ``target_gamma`` (n, S) and summed pairwise marginals ``target_xi_sum`` (S, S); it is exact
    for any Markov-chain target because the score is a sum of unary and pairwise terms.
    """
    return float(
        target_gamma[0] @ log_init + np.sum(target_xi_sum * _finite(log_trans))
        + np.sum(target_gamma * _finite(log_unary)) - log_z
    )


def _finite(x: np.ndarray, floor: float = -1e4) -> np.ndarray:
    """Replace -inf by a large negative number so 0 * -inf counts as 0."""
    return np.maximum(x, floor)
