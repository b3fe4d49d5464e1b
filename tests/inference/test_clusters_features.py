"""Prosody clusters (F0 marginalised when unvoiced) and the causal per-step features."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.contracts import Syllable
from gesture_sim.inference.clusters import ProsodyClusters, fit_clusters
from gesture_sim.inference.features import StepSettings, step_inputs, step_outputs


def test_em_with_missing_f0_recovers_two_clusters() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal([1.0, 1.0, -1.5], 0.2, size=(400, 3))
    b = rng.normal([-1.0, -1.0, -2.0], 0.2, size=(400, 3))
    x = np.vstack([a, b])
    x[rng.random(len(x)) < 0.3, 0] = np.nan
    gmm = fit_clusters(x, 2, seed=1)
    order = np.argsort(gmm.means[:, 0])
    np.testing.assert_allclose(gmm.means[order], [[-1.0, -1.0, -2.0], [1.0, 1.0, -1.5]],
                               atol=0.08)
    np.testing.assert_allclose(gmm.weights, [0.5, 0.5], atol=0.05)


def test_unvoiced_rows_ignore_f0_and_memberships_sum_to_one() -> None:
    # Two clusters that differ only in F0: with F0 unknown the membership is the prior.
    cov = np.repeat(np.eye(3)[None] * 0.1, 2, axis=0)
    gmm = ProsodyClusters(np.array([0.3, 0.7]), np.array([[-1.0, 0, 0], [1.0, 0, 0]]), cov)
    unvoiced = gmm.memberships(np.array([[np.nan, 0.5, -1.0]]))[0]
    np.testing.assert_allclose(unvoiced, [0.3, 0.7], atol=1e-12)
    voiced = gmm.memberships(np.array([[-1.0, 0.5, -1.0], [1.0, 0.5, -1.0]]))
    assert voiced[0, 0] > 0.99 and voiced[1, 1] > 0.99
    np.testing.assert_allclose(voiced.sum(axis=1), 1.0)


@pytest.mark.parametrize("x", [[0.3, -0.2, -1.6], [np.nan, 1.0, -2.0]])
def test_fast_single_membership_equals_batch(x) -> None:
    rng = np.random.default_rng(2)
    gmm = fit_clusters(rng.normal(size=(300, 3)), 4, seed=0)
    np.testing.assert_allclose(gmm.membership(np.array(x)), gmm.memberships(np.array([x]))[0],
                               atol=1e-12)


class _Identity:
    """Featurizer stand-in: (f0 or NaN, intensity, length) unnormalised."""

    def features(self, s: Syllable, update: bool = True) -> np.ndarray:
        return np.array([s.f0_hz if s.voiced else np.nan, s.intensity_db, s.length])


def test_step_inputs_hold_latest_known_syllable_then_silence() -> None:
    st = StepSettings(rate_hz=10.0, silence_hold_s=0.5)
    syl = [Syllable(0.0, 0.2, 0.25, 100.0, 60.0, True),
           Syllable(0.2, 0.4, 0.45, None, 50.0, False)]
    x = step_inputs(syl, 12, _Identity(), st)
    silence = st.silence()
    # t = 0.0, 0.1, 0.2: nothing emitted yet -> silence
    for t in range(3):
        np.testing.assert_array_equal(np.isnan(x[t]), np.isnan(silence))
        assert x[t, 1] == silence[1]
    np.testing.assert_allclose(x[3], [100.0, 60.0, 0.2])    # t = 0.3 >= 0.25
    assert np.isnan(x[5, 0]) and x[5, 1] == 50.0             # t = 0.5 >= 0.45, unvoiced
    assert x[9, 1] == 50.0                                   # 0.9 - 0.45 <= 0.5: still held
    assert x[10, 1] == silence[1]                            # 1.0 - 0.45 > 0.5: silence


def test_step_outputs_are_stepwise_per_segment() -> None:
    params = np.arange(18, dtype=float).reshape(3, 6)
    y = step_outputs(np.array([[0, 10], [10, 25], [25, 30]]), params, 30.0, 15, 15.0)
    # step t is at frame 2t
    assert np.all(y[:5] == params[0]) and np.all(y[5:13] == params[1])
    assert np.all(y[13:] == params[2])
