"""The kinematic HMM: EM recovers a known model; state-count selection prefers the truth."""

from __future__ import annotations

import numpy as np

from gesture_sim.inference.hmm import choose_n_states, fit_hmm

from .synthetic import sample_chain

TRANS = np.array([[0.95, 0.05, 0.0], [0.0, 0.95, 0.05], [0.05, 0.0, 0.95]])
MEANS = np.array([[2.0, 0, 0, 0, 0, 0], [0, 2.0, 0, 0, 0, 0], [0, 0, 2.0, 0, 0, 0]])


def _sample(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = sample_chain(TRANS, n, rng)
    return MEANS[q] + rng.normal(0, 0.3, (n, 6))


def test_em_recovers_means_and_transitions() -> None:
    hmm, _ = fit_hmm([_sample(1500, 0)], 3, n_restarts=2, prior_steps=5.0, prior_var=0.05)
    order = [int(np.argmin(np.linalg.norm(hmm.means - m, axis=1))) for m in MEANS]
    assert sorted(order) == [0, 1, 2]
    np.testing.assert_allclose(hmm.means[order], MEANS, atol=0.1)
    np.testing.assert_allclose(hmm.transmat[np.ix_(order, order)], TRANS, atol=0.04)
    gamma, xi, _ = hmm.posteriors(_sample(200, 1))
    np.testing.assert_allclose(gamma.sum(axis=1), 1.0)
    assert xi.sum() == np.float64(xi.sum()) and abs(xi.sum() - 199) < 1e-8


def test_held_out_likelihood_prefers_enough_states() -> None:
    best, curve = choose_n_states([_sample(900, 2)], [_sample(400, 3)], (1, 3), n_restarts=1)
    assert best == 3 and curve[3] > curve[1]
