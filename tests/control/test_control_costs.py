"""Costs of the control layer: eta by quasi-Monte Carlo, switch costs."""

from __future__ import annotations

import numpy as np
from scipy.special import gammaln

from gesture_sim.control.costs import ControlSettings, expected_mismatch, successor_costs


def test_eta_matches_chi_mean_for_isotropic_state() -> None:
    # E||y - mu|| for y ~ N(mu, s^2 I_6) is s * sqrt(2) * Gamma(7/2) / Gamma(3): closed form.
    s = 0.7
    means = np.zeros((1, 6))
    covs = (s * s * np.eye(6))[None]
    eta, err = expected_mismatch(np.zeros((1, 6)), means, covs)
    exact = s * np.sqrt(2.0) * np.exp(gammaln(3.5) - gammaln(3.0))
    assert abs(eta[0, 0] - exact) <= err[0, 0]
    assert abs(eta[0, 0] - exact) / exact < 2e-3


def test_eta_matches_large_monte_carlo_within_stated_error() -> None:
    rng = np.random.default_rng(0)
    params = rng.normal(size=(20, 6)) * 1.2
    means = rng.normal(size=(4, 6))
    a = rng.normal(size=(4, 6, 6)) * 0.5
    covs = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(6)
    eta, err = expected_mismatch(params, means, covs)
    big = rng.standard_normal((1 << 17, 6))
    eta_mc, err_mc = expected_mismatch(params, means, covs, samples=big)
    # the stated error (plain-MC standard error of the 4096 points) bounds the deviation
    dev = np.abs(eta - eta_mc)
    assert np.all(dev <= 4 * np.sqrt(err**2 + err_mc**2))
    assert np.max(dev / eta_mc) < 5e-3


def test_successor_costs_structure(small_lib) -> None:
    st = ControlSettings(smooth_weight=2.0, extra_interrupt_penalty=0.5)
    s = successor_costs(small_lib, st)
    n, k = small_lib.n_segments, small_lib.n_interrupts
    assert s.shape == (n, k + 1, n)
    assert np.all(np.isinf(s[np.arange(n), :, np.arange(n)]))       # no restart of itself
    off = ~np.eye(n, dtype=bool)
    np.testing.assert_allclose(s[:, k][off], 2.0 * small_lib.d_sp[off])
    valid = small_lib.valid_interrupts()
    a, kk = np.nonzero(valid)
    b = (a + 1) % n
    np.testing.assert_allclose(s[a, kk, b], 2.0 * (small_lib.d_in[a, kk, b] + 0.5))
    assert np.all(np.isinf(s[:, :k][~valid]))
