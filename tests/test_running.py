"""The one running mean/variance (:class:`gesture_sim.running.RunningStat`): known answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gesture_sim.running import ANCHOR, RunningStat


def _feed(stat: RunningStat, xs) -> RunningStat:
    for x in xs:
        stat.update(float(x))
    return stat


@pytest.mark.parametrize(("location", "expected"), [
    # prior = 2, no floor: (wm, wv) for k = 1, 2, 3
    ("prior", [(1 / 3, 1 / 3), (1 / 4, 1 / 4), (1 / 5, 1 / 5)]),
    ("first", [(1.0, 1 / 3), (1 / 2, 1 / 4), (1 / 3, 1 / 5)]),
    ("anchored", [(1.0, 0.0), (1 / 2, 1 / 4), (1 / 3, 1 / 5)]),
])
def test_weights_of_the_first_observations(location: str, expected) -> None:
    s = RunningStat(0.0, 1.0, prior=2.0, location=location)
    for k, (wm, wv) in enumerate(expected, start=1):
        assert s.weights(k) == pytest.approx((wm, wv), abs=1e-15)


def test_anchored_mean_weight_after_the_anchor() -> None:
    s = RunningStat(0.0, 1.0, prior=2.0, location="anchored")
    assert s.weights(ANCHOR) == pytest.approx((1 / ANCHOR, 1 / (ANCHOR + 2)))
    k = ANCHOR + 1
    assert s.weights(k) == pytest.approx((1 / (2 * k + 2), 1 / (k + 2)))
    floored = RunningStat(0.0, 1.0, prior=2.0, min_weight=0.05, location="anchored")
    assert floored.weights(100) == (0.05, 0.05)


def test_known_answers_of_three_updates() -> None:
    # prior mean 0, var 1, worth 1: x = 2 -> w = 1/2: mean 1, var (1/2)(1 + 1/2 * 4) = 1.5
    s = _feed(RunningStat(0.0, 1.0, prior=1.0), [2.0])
    assert (s.mean, s.var, s.n, s.count) == (1.0, 1.5, 1, 2.0)
    # x = 4 -> w = 1/3, d = 3: mean 2, var (2/3)(1.5 + 3) = 3
    s.update(4.0)
    assert s.mean == pytest.approx(2.0) and s.var == pytest.approx(3.0)
    # the first observation sets the mean; its variance weight only shrinks the prior
    f = _feed(RunningStat(var=4.0, prior=3.0, location="first"), [10.0])
    assert f.mean == 10.0 and f.var == pytest.approx(4.0 * 3 / 4)
    f.update(12.0)  # wm = 1/2, wv = 1/5, d = 2
    assert f.mean == pytest.approx(11.0) and f.var == pytest.approx(0.8 * (3.0 + 0.2 * 4))
    # anchored: the first sets the mean and leaves the variance alone
    a = _feed(RunningStat(70.0, 36.0, prior=5.0, location="anchored"), [50.0])
    assert (a.mean, a.var) == (50.0, 36.0)


def test_cumulative_statistics_equal_numpy() -> None:
    x = np.random.default_rng(0).normal(3.0, 2.0, 1000)
    for s in (RunningStat(location="first"), RunningStat(form="welford")):
        _feed(s, x)
        assert s.mean == pytest.approx(x.mean(), abs=1e-12)
        assert s.var == pytest.approx(x.var(), abs=1e-12)
        assert s.sd == pytest.approx(x.std(), abs=1e-12)


def test_welford_from_a_prior_is_the_pooled_statistic() -> None:
    x = np.random.default_rng(1).normal(10.0, 3.0, 500)
    m0, v0, n0 = 8.0, 4.0, 3.0
    w = _feed(RunningStat(m0, v0, n0, form="welford"), x)
    n = len(x)
    mean = (n0 * m0 + x.sum()) / (n0 + n)
    m2 = n0 * v0 + ((x - x.mean()) ** 2).sum() + n0 * n / (n0 + n) * (m0 - x.mean()) ** 2
    assert w.mean == pytest.approx(mean, abs=1e-12)
    assert w.var == pytest.approx(m2 / (n0 + n), abs=1e-12)
    # West's arithmetic with the same weights is the same statistic (not the same bits)
    west = _feed(RunningStat(m0, v0, n0), x)
    assert west.mean == pytest.approx(w.mean, abs=1e-12)
    assert west.var == pytest.approx(w.var, abs=1e-12)


def test_welford_reads_its_prior_sd_before_any_update() -> None:
    s = RunningStat(1.0, 0.3 * 0.3, 3.0, form="welford")
    assert s.sd == math.sqrt(0.3 * 0.3 * 3.0 / 3.0)


def test_memory_floor_gives_an_exponential_average() -> None:
    w = 0.01
    s = _feed(RunningStat(location="first", min_weight=w), np.zeros(1000))
    assert s.weights(1000) == (w, w)
    _feed(s, np.ones(200))  # a step: the mean closes the gap by (1 - w) per observation
    assert s.mean == pytest.approx(1.0 - (1.0 - w) ** 200, abs=1e-12)
    # without the floor the cumulative mean would be 200 / 1200
    assert s.mean > 0.8


def test_an_exponential_average_is_nan_until_the_first_value() -> None:
    e = RunningStat(mean=math.nan, min_weight=0.5, location="first")
    assert math.isnan(e.mean)
    e.update(4.0)
    assert e.mean == 4.0
    e.update(0.0)  # w = max(1/2, 1/2)
    e.update(0.0)  # w = max(1/3, 1/2)
    assert e.mean == 1.0


def test_anchored_z_scores_ignore_a_constant_offset() -> None:
    x = np.random.default_rng(2).normal(65.0, 4.0, 300)

    def zs(offset: float) -> np.ndarray:
        s = RunningStat(70.0, 36.0, prior=5.0, min_weight=1 / 200, location="anchored")
        out = []
        for v in x + offset:
            s.update(float(v))
            out.append(s.z(float(v)))
        return np.array(out)

    np.testing.assert_allclose(zs(20.0), zs(0.0), atol=1e-9)
    np.testing.assert_allclose(zs(-15.0), zs(0.0), atol=1e-9)
    # a prior location does not have that property
    p0 = _feed(RunningStat(70.0, 36.0, prior=5.0), x[:10])
    p1 = _feed(RunningStat(70.0, 36.0, prior=5.0), x[:10] + 20.0)
    assert abs(p1.z(x[9] + 20.0) - p0.z(x[9])) > 0.1


def test_sd_floor_and_z() -> None:
    s = RunningStat(5.0, 0.0, var_floor=1e-6)
    assert s.sd == pytest.approx(1e-3)
    assert s.z(5.002) == pytest.approx(2.0)


@pytest.mark.parametrize("kwargs", [
    {"location": "middle"}, {"form": "kahan"}, {"prior": -1.0}, {"min_weight": 1.5},
    {"anchor": 0}, {"form": "welford", "location": "first"},
    {"form": "welford", "min_weight": 0.1},
])
def test_bad_parameters_are_refused(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        RunningStat(**kwargs)


def test_normaliser_storage_keeps_the_anchored_variant() -> None:
    from gesture_sim.inference.normalize import SpeakerNormalizer

    d = SpeakerNormalizer().to_dict()
    assert d["logf0"] == {"mean": math.log(160.0), "var": 0.2**2, "count": 5.0,
                          "min_weight": 1 / 200, "n_mean": -1.0}
    for k in ("logf0", "intensity"):
        d[k]["n_mean"] = 0.0
    norm = SpeakerNormalizer.from_dict(d)
    for v in (60.0, 62.0, 64.0):
        norm.intensity.update(v)
    stored = json.loads(json.dumps(norm.to_dict()))
    assert stored["intensity"]["n_mean"] == 3.0 and stored["intensity"]["count"] == 8.0
    again = SpeakerNormalizer.from_dict(stored)
    assert again.intensity.location == "anchored" and again.intensity.n == 3
    for s in (norm.intensity, again.intensity):
        s.update(70.0)
    assert (again.intensity.mean, again.intensity.var) == (norm.intensity.mean,
                                                           norm.intensity.var)
    # a stored seed without n_mean (older models) is the prior variant
    del stored["logf0"]["n_mean"]
    assert SpeakerNormalizer.from_dict(stored).logf0.location == "prior"


def test_the_live_timing_window_keeps_numpys_mean_and_std() -> None:
    from gesture_sim.app.live_stats import RunningWindow

    xs = np.random.default_rng(4).gamma(2.0, 3.0, size=500)
    win = RunningWindow(n=100)
    for x in xs:
        win.add(float(x))
    assert win.count == 500 and win.max == xs.max()
    assert abs(win.mean - xs.mean()) < 1e-12 and abs(win.std - xs.std()) < 1e-12
    assert abs(win.pct(50) - np.percentile(xs[-100:], 50)) < 1e-12


@pytest.mark.parametrize("kw", [dict(location="prior", prior=3.0, var=2.0, min_weight=0.01),
                                dict(location="first", mean=float("nan"), min_weight=0.05),
                                dict(location="first", prior=5.0, var=1.0, min_weight=0.0),
                                dict(location="anchored", prior=4.0, var=1.0, min_weight=0.02)])
def test_update_is_the_weights_recurrence_to_the_last_bit(kw) -> None:
    """The inlined update gives exactly what :meth:`RunningStat.weights` prescribes."""
    xs = np.random.default_rng(5).normal(3.0, 2.0, size=300)
    fast, ref = RunningStat(**kw), RunningStat(**kw)
    for x in xs:
        fast.update(float(x))
        ref.n += 1
        wm, wv = ref.weights(ref.n)
        if ref.n == 1 and ref.location != "prior":
            ref.mean = float(x)
            if ref.location == "anchored":
                continue
            d = 0.0
        else:
            d = float(x) - ref.mean
            ref.mean += wm * d
        ref.var = (1.0 - wv) * (ref.var + wv * d * d)
        assert (fast.mean, fast.var) == (ref.mean, ref.var)
