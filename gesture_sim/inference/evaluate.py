"""The paper's Figure 4: held-out likelihood per time step, CRF vs HMM (and DCNF), windows 1–5.

The models infer the kinematic HMM ν's hidden states from the same windowed prosody input:

* the **remapped CRF** (:mod:`gesture_sim.inference.crf`) trained on the training part;
* a **remapped generative HMM** (Brand 1999, as in the paper) over the same states: ν's start
  and transition probabilities, and for each lag w of the window an emission distribution over
  the K prosody clusters, ``B_w[i, k] = Σ_t γ_t(i) m_{t-w}(k) / Σ_t γ_t(i)`` (soft counts on the
  training part); the window's observations are treated as independent given the state,
  ``log b_i(t) = Σ_w log Σ_k B_w[i, k] m_{t-w}(k)`` — the unmodelled dependence the paper blames
  for the HMM's drop with larger windows;
* optionally the **DCNF** of Chiu 2014 (:mod:`gesture_sim.inference.dcnf`) over the same window
  of per-step inputs (plus voicing, silence and F0/intensity slopes), its number of training
  steps chosen on the last 25 % of the training part, then refitted on all of it.

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
from gesture_sim.inference.dcnf import (
    DCNFSettings,
    dcnf_inputs,
    fit_dcnf_selected,
    hmm_targets,
    pad_input,
)
from gesture_sim.inference.features import StepSettings
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
    dcnf_loglik: float | None = None
    crf_seconds: float | None = None
    dcnf_seconds: float | None = None
    dcnf_iterations: int | None = None

    def to_dict(self) -> dict:
        out = {"window": self.window, "crf_loglik_per_step": self.crf_loglik,
               "hmm_loglik_per_step": self.hmm_loglik,
               "crf_likelihood_per_step": float(np.exp(self.crf_loglik)),
               "hmm_likelihood_per_step": float(np.exp(self.hmm_loglik))}
        if self.crf_seconds is not None:
            out["crf_training_seconds"] = self.crf_seconds
        if self.dcnf_loglik is not None:
            out |= {"dcnf_loglik_per_step": self.dcnf_loglik,
                    "dcnf_likelihood_per_step": float(np.exp(self.dcnf_loglik)),
                    "dcnf_training_seconds": self.dcnf_seconds,
                    "dcnf_iterations": self.dcnf_iterations}
        return out


def figure4(
    hmm: KinematicHMM, clusters: ProsodyClusters, pad: np.ndarray,
    train: Sequence[tuple[np.ndarray, np.ndarray]], test: Sequence[tuple[np.ndarray, np.ndarray]],
    windows: Sequence[int] = (1, 2, 3, 4, 5), l2: float = 1.0, max_iter: int = 300,
    on_window: Callable[[int], None] | None = None, dcnf: DCNFSettings | None = None,
    steps: StepSettings | None = None,
) -> list[Fig4Row]:
    """Train CRF and window-HMM (and DCNF) on ``train`` and score them on ``test`` per window.

    Args:
        hmm: the kinematic HMM ν (fitted on the training motion).
        clusters: the prosody mixture; ``pad`` (K,) the membership before a stream starts.
        train, test: sequences of (X (n, 3), Y (n, 6)) per take or part of a take.
        dcnf: DCNF hyperparameters (its ``window`` is replaced by each window); ``None``: no
            DCNF row.
        steps: the step settings whose silence vector the inputs use (defaults).
    """
    import time
    from dataclasses import replace

    def targets(parts):
        out = []
        for x, y in parts:
            g, xi, _ = hmm.posteriors(y)
            out.append((clusters.memberships(x), g, xi))
        return out

    tr, te = targets(train), targets(test)
    n_test = sum(len(g) for _, g, _ in te)
    silence = (steps or StepSettings()).silence()
    if dcnf is not None:
        d_pad = pad_input(silence, pad)
        d_train = [dcnf_inputs(x, m, silence) for (x, _), (m, _, _) in zip(train, tr,
                                                                         strict=True)]
        d_test = [(dcnf_inputs(x, m, silence), hmm_targets(hmm, y))
                  for (x, y), (m, _, _) in zip(test, te, strict=True)]
    rows = []
    for w in windows:
        if on_window is not None:
            on_window(w)
        phis = [window_features(m, w, pad) for m, _, _ in tr]
        crf, crf_info = fit_crf(phis, [g for _, g, _ in tr], [xi for _, _, xi in tr], l2=l2,
                                max_iter=max_iter)
        whmm = fit_window_hmm(hmm, phis, [g for _, g, _ in tr])
        crf_sum = hmm_sum = 0.0
        for m, g, xi in te:
            phi = window_features(m, w, pad)
            crf_sum += crf.expected_log_likelihood(phi, g, xi)
            hmm_sum += whmm.score(phi, g, xi)
        row = Fig4Row(w, crf_sum / n_test, hmm_sum / n_test, crf_seconds=crf_info.seconds)
        if dcnf is not None:
            t0 = time.perf_counter()
            model, info = fit_dcnf_selected(d_train, [y for _, y in train], hmm, d_pad,
                                            replace(dcnf, window=w))
            row.dcnf_seconds = time.perf_counter() - t0
            row.dcnf_iterations = info.iterations
            row.dcnf_loglik = sum(model.expected_log_likelihood(model.windows(x, d_pad), t)
                                  for x, t in d_test) / n_test
        rows.append(row)
    return rows
