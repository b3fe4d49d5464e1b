"""RUTH's automatic brow raises (gesture_sim.signals.ruth): only on the accents its rules mark
(those that may carry a nod), and one raise per movement: a prominent accent within
``brow_gap_s`` of the previous raise does not start a second one (it would be one raise to
see). With these rules the brows rise about as often as people's do (tools/brow_rates.py:
11.4 a minute on the BEAT2 takes against 12.3 from 6.8 % of words, Ambrazaitis et al. 2015)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gesture_sim.contracts import Accent
from gesture_sim.signals.ruth import RuthConfig, RuthSignals

DT = 1 / 30
DUR = 12.0


def _frames(peaks: list[float], loud_db: float, high_st: float, seed: int = 0):
    """10 ms frames of steady speech (60 +- 2 dB, a level 120 Hz) with a prominent nucleus
    (``loud_db`` louder, ``high_st`` higher) over +-20 ms around each of ``peaks`` (s)."""
    rng = np.random.default_rng(seed)
    times = np.arange(0.005, DUR, 0.01)
    db = 60.0 + rng.normal(0.0, 2.0, len(times))
    st = np.zeros(len(times))
    for p in peaks:
        near = np.abs(times - p) <= 0.02
        db[near] += loud_db
        st[near] += high_st
    f0 = 120.0 * 2.0 ** (st / 12.0)
    return times, db, np.zeros(len(times), bool), times + 0.02, f0


def _brows(cfg: RuthConfig, peaks: list[float], strength: float, loud_db: float = 14.0,
           high_st: float = 0.0) -> list[float]:
    """The times of the automatic brow raises for accents at ``peaks``."""
    sig = RuthSignals(cfg, seed=0)
    sig.push_frames(*_frames(peaks, loud_db, high_st))
    acc = [Accent(t=p, t_emitted=p + 0.03, strength=strength) for p in sorted(peaks)]
    for k in range(int(DUR / DT)):
        t = k * DT
        new = [a for a in acc if a.t_emitted <= t]
        acc = acc[len(new):]
        sig.step(t, new, (), True, 0.0)
    return [t for t, e in sig.events if e == "brow 1+2*"]


def test_prominent_strong_accents_raise_the_brows_once_per_movement() -> None:
    cfg = RuthConfig()
    assert cfg.brow_marked_only and 0.4 <= cfg.brow_gap_s <= 1.0
    apart = _brows(cfg, [3.0, 6.0, 9.0], strength=4.0)
    assert len(apart) == 3                                   # each its own raise
    close = _brows(cfg, [3.0, 3.25, 6.0, 9.0], strength=4.0)
    assert len(close) == 3                                   # 3.0 and 3.25: one raise
    assert all(np.min(np.abs(np.array(close) - p)) < 0.2 for p in (3.0, 6.0, 9.0))
    old = _brows(replace(cfg, brow_gap_s=0.0), [3.0, 3.25, 6.0, 9.0], strength=4.0)
    assert len(old) == 4                                     # without the gap: two


def test_only_the_accents_ruth_marks_get_brows() -> None:
    cfg = RuthConfig()
    # loud nuclei of weak accents (strength below the running strengths, no rise): unmarked
    weak = _brows(cfg, [3.0, 6.0, 9.0], strength=1.0)
    assert weak == []
    every = _brows(replace(cfg, brow_marked_only=False), [3.0, 6.0, 9.0], strength=1.0)
    assert len(every) == 3                                   # the old rule: every H accent
    strong = _brows(cfg, [3.0, 6.0, 9.0], strength=4.0)
    assert len(strong) == 3
    # quiet nuclei do not raise the brows, marked or not
    assert _brows(cfg, [3.0, 6.0, 9.0], strength=4.0, loud_db=0.0) == []


def test_a_channel_release_is_no_new_signal() -> None:
    """The face figures count a brow raise once: its release (``brow end``) is not a raise."""
    from gesture_sim.metrics.face import signal_kinds

    events = [(1.0, "brow 1+2*"), (1.4, "brow end"), (2.0, "nod D*"), (2.1, "jog TL"),
              (3.0, "jog end"), (3.2, "blink accent")]
    assert signal_kinds(events) == ["brow", "nod", "jog", "blink"]
