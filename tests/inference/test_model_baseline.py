"""Training end to end on synthetic takes, save/load, the run-time filters, the baseline."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.contracts import Syllable
from gesture_sim.inference.levine09 import Discretiser, Levine09Filter
from gesture_sim.inference.model import GestureModel
from gesture_sim.inference.train import TrainSettings, train_model

from .synthetic import synthetic_take


@pytest.fixture(scope="module")
def takes() -> list:
    rng = np.random.default_rng(0)
    return [synthetic_take(rng, 25.0), synthetic_take(rng, 20.0)]


@pytest.fixture(scope="module")
def model(takes) -> GestureModel:
    return train_model(takes, TrainSettings(n_states=3, n_clusters=4, window=3, hmm_restarts=2,
                                            crf_max_iter=80))


def _stream(loud: bool, t0: float, duration: float, rng) -> list[Syllable]:
    out, t = [], t0
    while t < t0 + duration:
        out.append(Syllable(t, t + 0.2, t + 0.25, 220.0 if loud else 120.0,
                            (78.0 if loud else 62.0) + float(rng.normal(0, 1)), True))
        t += 0.25
    return out


def _run(filt, syllables, duration: float, rate: float = 30.0) -> np.ndarray:
    beliefs, k = [], 0
    for i in range(int(duration * rate)):
        t = i / rate
        new = []
        while k < len(syllables) and syllables[k].t_emitted <= t:
            new.append(syllables[k])
            k += 1
        beliefs.append(filt.step(t, new))
    return np.array(beliefs)


def test_loud_speech_shifts_belief_to_fast_states(model: GestureModel) -> None:
    """In the synthetic data loud, high speech goes with fast gestures: the trained CRF must
    put more belief on high-velocity states during loud passages than during quiet ones."""
    rng = np.random.default_rng(1)
    syl = _stream(False, 0.0, 4.0, rng) + _stream(True, 4.0, 4.0, rng)
    for kind in ("crf", "levine09"):
        beliefs = _run(model.new_filter(kind), syl, 8.0)
        np.testing.assert_allclose(beliefs.sum(axis=1), 1.0, atol=1e-9)
        v = beliefs @ model.hmm.means[:, 2]           # expected velocity parameter per step
        assert v[150:240].mean() > v[30:120].mean() + 0.5, kind


def test_save_load_round_trip(model: GestureModel, tmp_path) -> None:
    model.save(tmp_path / "m")
    loaded = GestureModel.load(tmp_path / "m")
    assert loaded.fingerprint == model.fingerprint and loaded.n_states == model.n_states
    np.testing.assert_array_equal(loaded.transition_matrix, model.transition_matrix)
    np.testing.assert_array_equal(loaded.hmm.covars, model.hmm.covars)
    rng = np.random.default_rng(2)
    syl = _stream(True, 0.0, 2.0, rng) + _stream(False, 2.0, 2.0, rng)
    for kind in ("crf", "levine09"):
        np.testing.assert_allclose(_run(loaded.new_filter(kind), syl, 4.0),
                                   _run(model.new_filter(kind), syl, 4.0), atol=1e-12)


def test_transition_matrix_is_row_stochastic_and_predicts(model: GestureModel) -> None:
    t = model.transition_matrix
    assert t.shape == (3, 3)
    np.testing.assert_allclose(t.sum(axis=1), 1.0)
    b = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(model.predict(b, 2), b @ t @ t)


def test_loading_a_missing_model_is_a_clear_error(tmp_path) -> None:
    from gesture_sim.errors import GestureSimError

    with pytest.raises(GestureSimError, match="not an inference model"):
        GestureModel.load(tmp_path)


def test_baseline_forward_probabilities_sum_to_one_and_react(model: GestureModel) -> None:
    assert model.baseline is not None
    filt = Levine09Filter(model.baseline)
    rng = np.random.default_rng(3)
    before = filt.step(0.0)
    np.testing.assert_allclose(filt.alpha.sum(), 1.0)
    loud = _stream(True, 0.0, 1.0, rng)
    after = None
    for i, s in enumerate(loud):
        after = filt.step(s.t_emitted, [s])
        np.testing.assert_allclose(filt.alpha.sum(), 1.0, atol=1e-12)
        assert np.all(filt.alpha >= 0) and i >= 0
    assert np.abs(after - before).sum() > 0.05


def test_discretiser_codes_follow_table() -> None:
    d = Discretiser({"change": (0.0, 1.0), "intensity": (70.0, 4.0), "length": (0.2, 0.05)})
    loud_long = d.observe(Syllable(0, 0.4, 0.45, 150.0, 90.0, True))
    # first syllable: no F0 change; intensity high (2); length long (2)
    assert loud_long == ((0 * 2 + 0) * 3 + 2) * 3 + 2
    rise = d.observe(Syllable(0.5, 0.55, 0.6, 300.0, 60.0, True))
    assert rise // 9 == 2          # up = 1, down = 0
    assert Discretiser.silence() == 1


def test_figure4_crf_beats_window_hmm_on_held_out_take(model: GestureModel, takes) -> None:
    """Fig. 4 protocol on synthetic data: train on one take, score on the other. The CRF must
    beat the generative HMM at every window and a transitions-only chain (W = 0), and the HMM
    (independent window observations) must lose as the window grows."""
    from gesture_sim.inference.evaluate import figure4
    from gesture_sim.inference.train import prepare_takes

    prepared = prepare_takes(takes, model.settings, model.normalizer_seed,
                             model.param_normalisation)
    rows = figure4(model.hmm, model.clusters, model.pad_membership,
                   [(prepared[0].x, prepared[0].y)], [(prepared[1].x, prepared[1].y)],
                   windows=(0, 1, 4), max_iter=80)
    no_input, w1, w4 = rows
    for r in (w1, w4):
        assert r.crf_loglik > r.hmm_loglik
    assert w4.crf_loglik > no_input.crf_loglik              # prosody adds to the transitions
    assert w4.hmm_loglik < w1.hmm_loglik


def test_cli_errors_are_one_line(tmp_path) -> None:
    import subprocess
    import sys

    res = subprocess.run(
        [sys.executable, "-m", "gesture_sim.cli", "train", "--pair", str(tmp_path / "no.npz"),
         str(tmp_path / "no.wav"), "-o", str(tmp_path / "m")], capture_output=True, text=True)
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "motion file not found" in res.stderr
    res = subprocess.run(
        [sys.executable, "-m", "gesture_sim.cli", "train", "--pair", "a", "b", "-o", "m",
         "--states", "1"], capture_output=True, text=True)
    assert res.returncode == 2 and "--states" in res.stderr
