"""The remapped CRF's maths: forward-backward, online filter, gradient, training recovery."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gesture_sim.inference.chain import forward_backward, forward_backward_log
from gesture_sim.inference.crf import (
    RemappedCRF,
    fit_crf,
    objective_and_gradient,
    window_features,
)

from .synthetic import sample_chain


def _enumerate(log_init, log_trans, log_unary):
    """All paths' scores of a small chain: dict path -> score."""
    n, s = log_unary.shape
    out = {}
    for q in itertools.product(range(s), repeat=n):
        sc = log_init[q[0]] + sum(log_trans[q[t - 1], q[t]] for t in range(1, n))
        out[q] = sc + sum(log_unary[t, q[t]] for t in range(n))
    return out


@pytest.mark.parametrize("routine", [forward_backward, forward_backward_log])
def test_forward_backward_equals_enumeration(routine) -> None:
    rng = np.random.default_rng(1)
    li, lt, lu = rng.normal(size=3), rng.normal(size=(3, 3)) * 2, rng.normal(size=(4, 3)) * 2
    scores = _enumerate(li, lt, lu)
    log_z = np.log(sum(np.exp(v) for v in scores.values()))
    gamma = np.zeros((4, 3))
    xi = np.zeros((3, 3))
    for q, v in scores.items():
        p = np.exp(v - log_z)
        for t in range(4):
            gamma[t, q[t]] += p
        for t in range(1, 4):
            xi[q[t - 1], q[t]] += p
    post = routine(li, lt, lu)
    assert post.log_z == pytest.approx(log_z, abs=1e-10)
    np.testing.assert_allclose(post.gamma, gamma, atol=1e-10)
    np.testing.assert_allclose(post.xi_sum, xi, atol=1e-10)


def test_online_filter_equals_enumeration_of_prefixes() -> None:
    """α_t from the one-step filter = P(q_t | x_0..t) by summing over all prefix paths."""
    rng = np.random.default_rng(2)
    s, w, k, n = 3, 2, 4, 4
    crf = RemappedCRF(rng.normal(size=(s, s)) * 1.5, rng.normal(size=(s, w, k)) * 1.5)
    memberships = rng.dirichlet(np.ones(k), size=n)
    pad = rng.dirichlet(np.ones(k))
    phi = window_features(memberships, w, pad)
    unary = crf.unary(phi)
    filt = crf.new_filter(pad)
    for t in range(n):
        belief = filt.step_membership(memberships[t])
        scores = _enumerate(np.zeros(s), crf.trans, unary[: t + 1])
        expect = np.zeros(s)
        for q, v in scores.items():
            expect[q[-1]] += np.exp(v)
        np.testing.assert_allclose(belief, expect / expect.sum(), atol=1e-12)
        assert belief.sum() == pytest.approx(1.0, abs=1e-12)


def test_filter_window_argument_matches_internal_window() -> None:
    rng = np.random.default_rng(3)
    crf = RemappedCRF(rng.normal(size=(3, 3)), rng.normal(size=(3, 4, 5)))
    m = rng.dirichlet(np.ones(5), size=10)
    pad = np.full(5, 0.2)
    phi = window_features(m, 4, pad)
    a, b = crf.new_filter(pad), crf.new_filter(pad)
    for t in range(10):
        np.testing.assert_allclose(a.step(phi[t]), b.step_membership(m[t]), atol=1e-12)


def test_gradient_matches_finite_differences() -> None:
    rng = np.random.default_rng(4)
    s, w, k = 3, 2, 3
    phis = [rng.dirichlet(np.ones(k), size=(12, w)), rng.dirichlet(np.ones(k), size=(7, w))]
    gammas = [rng.dirichlet(np.ones(s), size=12), rng.dirichlet(np.ones(s), size=7)]
    xis = [rng.dirichlet(np.ones(s * s)).reshape(s, s) * 11,
           rng.dirichlet(np.ones(s * s)).reshape(s, s) * 6]
    theta = rng.normal(size=s * s + s * w * k)
    _, grad = objective_and_gradient(theta, phis, gammas, xis, s, 0.3)
    eps = 1e-6
    numeric = np.array([
        (objective_and_gradient(theta + e, phis, gammas, xis, s, 0.3)[0]
         - objective_and_gradient(theta - e, phis, gammas, xis, s, 0.3)[0]) / (2 * eps)
        for e in np.eye(len(theta)) * eps])
    np.testing.assert_allclose(grad, numeric, atol=1e-6)


def test_training_recovers_transition_structure_and_state() -> None:
    """Data from a known cyclic chain with noisy state-coded inputs: the CRF learns the cycle
    and its filter tracks the state on fresh data."""
    rng = np.random.default_rng(5)
    s = 3
    trans = np.array([[0.9, 0.1, 0.0], [0.0, 0.9, 0.1], [0.1, 0.0, 0.9]])

    def inputs(q):
        m = np.full((len(q), s), 0.15) + rng.uniform(0, 0.1, (len(q), s))
        m[np.arange(len(q)), q] += 0.45
        return m / m.sum(axis=1, keepdims=True)

    q = sample_chain(trans, 3000, rng)
    gamma = np.eye(s)[q]
    xi = np.zeros((s, s))
    np.add.at(xi, (q[:-1], q[1:]), 1.0)
    pad = np.full(s, 1.0 / s)
    crf, info = fit_crf([window_features(inputs(q), 2, pad)], [gamma], [xi], l2=0.1)
    assert info.converged
    t_mat = crf.transition_matrix()
    np.testing.assert_allclose(t_mat.sum(axis=1), 1.0)
    for i in range(s):
        assert np.argmax(t_mat[i]) == i                    # sticky
        off = t_mat[i].copy()
        off[i] = -1
        assert np.argmax(off) == (i + 1) % s               # the cycle's successor
    q2 = sample_chain(trans, 600, rng)
    m2 = inputs(q2)
    filt = crf.new_filter(pad)
    beliefs = np.array([filt.step_membership(m) for m in m2])
    np.testing.assert_allclose(beliefs.sum(axis=1), 1.0, atol=1e-12)
    assert np.mean(beliefs.argmax(axis=1) == q2) > 0.9
