"""The DCNF (Chiu 2014): exact second-order chain, joint gradient, filter, training, storage."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.inference.dcnf import (
    DCNF,
    ChainStats,
    DCNFInputs,
    DCNFSettings,
    chain_stats,
    dcnf_inputs,
    fit_dcnf,
    hmm_targets,
    init_dcnf,
    objective_and_gradient,
    pad_input,
    penalty_vector,
)
from gesture_sim.inference.hmm import KinematicHMM


def _brute(unary, trans, trans2):
    """log Z, marginals, pair and triple sums by enumerating every path."""
    n, s = unary.shape
    paths = list(itertools.product(range(s), repeat=n))
    scores = []
    for q in paths:
        v = sum(unary[t, q[t]] for t in range(n))
        v += sum(trans[q[t - 1], q[t]] for t in range(1, n))
        v += sum(trans2[q[t - 1], q[t], q[t + 1]] for t in range(1, n - 1))
        scores.append(v)
    scores = np.array(scores)
    log_z = np.log(np.sum(np.exp(scores - scores.max()))) + scores.max()
    p = np.exp(scores - log_z)
    gamma = np.zeros((n, s))
    xi = np.zeros((s, s))
    xi3 = np.zeros((s, s, s))
    for pq, q in zip(p, paths, strict=True):
        for t in range(n):
            gamma[t, q[t]] += pq
        for t in range(1, n):
            xi[q[t - 1], q[t]] += pq
        for t in range(1, n - 1):
            xi3[q[t - 1], q[t], q[t + 1]] += pq
    return log_z, gamma, xi, xi3


def _random_model(rng, s=3, d=4, window=2, hidden=(5, 4), order=2, dropout=0.0) -> DCNF:
    cfg = DCNFSettings(window=window, hidden=hidden, order=order, dropout=dropout, seed=3)
    m = init_dcnf(d, s, cfg, rng.normal(size=d), rng.uniform(0.5, 2.0, size=d))
    return m.with_flat(rng.normal(0.0, 0.7, size=m.flat().size))


def test_second_order_chain_matches_enumeration() -> None:
    rng = np.random.default_rng(0)
    s, n = 3, 5
    unary, trans, trans2 = rng.normal(size=(n, s)), rng.normal(size=(s, s)), rng.normal(
        size=(s, s, s))
    got = chain_stats(unary, trans, trans2)
    log_z, gamma, xi, xi3 = _brute(unary, trans, trans2)
    assert got.log_z == pytest.approx(log_z, abs=1e-10)
    np.testing.assert_allclose(got.gamma, gamma, atol=1e-10)
    np.testing.assert_allclose(got.xi, xi, atol=1e-10)
    np.testing.assert_allclose(got.xi3, xi3, atol=1e-10)


def test_hmm_targets_triples_are_consistent_with_pairs() -> None:
    rng = np.random.default_rng(1)
    s = 3
    trans = rng.dirichlet(np.ones(s) * 3, size=s)
    hmm = KinematicHMM(np.full(s, 1 / s), trans, rng.normal(size=(s, 6)),
                       np.repeat(np.eye(6)[None], s, axis=0))
    y = rng.normal(size=(40, 6))
    tgt = hmm_targets(hmm, y)
    g, xi, _ = hmm.posteriors(y)
    np.testing.assert_allclose(tgt.gamma, g, atol=1e-9)
    np.testing.assert_allclose(tgt.xi, xi, atol=1e-9)
    # Σ_k triple(i, j, k) = pair sums over t = 1..n-2, i.e. ξ minus the last pair
    assert tgt.xi3.sum() == pytest.approx(len(y) - 2)
    np.testing.assert_allclose(tgt.xi3.sum(axis=2) <= tgt.xi + 1e-12, True)


@pytest.mark.parametrize("order,dropout", [(2, 0.0), (1, 0.0), (2, 0.5)])
def test_joint_gradient_matches_finite_differences(order: int, dropout: float) -> None:
    rng = np.random.default_rng(2)
    s, d, n = 3, 4, 7
    model = _random_model(rng, s=s, d=d, order=order, dropout=dropout)
    a0s = [rng.normal(size=(n, model.window * d)), rng.normal(size=(4, model.window * d))]
    targets = []
    for a in a0s:   # soft targets: the posterior of some other chain
        other = chain_stats(rng.normal(size=(len(a), s)), rng.normal(size=(s, s)),
                            rng.normal(size=(s, s, s)))
        targets.append(ChainStats(0.0, other.gamma, other.xi, other.xi3))
    masks = None
    if dropout:
        masks = [[(rng.random((len(a), model.layers[0].shape[1])) > dropout) / (1 - dropout)]
                 for a in a0s]
    l2 = penalty_vector(model, 0.3, 0.05)
    vec = model.flat()
    f0, g = objective_and_gradient(model, vec, a0s, targets, l2, masks)
    h = 1e-6
    num = np.empty_like(vec)
    for j in range(len(vec)):
        e = np.zeros_like(vec)
        e[j] = h
        fp, _ = objective_and_gradient(model, vec + e, a0s, targets, l2, masks)
        fm, _ = objective_and_gradient(model, vec - e, a0s, targets, l2, masks)
        num[j] = (fp - fm) / (2 * h)
    assert np.isfinite(f0)
    np.testing.assert_allclose(g, num, rtol=1e-5, atol=1e-6)
    assert np.abs(g).max() > 1e-2      # the check is not vacuous


@pytest.mark.parametrize("order", [1, 2])
def test_filter_is_the_forward_marginal_of_every_prefix(order: int) -> None:
    rng = np.random.default_rng(4)
    s, d = 3, 4
    model = _random_model(rng, s=s, d=d, window=3, order=order)
    x = rng.normal(size=(9, d))
    pad = rng.normal(size=d)
    a0 = model.windows(x, pad)
    unary = model.unary(a0)
    filt = model.new_filter(pad)
    for t in range(len(x)):
        belief = filt.step(x[t])
        offline = chain_stats(unary[: t + 1], model.trans, model.trans2).gamma[-1]
        np.testing.assert_allclose(belief, offline, atol=1e-10)
    assert belief.sum() == pytest.approx(1.0)
    filt.reset()
    np.testing.assert_allclose(filt.step(x[0]), chain_stats(unary[:1], model.trans,
                                                            model.trans2).gamma[-1])


def test_inputs_slopes_voicing_and_silence() -> None:
    silence = np.array([np.nan, -3.0, np.log(0.02)])
    x = np.array([silence, [0.5, 1.0, -1.5], [0.5, 1.0, -1.5], [np.nan, 0.2, -1.6],
                  [1.5, 0.7, -1.4], silence, [0.1, 0.3, -1.5]])
    m = np.tile([0.25, 0.75], (len(x), 1))
    out = dcnf_inputs(x, m, silence)
    assert out.shape == (7, 9)
    np.testing.assert_array_equal(out[:, 0], [0, 1, 1, 0, 1, 0, 1])           # voiced
    np.testing.assert_array_equal(out[:, 4], [1, 0, 0, 0, 0, 1, 0])           # silent
    np.testing.assert_allclose(out[:, 5], [0, 0, 0, 0, 1.0, 0, 0])             # F0 slope
    np.testing.assert_allclose(out[:, 6], [0, 0, 0, -0.8, 0.5, 0, 0])          # intensity slope
    assert np.all(np.isfinite(out))
    np.testing.assert_array_equal(pad_input(silence, m[0]), out[0])
    inp = DCNFInputs(silence)   # streaming = batch
    np.testing.assert_array_equal(np.array([inp.push(a, b) for a, b in zip(x, m, strict=True)]),
                                  out)


def _toy_data(rng, n=300, s=3):
    """A sticky chain whose state shows in the inputs (noisily)."""
    q = np.zeros(n, dtype=int)
    for t in range(1, n):
        q[t] = q[t - 1] if rng.random() < 0.9 else rng.integers(s)
    x = np.eye(s)[q] + rng.normal(0, 0.6, size=(n, s))
    gamma = np.full((n, s), 0.05)
    gamma[np.arange(n), q] = 1 - 0.05 * (s - 1)
    xi = np.zeros((s, s))
    np.add.at(xi, (q[:-1], q[1:]), 1.0)
    xi3 = np.zeros((s, s, s))
    np.add.at(xi3, (q[:-2], q[1:-1], q[2:]), 1.0)
    return x, ChainStats(0.0, gamma, xi, xi3)


def test_training_is_deterministic_and_beats_transitions_only() -> None:
    rng = np.random.default_rng(5)
    (x1, t1), (x2, t2) = _toy_data(rng), _toy_data(rng)
    pad = np.zeros(3)
    cfg = DCNFSettings(window=2, hidden=(8, 4), iterations=100, dropout=0.2, eval_every=5)
    m1, info = fit_dcnf([x1], [t1], pad, cfg, valid=([x2], [t2]))
    m2, _ = fit_dcnf([x1], [t1], pad, cfg, valid=([x2], [t2]))
    np.testing.assert_array_equal(m1.flat(), m2.flat())
    m0, _ = fit_dcnf([x1], [t1], pad, DCNFSettings(window=0, hidden=(2,), iterations=60),
                     valid=([x2], [t2]))
    score = m1.expected_log_likelihood(m1.windows(x2, pad), t2) / len(x2)
    floor = m0.expected_log_likelihood(m0.windows(x2, pad), t2) / len(x2)
    assert score > floor + 0.04
    assert info.valid_loglik_per_step == pytest.approx(score)
    assert info.history[-1] < info.history[0]


def test_model_with_dcnf_saves_loads_and_refuses_a_misfit(tmp_path) -> None:
    from gesture_sim.commands.bench.inference import random_model
    from gesture_sim.inference.model import GestureModel

    model = random_model(4, 5, 3, with_dcnf=True)
    model.save(tmp_path / "m")
    back = GestureModel.load(tmp_path / "m")
    np.testing.assert_array_equal(back.dcnf.flat(), model.dcnf.flat())
    f_a, f_b = model.new_filter("dcnf"), back.new_filter("dcnf")
    assert f_a.n_states == 4
    for i in range(20):
        np.testing.assert_allclose(f_a.step(i / 30), f_b.step(i / 30))
    np.testing.assert_allclose(f_a.belief.sum(), 1.0)
    f_a.reset()
    # an old model (no DCNF) still loads and says so when asked for one
    plain = random_model(4, 5, 3)
    plain.save(tmp_path / "p")
    with pytest.raises(GestureSimError, match="no DCNF"):
        GestureModel.load(tmp_path / "p").new_filter("dcnf")
    # a DCNF whose parameter space is not the model's: refused with one line
    bad = random_model(4, 5, 3, with_dcnf=True)
    bad.dcnf.trans = np.zeros((3, 3))
    bad.save(tmp_path / "b")
    with pytest.raises(GestureSimError) as err:
        GestureModel.load(tmp_path / "b")
    assert "\n" not in str(err.value) and "DCNF" in str(err.value)


def test_trained_dcnf_follows_the_loudness_of_synthetic_speech(tmp_path) -> None:
    """End to end: train_model with the DCNF on synthetic takes (loud speech goes with fast
    gestures); the DCNF filter must put more belief on fast states in loud passages."""
    from dataclasses import replace

    from gesture_sim.inference.model import GestureModel
    from gesture_sim.inference.train import TrainSettings, train_model

    from .synthetic import synthetic_take
    from .test_model_baseline import _run, _stream

    rng = np.random.default_rng(0)
    takes = [synthetic_take(rng, 20.0)]
    cfg = TrainSettings(n_states=3, n_clusters=4, window=3, hmm_restarts=1, crf_max_iter=30,
                        dcnf=True)
    cfg = replace(cfg, dcnf_settings=replace(cfg.dcnf_settings, window=3, hidden=(8, 4),
                                             iterations=40))
    model = train_model(takes, cfg)
    assert model.dcnf is not None and model.summary["dcnf"]["iterations"] >= 1
    model.save(tmp_path / "m")
    loaded = GestureModel.load(tmp_path / "m")
    syl = _stream(False, 0.0, 4.0, rng) + _stream(True, 4.0, 4.0, rng)
    beliefs = _run(loaded.new_filter("dcnf"), syl, 8.0)
    np.testing.assert_allclose(beliefs.sum(axis=1), 1.0, atol=1e-9)
    v = beliefs @ model.hmm.means[:, 2]
    assert v[150:240].mean() > v[30:120].mean() + 0.5

    # figure 4's DCNF row on a held-out split of the same take
    from gesture_sim.inference.evaluate import figure4
    from gesture_sim.inference.train import prepare_takes

    p = prepare_takes(takes, model.settings, model.normalizer_seed, model.param_normalisation)[0]
    cut = int(len(p.x) * 0.7)
    rows = figure4(model.hmm, model.clusters, model.pad_membership, [(p.x[:cut], p.y[:cut])],
                   [(p.x[cut:], p.y[cut:])], windows=(2,), max_iter=20,
                   dcnf=DCNFSettings(hidden=(4, 2), iterations=20, eval_every=5))
    row = rows[0].to_dict()
    assert -np.log(3) < row["dcnf_loglik_per_step"] < 0 and row["dcnf_iterations"] >= 1
