"""Training's large-data path (above ``exact_steps``) and the exact path below it."""

from __future__ import annotations

import numpy as np
import pytest

import gesture_sim.inference.train as train
from gesture_sim.inference.chain import forward_backward
from gesture_sim.inference.crf import BatchedChains, fit_crf, objective_and_gradient
from gesture_sim.inference.train import TrainSettings, selection_subsample, train_model

from .synthetic import synthetic_take


@pytest.fixture(scope="module")
def takes() -> list:
    rng = np.random.default_rng(3)
    return [synthetic_take(rng, 25.0), synthetic_take(rng, 20.0), synthetic_take(rng, 15.0)]


def _settings(**kw) -> TrainSettings:
    return TrainSettings(state_candidates=(2, 3), n_clusters=4, window=3, hmm_restarts=3,
                         crf_max_iter=40, **kw)


class _Spy:
    """Records the calls of training's fitting functions (and still runs them)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls: dict[str, list] = {"clusters": [], "choose": [], "hmm": [], "crf": []}
        for name, key in (("fit_clusters", "clusters"), ("choose_n_states", "choose"),
                          ("fit_hmm", "hmm"), ("fit_crf", "crf")):
            monkeypatch.setattr(train, name, self._wrap(getattr(train, name), key))

    def _wrap(self, fn, key):
        def spy(*args, **kwargs):
            self.calls[key].append((args, kwargs))
            return fn(*args, **kwargs)

        return spy


def test_exact_path_at_and_below_the_threshold(takes, monkeypatch) -> None:
    n_steps = int(sum(np.floor(t.duration_s * 30.0) for t in takes))
    spy = _Spy(monkeypatch)
    model = train_model(takes, _settings())                     # default: far above 1800 steps
    at = train_model(takes, _settings(exact_steps=n_steps))     # at the threshold: still exact
    assert model.summary["steps"] == n_steps
    for m in (model, at):
        assert "large_data_path" not in m.summary
    for i in (0, 1):
        x = spy.calls["clusters"][i][0][0]
        assert len(x) == n_steps                                  # all rows
        (tr, held, cands), kw = spy.calls["choose"][i]
        assert sum(len(y) for y in tr) + sum(len(y) for y in held) == n_steps
        assert kw["n_restarts"] == 2
        assert spy.calls["hmm"][i][1]["n_restarts"] == 3
        assert spy.calls["crf"][i][1]["batched"] is False
    # the two exact runs are the same computation
    for a, b in ((model.hmm.means, at.hmm.means), (model.crf.obs, at.crf.obs),
                 (model.clusters.means, at.clusters.means)):
        np.testing.assert_array_equal(a, b)


def test_large_path_above_the_threshold(takes, monkeypatch) -> None:
    spy = _Spy(monkeypatch)
    model = train_model(takes, _settings(exact_steps=1000, sample_steps=1200,
                                         large_hmm_restarts=2))
    info = model.summary["large_data_path"]
    assert info["exact_steps"] == 1000 and info["crf_batched"] and info["hmm_restarts"] == 2
    x = spy.calls["clusters"][0][0][0]
    assert len(x) == info["cluster_fit_steps"] == 1200
    (tr, held, _), _ = spy.calls["choose"][0]
    assert sum(len(y) for y in tr) == info["selection_train_steps"] <= 1200
    assert spy.calls["hmm"][-1][1]["n_restarts"] == 2
    assert spy.calls["crf"][0][1]["batched"] is True
    default = train_model(takes, _settings(exact_steps=1000, sample_steps=1200))
    assert default.summary["large_data_path"]["hmm_restarts"] == 3
    assert spy.calls["hmm"][-1][1]["n_restarts"] == 3
    assert model.n_states in (2, 3) and np.isfinite(model.summary["crf_objective_per_step"])


def test_selection_subsample_draws_contiguous_blocks_across_takes() -> None:
    rng = np.random.default_rng(0)
    train_y = [rng.normal(size=(n, 6)) for n in (5000, 3000, 400, 4000, 6000)]
    held_y = [rng.normal(size=(n, 6)) for n in (50, 30, 4, 40, 60)]
    sub, held = selection_subsample(train_y, held_y, 2000, seed=1, min_block=900)
    assert len(sub) == 2 and [len(h) for h in held] == [50, 60]      # takes 0 and 4
    assert sum(len(y) for y in sub) <= 2000
    for y, full in zip(sub, (train_y[0], train_y[4]), strict=True):
        start = int(np.flatnonzero(np.all(full == y[0], axis=1))[0])
        np.testing.assert_array_equal(full[start:start + len(y)], y)   # one contiguous block
    again, _ = selection_subsample(train_y, held_y, 2000, seed=1, min_block=900)
    for a, b in zip(sub, again, strict=True):
        np.testing.assert_array_equal(a, b)
    every, held_all = selection_subsample(train_y, held_y, 10**6, seed=1)
    assert all(a is b for a, b in zip(every, train_y, strict=True)) and len(held_all) == 5


def test_batched_crf_objective_equals_the_per_sequence_one() -> None:
    rng = np.random.default_rng(1)
    s, w, k = 4, 3, 5
    lengths = (120, 1, 2, 80, 120, 7)
    phis = [rng.random((n, w, k)) for n in lengths]
    trans = rng.normal(size=(s, s)) + 2.0 * np.eye(s)
    posts = [forward_backward(np.zeros(s), trans, rng.normal(size=(n, s))) for n in lengths]
    gammas = [p.gamma for p in posts]
    xis = [p.xi_sum for p in posts]
    l2 = np.full(s * s + s * w * k, 0.3)
    for scale in (0.5, 3.0):
        theta = rng.normal(size=len(l2)) * scale
        f0, g0 = objective_and_gradient(theta, phis, gammas, xis, s, l2)
        f1, g1 = BatchedChains(phis, gammas, xis).objective_and_gradient(theta, l2)
        assert f1 == pytest.approx(f0, rel=1e-12)
        np.testing.assert_allclose(g1, g0, rtol=1e-9, atol=1e-9)
    a, info_a = fit_crf(phis, gammas, xis, max_iter=30)
    b, info_b = fit_crf(phis, gammas, xis, max_iter=30, batched=True)
    assert info_b.objective_per_step == pytest.approx(info_a.objective_per_step, rel=1e-6)
    np.testing.assert_allclose(b.obs, a.obs, atol=1e-4)
