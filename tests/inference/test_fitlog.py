"""EM and k-means convergence problems are counted and summarised, never printed raw."""

from __future__ import annotations

import logging

import numpy as np

from gesture_sim.inference import fitlog
from gesture_sim.inference.hmm import _counting_monitor, fit_hmm


def _few_distinct_points(seed: int = 0) -> np.ndarray:
    """Y (n, 6) taking only 5 distinct values: k-means with 8 clusters warns about it."""
    rng = np.random.default_rng(seed)
    points = rng.normal(0, 1, (5, 6))
    return points[np.repeat(rng.integers(0, 5, 40), rng.integers(3, 12, 40))]


def test_fit_warnings_are_counted_not_printed(capsys, caplog) -> None:
    caplog.set_level(logging.WARNING)
    with fitlog.collect() as outer, fitlog.collect() as inner:
        fit_hmm([_few_distinct_points()], 8, n_restarts=3, n_iter=1)
    for log in (outer, inner):
        assert log.fits == 3
        assert log.not_converged == 3          # one iteration: stopped at the limit
        assert log.warnings == {"k-means found fewer distinct points than clusters": 3}
    line = outer.summary()
    assert line is not None and "\n" not in line
    assert line.startswith("EM did not converge in 3 of 3 fits")
    assert "k-means found fewer distinct points than clusters in 3 of 3 fits" in line
    out, err = capsys.readouterr()
    assert out == "" and err == ""
    assert not [r for r in caplog.records if r.name.startswith(("hmmlearn", "sklearn"))]


def test_clean_fits_have_no_summary_and_nothing_collects_outside() -> None:
    rng = np.random.default_rng(1)
    y = np.concatenate([rng.normal(m, 0.3, (200, 6)) for m in (-2.0, 2.0)])
    fit_hmm([y], 2, n_restarts=1)              # no collector: nothing recorded, no error
    with fitlog.collect() as log:
        fit_hmm([y], 2, n_restarts=2)
    assert log.fits == 2 and log.not_converged == 0 and log.failed == 0
    assert log.summary() is None


def test_counting_monitor_counts_likelihood_drops_silently(caplog) -> None:
    from hmmlearn.base import ConvergenceMonitor

    caplog.set_level(logging.DEBUG)
    monitor = _counting_monitor(ConvergenceMonitor(tol=1e-3, n_iter=10, verbose=False))
    monitor._reset()
    for value in (-10.0, -9.0, -9.5, -9.2, -9.3):
        monitor.report(value)
    assert monitor.drops == 2 and monitor.iter == 5
    assert list(monitor.history) == [-10.0, -9.0, -9.5, -9.2, -9.3]
    assert caplog.records == []


def test_summary_counts() -> None:
    log = fitlog.FitLog()
    for converged in (True, False, True):
        log.add_fit(converged)
    log.add_fit(False, failed=True, warnings=["x", "x"])
    assert log.to_dict()["warnings"] == {"x": 1}
    assert log.summary() == ("EM did not converge in 1 of 4 fits; EM failed in 1 of 4 fits "
                             "(skipped); x in 1 of 4 fits (the best restart of each fit is kept)")
