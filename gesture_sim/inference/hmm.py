"""The kinematic HMM ν (Gesture Controllers §6.1 stage 1, digest §5.3).

Gaussian emissions with full covariance over the six normalised kinematic parameters
y = (T, D, V, A, C, H) per step, fitted by EM (hmmlearn's Baum-Welch) on Y alone, with several
random restarts (best training likelihood kept). The number of states is chosen by held-out
log-likelihood per step over a range. Its posterior — marginals γ (n, S) and summed pairwise
marginals ξ (S, S) — is then fixed as the CRF's training target.
"""

from __future__ import annotations

import contextlib
import logging
import re
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from gesture_sim.inference import fitlog
from gesture_sim.inference.chain import forward_backward

_LOG2PI = np.log(2.0 * np.pi)


@dataclass
class KinematicHMM:
    """A fitted Gaussian HMM over the kinematic parameters.

    Attributes:
        startprob: (S,) initial state distribution.
        transmat: (S, S) row-stochastic transitions, ``[i, j] = P(q_t=j | q_{t-1}=i)``.
        means: (S, 6) state means (normalised log parameters).
        covars: (S, 6, 6) full state covariances.
    """

    startprob: np.ndarray
    transmat: np.ndarray
    means: np.ndarray
    covars: np.ndarray

    @property
    def n_states(self) -> int:
        return int(self.means.shape[0])

    def emission_log_likelihood(self, y: np.ndarray) -> np.ndarray:
        """``log N(y_t; μ_i, Σ_i)`` (n, S) of rows y (n, 6)."""
        y = np.atleast_2d(np.asarray(y, dtype=float))
        out = np.empty((len(y), self.n_states))
        for i in range(self.n_states):
            chol = np.linalg.cholesky(self.covars[i])
            z = np.linalg.solve(chol, (y - self.means[i]).T)
            out[:, i] = -0.5 * (np.sum(z * z, axis=0) + y.shape[1] * _LOG2PI) - np.sum(
                np.log(np.diag(chol)))
        return out

    def _logs(self) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(divide="ignore"):
            return np.log(self.startprob), np.log(self.transmat)

    def posteriors(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """γ (n, S), ξ summed over steps (S, S) and log P(Y) of one sequence y (n, 6)."""
        li, lt = self._logs()
        post = forward_backward(li, lt, self.emission_log_likelihood(y))
        return post.gamma, post.xi_sum, post.log_z

    def log_likelihood(self, ys: Sequence[np.ndarray]) -> float:
        """Total log P(Y) over sequences."""
        li, lt = self._logs()
        return float(sum(forward_backward(li, lt, self.emission_log_likelihood(y)).log_z
                         for y in ys))

    def to_arrays(self, prefix: str = "hmm_") -> dict[str, np.ndarray]:
        return {f"{prefix}startprob": self.startprob, f"{prefix}transmat": self.transmat,
                f"{prefix}means": self.means, f"{prefix}covars": self.covars}

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str = "hmm_") -> KinematicHMM:
        return cls(*(np.asarray(arrays[f"{prefix}{n}"], dtype=float)
                     for n in ("startprob", "transmat", "means", "covars")))


