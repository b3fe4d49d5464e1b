"""The physics loop's deferral (PhysicsLoop.defer_s, the feed's DEFER_PHYSICS_S): the same
physics, run later in longer stretches."""

from __future__ import annotations

import numpy as np

from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import RollingTargets
from gesture_sim.sim.tracking import HumanoidSim


def _stream(sim: HumanoidSim, defer: float, steps: int = 45) -> dict[str, np.ndarray]:
    """Push a 30 Hz target stream and advance after every push, as the feed does."""
    rng = np.random.default_rng(3)
    sim.reset()
    sim.begin_trace()
    sim.loop.defer_s = defer
    targets = RollingTargets(1.0 / 30.0)
    q = np.zeros(sim.n)
    arms = hm.actuated_index(hm.JOINT_GROUPS["shoulder"] + hm.JOINT_GROUPS["elbow_forearm"])
    for k in range(steps):
        q = q.copy()
        q[arms] += 0.05 * rng.standard_normal(len(arms))
        targets.push(k / 30.0, q)
        sim.advance_to(k / 30.0, targets.sample)
        sim.advance_to(k / 30.0, targets.sample)        # a repeated call runs nothing
    sim.loop.defer_s = 0.0
    sim.advance_to(steps / 30.0 + 0.05, targets.sample)
    tr = sim.trace()
    return {k: v for k, v in vars(tr).items() if isinstance(v, np.ndarray)}


def test_deferred_physics_is_the_same_physics() -> None:
    now = _stream(HumanoidSim(seed=1), 0.0)
    later = _stream(HumanoidSim(seed=1), 0.25)
    assert now.keys() == later.keys()
    for k in now:
        assert np.array_equal(now[k], later[k], equal_nan=True), k


def test_deferred_calls_wait_until_they_span_defer_s() -> None:
    sim = HumanoidSim(seed=0)
    sim.reset()
    sim.begin_trace()
    loop = sim.loop
    loop.defer_s = 0.2
    targets = RollingTargets(1.0 / 30.0)
    targets.push(0.0, np.zeros(sim.n))
    assert loop.run_until(0.0, [targets.sample]) == 0
    targets.push(1.0 / 30.0, np.zeros(sim.n))
    assert loop.run_until(1.0 / 30.0, [targets.sample]) == 0       # deferred
    assert sim.time == 0.0
    targets.push(0.2, np.zeros(sim.n))
    assert loop.run_until(0.2, [targets.sample]) == 20              # now: every pending call
    assert abs(sim.time - 0.2) < 1e-9
    targets.push(0.25, np.zeros(sim.n))
    loop.run_until(0.25, [targets.sample])
    assert len(sim.trace().time) == 21 + 5                          # trace() runs the rest
    # a stream that is no RollingTargets cannot be frozen: it runs at once
    assert loop.run_until(0.3, [lambda t: (np.zeros(sim.n), np.zeros(sim.n))]) == 5
