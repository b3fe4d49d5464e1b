"""The paper's Figure 4: held-out likelihood per time step, CRF vs HMM, input windows 1–5.

Both models infer the kinematic HMM ν's hidden states from the same windowed prosody input:

* the **remapped CRF** (:mod:`gesture_sim.inference.crf`) trained on the training part;
* a **remapped generative HMM** (Brand 1999, as in the paper) over the same states: ν's start
  and transition probabilities, and for each lag w of the window an emission distribution over
  the K prosody clusters, ``B_w[i, k] = Σ_t γ_t(i) m_{t-w}(k) / Σ_t γ_t(i)`` (soft counts on the
  training part); the window's observations are treated as independent given the state,
  ``log b_i(t) = Σ_w log Σ_k B_w[i, k] m_{t-w}(k)`` — the unmodelled dependence the paper blames
  for the HMM's drop with larger windows.

The score of a model on test data is the expected conditional log-likelihood of ν's posterior
over state paths on the test motion, per step: ``E_{γ,ξ}[log P(Q | X)] / n`` (the CRF's own
training objective, and for the HMM ``log P(Q, X) - log P(X)``). "Likelihood per time step" is
its exponential (a geometric mean over steps); 1/S is the score of a uniform guess.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from gesture_sim.inference.chain import expected_log_likelihood, forward_backward
from gesture_sim.inference.clusters import ProsodyClusters
from gesture_sim.inference.crf import fit_crf, window_features
from gesture_sim.inference.hmm import KinematicHMM


@dataclass
class WindowHMM:
    """The remapped generative HMM over windowed cluster memberships."""

    log_init: np.ndarray          # (S,)
    log_trans: np.ndarray         # (S, S)
    emission: np.ndarray          # (W, S, K)

    def log_unary(self, phi: np.ndarray) -> np.ndarray:
        """Per-step log observation likelihood (n, S) of window features phi (n, W, K)."""
        mix = np.einsum("nwk,wsk->nws", phi, self.emission)
        return np.sum(np.log(np.maximum(mix, 1e-300)), axis=1)

    def score(self, phi: np.ndarray, gamma: np.ndarray, xi_sum: np.ndarray) -> float:
        """``E_{γ,ξ}[log P(Q | X)]`` (a sum over steps)."""
        lu = self.log_unary(phi)
        log_z = forward_backward(self.log_init, self.log_trans, lu).log_z
        return expected_log_likelihood(self.log_init, self.log_trans, lu, gamma, xi_sum, log_z)


def fit_window_hmm(
    hmm: KinematicHMM, phis: Sequence[np.ndarray], gammas: Sequence[np.ndarray],
    pseudo: float = 1e-3,
) -> WindowHMM:
    """Remap ν onto windowed cluster observations by soft counting."""
    w, k = phis[0].shape[1:]
    s = hmm.n_states
    counts = np.full((w, s, k), pseudo)
    for phi, g in zip(phis, gammas, strict=True):
        counts += np.einsum("ns,nwk->wsk", g, phi)
    emission = counts / counts.sum(axis=2, keepdims=True)
    with np.errstate(divide="ignore"):
        return WindowHMM(np.log(hmm.startprob), np.log(hmm.transmat), emission)


@dataclass
class Fig4Row:
    """Scores for one window size (per step; log and likelihood)."""

    window: int
    crf_loglik: float
    hmm_loglik: float

    def to_dict(self) -> dict:
        return {"window": self.window, "crf_loglik_per_step": self.crf_loglik,
                "hmm_loglik_per_step": self.hmm_loglik,
                "crf_likelihood_per_step": float(np.exp(self.crf_loglik)),
                "hmm_likelihood_per_step": float(np.exp(self.hmm_loglik))}


def figure4(
    hmm: KinematicHMM, clusters: ProsodyClusters, pad: np.ndarray,
    train: Sequence[tuple[np.ndarray, np.ndarray]], test: Sequence[tuple[np.ndarray, np.ndarray]],
    windows: Sequence[int] = (1, 2, 3, 4, 5), l2: float = 1.0, max_iter: int = 300,
    on_window: Callable[[int], None] | None = None,
) -> list[Fig4Row]:
    """Train CRF and window-HMM on ``train`` and score both on ``test`` for each window.

    Args:
        hmm: the kinematic HMM ν (fitted on the training motion).
        clusters: the prosody mixture; ``pad`` (K,) the membership before a stream starts.
        train, test: sequences of (X (n, 3), Y (n, 6)) per take or part of a take.
    """
    def targets(parts):
        out = []
        for x, y in parts:
            g, xi, _ = hmm.posteriors(y)
            out.append((clusters.memberships(x), g, xi))
        return out

    tr, te = targets(train), targets(test)
    n_test = sum(len(g) for _, g, _ in te)
    rows = []
    for w in windows:
        if on_window is not None:
            on_window(w)
        phis = [window_features(m, w, pad) for m, _, _ in tr]
        crf, _ = fit_crf(phis, [g for _, g, _ in tr], [xi for _, _, xi in tr], l2=l2,
                         max_iter=max_iter)
        whmm = fit_window_hmm(hmm, phis, [g for _, g, _ in tr])
        crf_sum = hmm_sum = 0.0
        for m, g, xi in te:
            phi = window_features(m, w, pad)
            crf_sum += crf.expected_log_likelihood(phi, g, xi)
            hmm_sum += whmm.score(phi, g, xi)
        rows.append(Fig4Row(w, crf_sum / n_test, hmm_sum / n_test))
    return rows
