"""The one physics loop (gesture_sim.sim.world) and the pushed live targets (RollingTargets)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import RollingTargets, TargetStream
from gesture_sim.sim.tracking import HumanoidSim, Push
from gesture_sim.sim.world import PhysicsLoop

# ------------------------------------------------------------------------------ RollingTargets


class _Reference:
    """The pipeline's target_at, as it was before RollingTargets (the behaviour to keep)."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self._q_prev = self._q_last = None
        self._t_last = 0.0

    def push(self, t: float, q: np.ndarray) -> None:
        self._q_prev, self._q_last, self._t_last = self._q_last, q, t

    def target_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if self._q_last is None:
            raise GestureSimError("no control step yet: push audio first")
        if self._q_prev is None or t >= self._t_last:
            return self._q_last, np.zeros_like(self._q_last)
        a = (t - (self._t_last - self.dt)) / self.dt
        a = min(max(a, 0.0), 1.0)
        return (self._q_prev + a * (self._q_last - self._q_prev),
                (self._q_last - self._q_prev) / self.dt)


def test_rolling_targets_reproduce_the_pipeline_interpolation() -> None:
    rng = np.random.default_rng(0)
    dt = 1.0 / 30.0
    new, ref = RollingTargets(dt), _Reference(dt)
    assert not new.ready and new.last is None
    with pytest.raises(GestureSimError, match="no control step yet"):
        new.sample(0.0)
    t = 0.0
    for _ in range(40):
        t += dt * rng.choice([1.0, 1.0, 0.5, 2.0])        # mostly regular, sometimes not
        q = rng.standard_normal(5)
        new.push(t, q)
        ref.push(t, q)
        assert new.ready and new.last is q
        for s in (t - 2 * dt, t - dt, t - 0.7 * dt, t - 0.1 * dt, t, t + 0.3 * dt,
                  *rng.uniform(t - 1.5 * dt, t + 0.5 * dt, 5)):
            (q_new, qd_new), (q_ref, qd_ref) = new.sample(s), ref.target_at(s)
            assert np.array_equal(q_new, q_ref) and np.array_equal(qd_new, qd_ref)
    new.reset()
    assert not new.ready and new.last is None
    with pytest.raises(GestureSimError):
        new.sample(t)
    with pytest.raises(GestureSimError, match="period"):
        RollingTargets(0.0)


# ------------------------------------------------------------------------------ PhysicsLoop


class _Probe:
    """A loop body that logs what the loop asks of it."""

    def __init__(self, name: str, log: list) -> None:
        self.name, self.log = name, log

    def control(self, q_target: np.ndarray, qd_target: np.ndarray) -> None:
        self.log.append(("control", self.name, float(q_target[0])))

    def record_row(self, q_target: np.ndarray) -> None:
        self.log.append(("record", self.name, float(q_target[0])))


def _tiny_loop(control_every: int = 2, record_every: int = 4):
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><option timestep='0.01'/><worldbody/></mujoco>")
    data = mujoco.MjData(model)
    log: list = []
    bodies = [_Probe("a", log), _Probe("b", log)]
    return PhysicsLoop(model, data, bodies, control_every, record_every), log


def test_the_loop_checks_the_rates_once_when_built() -> None:
    with pytest.raises(GestureSimError, match="multiple"):
        _tiny_loop(2, 3)
    with pytest.raises(GestureSimError, match=">= 1"):
        _tiny_loop(0, 4)
    with pytest.raises(GestureSimError, match="multiple"):
        HumanoidSim(control_every=2, record_every=3)