def fit_hmm(
    ys: Sequence[np.ndarray], n_states: int, n_restarts: int = 4, seed: int = 0,
    n_iter: int = 100, prior_steps: float = 60.0, prior_var: float = 0.2,
) -> tuple[KinematicHMM, float]:
    """EM with restarts; returns the model with the best training log-likelihood and it.

    Each restart starts its means and covariances from k-means clusters (4 seeds; hmmlearn's
    own start, one broad covariance for all states, often ends in a poor optimum) and its
    start/transition probabilities from hmmlearn's defaults, with its own random seed.

    Args:
        ys: sequences (n_i, 6) of per-step kinematic parameters.
        n_states: S.
        n_restarts: number of EM runs from different random initialisations.
        prior_steps, prior_var: a conjugate (inverse-Wishart-like) prior on each covariance
            worth ``prior_steps`` steps of variance ``prior_var`` per dimension (normalised
            units). Y is stepwise constant per segment, so a state holding few segments would
            otherwise collapse onto them; the prior keeps every Σ_i well conditioned.

    Nothing is printed: hmmlearn's "Model is not converging" reports and scikit-learn's
    warnings are captured and each restart is reported to :mod:`gesture_sim.inference.fitlog`
    (converged or not, likelihood drops, warnings), whose collectors a command summarises.
    """
    from hmmlearn.hmm import GaussianHMM
    from sklearn.cluster import KMeans

    data = np.concatenate([np.asarray(y, dtype=float) for y in ys])
    lengths = [len(y) for y in ys]
    best: KinematicHMM | None = None
    best_ll = -np.inf
    caught: list[str] = []   # short texts of the warnings of the current restart
    for r in range(n_restarts):
        d = data.shape[1]
        model = GaussianHMM(n_components=n_states, covariance_type="full", n_iter=n_iter,
                            random_state=seed + r, tol=1e-3, init_params="st",
                            covars_prior=prior_steps * prior_var * np.eye(d),
                            covars_weight=d + prior_steps)
        model.monitor_ = _counting_monitor(model.monitor_)
        # Means from k-means with several seeds (hmmlearn's own start is often a poor optimum).
        with _captured(caught):
            km = KMeans(n_clusters=n_states, n_init=4, random_state=seed + r).fit(data)
        model.means_ = km.cluster_centers_
        covs = np.empty((n_states, d, d))
        for k in range(n_states):
            member = data[km.labels_ == k]
            scatter = (member - km.cluster_centers_[k]).T @ (member - km.cluster_centers_[k])
            covs[k] = (scatter + prior_steps * prior_var * np.eye(d)) / (len(member) + prior_steps)
        model.covars_ = covs
        failed = False
        with _captured(caught):
            try:
                model.fit(data, lengths)
                ll = float(model.score(data, lengths))
            except (ValueError, np.linalg.LinAlgError):
                failed = True
        monitor = model.monitor_
        stopped_early = monitor.iter < monitor.n_iter and monitor.converged
        fitlog.record_fit(stopped_early and monitor.drops == 0, monitor.drops, failed=failed,
                          warnings=caught)
        caught.clear()
        if failed or not np.isfinite(ll) or ll <= best_ll:
            continue
        start = np.maximum(model.startprob_, 1e-6)
        trans = np.maximum(model.transmat_, 1e-8)
        best = KinematicHMM(start / start.sum(), trans / trans.sum(axis=1, keepdims=True),
                            np.array(model.means_), np.array(model.covars_))
        best_ll = ll
    if best is None:
        raise ValueError(f"EM failed for {n_states} states on {len(data)} steps")
    return best, best_ll


def _counting_monitor(monitor):
    """A copy of hmmlearn's ``ConvergenceMonitor`` that counts likelihood drops, silently.

    hmmlearn documents replacing ``model.monitor_`` with a subclass. ``drops`` counts the
    iterations whose likelihood fell by more than the float precision, which hmmlearn would
    report as "Model is not converging" on its logger.
    """
    from hmmlearn.base import ConvergenceMonitor

    class CountingMonitor(ConvergenceMonitor):
        drops = 0

        def _reset(self) -> None:
            super()._reset()
            self.drops = 0

        def report(self, log_prob: float) -> None:
            precision = np.finfo(float).eps ** 0.5
            if self.history and log_prob - self.history[-1] < -precision:
                self.drops += 1
            self.history.append(log_prob)
            self.iter += 1

    return CountingMonitor(monitor.tol, monitor.n_iter, False)


class _LogCatcher(logging.Filter):
    """Drops the records of a logger, keeping their short text."""

    def __init__(self, sink: list[str]) -> None:
        super().__init__()
        self.sink = sink

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            self.sink.append(_short_text(record.getMessage()))
        return False


@contextlib.contextmanager
def _captured(sink: list[str]) -> Iterator[None]:
    """Catch warnings and hmmlearn's log records inside the block, appending short texts."""
    loggers = [logging.getLogger(n) for n in ("hmmlearn.base", "hmmlearn.hmm")]
    catcher = _LogCatcher(sink)
    for lg in loggers:
        lg.addFilter(catcher)
    try:
        with warnings.catch_warnings(record=True) as records:
            warnings.simplefilter("always")
            yield
    finally:
        for lg in loggers:
            lg.removeFilter(catcher)
    sink.extend(_short_text(str(w.message), w.category.__name__) for w in records)


def _short_text(message: str, kind: str = "") -> str:
    """First sentence of a library message, numbers replaced by N (so repeats group)."""
    if message.startswith("Number of distinct clusters"):
        return "k-means found fewer distinct points than clusters"
    first = re.sub(r"-?\d+(\.\d+)?(e[-+]?\d+)?", "N", message.split(". ")[0].strip())
    return (f"{kind}: " if kind else "") + first.rstrip(".")[:100]


def choose_n_states(
    train: Sequence[np.ndarray], held_out: Sequence[np.ndarray], candidates: Sequence[int],
    n_restarts: int = 3, seed: int = 0,
    on_progress: Callable[[int, float], None] | None = None,
) -> tuple[int, dict[int, float]]:
    """Held-out log-likelihood per step for each candidate S; returns (best S, curve).

    The curve maps S to the mean held-out log-likelihood per step (-inf where EM failed).
    """
    n_held = sum(len(y) for y in held_out)
    curve: dict[int, float] = {}
    for s in candidates:
        try:
            model, _ = fit_hmm(train, s, n_restarts=n_restarts, seed=seed)
            curve[s] = model.log_likelihood(held_out) / n_held
        except ValueError:
            curve[s] = float("-inf")
        if on_progress is not None:
            on_progress(s, curve[s])
    best = max(curve, key=lambda k: curve[k])
    return best, curve
