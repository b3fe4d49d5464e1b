"""The balance law's hip strategy (``BalanceGains.hip_guard``): it acts only when the capture
point leaves its band — never while the body stands, and while a backward push drives the
capture point towards the heels — and not at all when switched off."""

from __future__ import annotations

import numpy as np

from gesture_sim.sim.tracking import BalanceGains, HumanoidSim, Push


def _run(guard, force: float | None) -> HumanoidSim:
    sim = HumanoidSim(balance=BalanceGains(hip_guard=guard))
    sim.reset()
    pushes = [] if force is None else [Push(1.0, 0.1, (force, 0.0, 0.0), body="chest")]
    trace = sim.run(np.zeros((75, sim.n)), rate=30.0, pushes=pushes)
    assert trace.pelvis_height.min() / trace.standing_height > 0.95     # no fall
    return sim


def test_the_hip_strategy_acts_only_beyond_its_band() -> None:
    band = BalanceGains().hip_guard
    assert band is not None and band[0] < 0.0 < band[1]
    assert _run(band, None).hip_strategy_steps == 0            # standing: the band holds
    assert _run(band, -80.0).hip_strategy_steps > 5            # 8 N·s backwards: it acts
    assert _run(None, -80.0).hip_strategy_steps == 0           # off