def test_one_update_hooks_then_controls_every_body_then_records_each() -> None:
    loop, log = _tiny_loop()                          # updates of 0.02 s, rows every 2 updates
    loop.begin()
    samples = [lambda t: (np.array([t]), np.zeros(1)),
               lambda t: (np.array([-t]), np.zeros(1))]
    done = loop.run_updates(3, samples, before_control=lambda t: log.append(("hook", t)),
                            after_update=lambda k: log.append(("after", k)))
    assert done is None
    ts = [0.0, 0.02, 0.04]
    expect = []
    for k, t in enumerate(ts):
        expect += [("hook", t), ("control", "a", t), ("control", "b", -t)]
        if k == 1:
            expect += [("record", "a", 0.04), ("record", "b", -0.04)]
        expect += [("after", k)]
    assert len(log) == len(expect)
    for got, want in zip(log, expect, strict=True):
        assert got[:-1] == want[:-1] and got[-1] == pytest.approx(want[-1], abs=1e-12)
    assert loop.updates == 3 and loop.time == pytest.approx(0.06)
    with pytest.raises(GestureSimError, match="2 target streams"):
        loop.run_updates(1, samples[:1])


def test_run_until_stops_at_the_stream_time_and_keeps_the_record_phase() -> None:
    loop, log = _tiny_loop()
    loop.data.time = 5.0                              # stream time starts at begin()
    loop.begin()
    samples = [lambda t: (np.array([t]), np.zeros(1))] * 2
    assert loop.run_until(0.045, samples) == 2        # to 0.04: 0.04 + 0.01 > 0.045
    assert loop.run_until(0.045, samples) == 0
    assert loop.run_until(0.075, samples) == 2        # to 0.08: within half an update past
    assert loop.time == pytest.approx(0.08)
    rows = [e for e in log if e[0] == "record"]
    assert [r[2] for r in rows] == pytest.approx([0.04, 0.04, 0.08, 0.08])
    loop.begin(record=False)
    log.clear()
    loop.run_until(0.1, samples)
    assert log and all(e[0] == "control" for e in log)


# ------------------------------------------------------------------------------ HumanoidSim


def _stream() -> TargetStream:
    t = np.arange(31) / 30.0
    q = np.zeros((31, len(hm.ACTUATED_JOINTS)))
    for k, j in enumerate(("left_shoulder_flex", "left_elbow_flex", "right_shoulder_abduct")):
        q[:, hm.ACTUATED_JOINTS.index(j)] = 0.3 + 0.3 * np.sin(4.0 * t + k)
    return TargetStream(q, rate=30.0)


def _arrays(trace) -> dict[str, np.ndarray]:
    return {f.name: getattr(trace, f.name) for f in dataclasses.fields(trace)
            if isinstance(getattr(trace, f.name), np.ndarray)}


def _assert_same(a, b) -> None:
    x, y = _arrays(a), _arrays(b)
    bad = [k for k in x if not np.array_equal(x[k], y[k], equal_nan=True)]
    assert not bad, bad


def test_run_and_a_streamed_run_of_the_same_stream_are_the_same_trace() -> None:
    s = _stream()

    def fresh() -> HumanoidSim:
        sim = HumanoidSim(seed=1, record_every=10)     # a row every second control update
        sim.reset(s.q[0], settle=0.2)                  # so row 0 has q* = s.q[0] either way
        return sim

    whole = fresh().run(s, duration=1.0)
    sim = fresh()
    sim.begin_trace()
    for k in range(1, 31):
        sim.advance_to(k / 30.0, s.sample)
    _assert_same(whole, sim.trace())
    one = fresh()
    one.begin_trace()
    one.advance_to(1.0, s.sample)                      # one call = the same increments
    _assert_same(whole, one.trace())
    assert len(whole.time) == 51


def test_a_push_acts_through_the_hook_and_is_cleared_after_the_run() -> None:
    sim = HumanoidSim(seed=0)
    sim.reset(settle=0.2)
    trace = sim.run(np.zeros((16, sim.n)), rate=30.0, pushes=[Push(0.105, 0.1, (40.0, 0.0, 0.0))])
    pushed = trace.disturbance[:, 0] == 40.0
    assert pushed.sum() == 10                          # updates from 0.11 s to 0.20 s
    assert trace.time[pushed].min() == pytest.approx(0.12)   # rows end their update
    assert not sim.data.xfrc_applied.any()
