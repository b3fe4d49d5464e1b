"""Known answers of the GPDM (gesture_sim.motion.gpdm) on a circle embedded in 10-D."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import approx_fprime

from gesture_sim.motion import gpdm as G
from gesture_sim.motion.gpdm import GPDM

PERIOD = 30  # frames per turn
RADIUS = 1.0


def _basis() -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(10, 2)))
    return q  # (10, 2) orthonormal


def _circle(phase: np.ndarray) -> np.ndarray:
    return RADIUS * np.stack([np.cos(phase), np.sin(phase)], 1) @ _basis().T


def _distance_to_circle(Y: np.ndarray) -> np.ndarray:
    p = Y @ _basis()
    off = Y - p @ _basis().T
    return np.sqrt((off ** 2).sum(1) + (np.linalg.norm(p, axis=1) - RADIUS) ** 2)


@pytest.fixture(scope="module")
def circle_data() -> np.ndarray:
    t = np.arange(2 * PERIOD)
    noise = 0.01 * np.random.default_rng(0).normal(size=(len(t), 10))
    return _circle(2 * np.pi * t / PERIOD) + noise


def _fit(Y: np.ndarray, seed: int = 0) -> GPDM:
    return GPDM.fit([Y], d=2, n_components=4, n_runs=1, run_length=len(Y), seed=seed,
                    max_iter=80)


@pytest.fixture(scope="module")
def circle_model(circle_data) -> GPDM:
    return _fit(circle_data)


def test_gradients_match_finite_differences():
    rng = np.random.default_rng(0)
    N, d, q = 20, 2, 3
    X, Z = rng.normal(size=(N, d)), rng.normal(size=(N, q))
    th = G._THETA0 + 0.3 * rng.normal(size=7)
    idx = G._runs_index(np.array([[0, 10], [10, 20]]))

    def f(v):
        return G._neg_log_posterior(v[:N * d].reshape(N, d), v[N * d:], Z, idx, 1.5)

    v = np.concatenate([X.ravel(), th])
    _, gX, gth = f(v)
    num = approx_fprime(v, lambda u: f(u)[0], 1e-6)
    an = np.concatenate([gX.ravel(), gth])
    assert np.abs(num - an).max() < 1e-4 * np.abs(num).max()
    m = GPDM(mean=np.zeros(q), basis=np.eye(q), scale=1.0, Z=Z, X=X,
             runs=np.array([[0, 10], [10, 20]]), theta=th)
    inner = rng.normal(size=4 * d)
    for weights in ((1.0, 1.0, 0.0), (0.5, 1.0, 3.0)):  # (w, dynamics, spread)
        _, g = m._path_energy(inner, X[0], X[15], *weights)
        num = approx_fprime(inner, lambda u, w=weights: m._path_energy(u, X[0], X[15], *w)[0],
                            1e-7)
        assert np.abs(num - g).max() < 1e-3 * np.abs(num).max()


def test_dynamics_predict_next_pose_better_than_constant(circle_model):
    phase = 2 * np.pi * (np.arange(0, PERIOD, 3) + 0.5) / PERIOD  # unseen phases
    Y, Y_next = _circle(phase), _circle(phase + 2 * np.pi / PERIOD)
    X = np.array([circle_model.latent_of(y) for y in Y])
    pred = circle_model.pose(circle_model.dynamics(X)[0])
    err = np.linalg.norm(pred - Y_next, axis=1).mean()
    const = np.linalg.norm(Y - Y_next, axis=1).mean()
    assert err < 0.5 * const


def test_transition_follows_the_circle(circle_model):
    y_a, y_b = _circle(np.array([0.0]))[0], _circle(np.array([np.pi / 2]))[0]
    T = circle_model.transition(y_a, y_b, 6)
    assert T.shape == (6, 10)
    midpoint = _distance_to_circle(((y_a + y_b) / 2)[None])[0]  # R (1 − cos 45°) ≈ 0.29
    dist = _distance_to_circle(T)
    assert dist.max() < 0.25 * midpoint
    # It moves from A to B: the phase rises monotonically through the quarter turn.
    p = T @ _basis()
    ang = np.arctan2(p[:, 1], p[:, 0])
    assert np.all(np.diff(ang) > 0) and 0 < ang[0] < ang[-1] < np.pi / 2
    # Chiu's own energy (manifold variance + even spread) stays near the circle too, while
    # the straight latent line (no optimisation) cuts across it.
    chiu = circle_model.transition(y_a, y_b, 6, manifold_weight=100.0, dynamics_weight=0.0,
                                   spread_weight=0.1)
    assert _distance_to_circle(chiu).max() < 0.25 * midpoint
    line = circle_model.transition(y_a, y_b, 6, optimise=False)
    assert _distance_to_circle(line).max() > 0.5 * midpoint


def test_fit_is_deterministic(circle_data, circle_model):
    again = _fit(circle_data)
    np.testing.assert_array_equal(again.X, circle_model.X)
    np.testing.assert_array_equal(again.theta, circle_model.theta)


def test_save_load_round_trip(tmp_path, circle_model):
    path = tmp_path / "gpdm.npz"
    circle_model.save(path)
    back = GPDM.load(path)
    for k in ("mean", "basis", "Z", "X", "runs", "theta"):
        np.testing.assert_array_equal(getattr(back, k), getattr(circle_model, k))
    assert back.scale == circle_model.scale and back.info == circle_model.info
    y_a, y_b = circle_model.Z[0], circle_model.Z[9]
    y_a, y_b = circle_model.to_pose(y_a)[0], circle_model.to_pose(y_b)[0]
    np.testing.assert_allclose(back.transition(y_a, y_b, 4), circle_model.transition(y_a, y_b, 4))


def test_choose_runs_are_seeded_windows():
    runs = G.choose_runs([100, 50], n_runs=4, run_length=20, seed=3)
    assert runs == G.choose_runs([100, 50], n_runs=4, run_length=20, seed=3)
    assert all(b - a == 20 and b <= (100, 50)[s] for s, a, b in runs)
