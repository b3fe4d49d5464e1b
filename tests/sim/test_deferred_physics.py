"""The physics loop's deferral (PhysicsLoop.defer_s, the feed's DEFER_PHYSICS_S): the same
physics, run later in longer stretches."""

from __future__ import annotations

import os
import sys
import threading

import numpy as np
import pytest

from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import RollingTargets
from gesture_sim.sim.tracking import HumanoidSim


def _stream(sim: HumanoidSim, defer: float, steps: int = 45, background: str | None = None
            ) -> dict[str, np.ndarray]:
    """Push a 30 Hz target stream and advance after every push, as the feed does (with
    ``background``, ``"thread"`` or ``"process"``, the deferred stretches run there)."""
    rng = np.random.default_rng(3)
    sim.reset()
    sim.begin_trace()
    sim.loop.defer_s = defer
    if background:
        sim.loop.start_background(background)
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
    sim.loop.stop_background()
    return {k: v for k, v in vars(tr).items() if isinstance(v, np.ndarray)}


def test_deferred_physics_is_the_same_physics() -> None:
    now = _stream(HumanoidSim(seed=1), 0.0)
    later = _stream(HumanoidSim(seed=1), 0.25)
    assert now.keys() == later.keys()
    for k in now:
        assert np.array_equal(now[k], later[k], equal_nan=True), k


@pytest.mark.parametrize("mode", ["thread", "process"])
def test_deferred_physics_beside_the_caller_is_the_same_physics(mode: str) -> None:
    """On a thread or in a child process (whose state comes back at the end), then more steps
    here: the same trace as all of it here."""
    beside = _stream(HumanoidSim(seed=1), 0.1, steps=60, background=mode)
    assert not _physics_threads()
    ref = _stream(HumanoidSim(seed=1), 0.0, steps=60)
    assert ref.keys() == beside.keys()
    for k in ref:
        assert np.array_equal(ref[k], beside[k], equal_nan=True), k


def _physics_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "gesture-sim-physics"]


def _gone(pid: int) -> bool:
    """Whether process ``pid`` has ended and been reaped (a zombie still takes signal 0)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


@pytest.mark.parametrize("mode", ["thread", "process"])
def test_an_error_beside_the_caller_reaches_it_once(mode: str) -> None:
    sim = HumanoidSim(seed=0)
    sim.reset()
    sim.begin_trace()
    loop = sim.loop
    loop.defer_s = 0.05

    def boom(pending) -> int:                     # a stretch that fails where it runs
        raise RuntimeError(f"stretch of {len(pending)} failed")

    if mode == "process":
        loop._run_stretch = boom                  # the child inherits it
        loop.start_background("process")
    else:
        loop.start_background("thread")
        loop._worker._run = boom
    worker = loop._worker
    targets = RollingTargets(1.0 / 30.0)
    targets.push(0.0, np.zeros(sim.n))
    loop.run_until(1.0 / 30.0, [targets.sample])
    loop.run_until(0.1, [targets.sample])          # spans defer_s: handed over
    with pytest.raises(Exception, match="stretch of 2 failed"):
        loop.flush()
    assert loop.flush() == 0                       # raised once, not again
    loop.stop_background()
    assert not _physics_threads()
    if mode == "process":
        assert _gone(worker._pid)


@pytest.mark.parametrize("mode", ["thread", "process"])
def test_a_feed_interrupted_leaves_nothing_running_and_the_switch_interval_as_it_was(
        monkeypatch, mode: str) -> None:
    import gesture_sim.feed as fd
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.pipeline import GesturePipeline

    monkeypatch.setattr(fd, "physics_worker", lambda: mode)
    pipe = GesturePipeline.create(method="random", physics=True)
    pipe.reset()
    t = np.arange(2 * SAMPLE_RATE) / SAMPLE_RATE
    audio = (0.3 * np.sin(2 * np.pi * 150 * t) * (np.sin(2 * np.pi * 3 * t) > 0))
    switch = sys.getswitchinterval()
    workers = []

    def stop_at(t_start: float) -> None:
        workers.append(pipe.sim.loop._worker)
        if t_start >= 1.0:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fd.feed(fd._One(pipe), audio.astype(np.float32)[:, None], before_block=stop_at)
    kinds = {type(w).__name__ for w in workers if w is not None}
    assert kinds == {"_StretchProcess" if mode == "process" else "_StretchWorker"}
    assert not _physics_threads()
    if mode == "process":
        assert all(_gone(w._pid) for w in workers if w is not None)
    assert sys.getswitchinterval() == switch
    assert pipe.sim.loop.defer_s == 0.0 and pipe.sim.loop._worker is None


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


@pytest.mark.parametrize("mode", ["thread", "process"])
def test_a_pipeline_run_with_the_physics_beside_it_is_the_same_run(monkeypatch, mode) -> None:
    """The whole pipeline on speech-like audio, the physics beside it and not: the same trace
    and the same control steps, array for array (two fresh pipelines: each reset draws the
    body's seeded starting noise anew)."""
    import gesture_sim.feed as fd
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.pipeline import GesturePipeline

    t = np.arange(int(3.5 * SAMPLE_RATE)) / SAMPLE_RATE
    f0 = 140.0 + 40.0 * np.sin(2 * np.pi * 0.7 * t)
    voiced = np.sin(2 * np.pi * 3.5 * t) > -0.2                  # syllable-like bursts
    audio = (0.3 * np.sin(2 * np.pi * np.cumsum(f0) / SAMPLE_RATE) * voiced).astype(np.float32)
    runs = {}
    for where in (None, mode):
        pipe = GesturePipeline.create(physics=True)
        monkeypatch.setattr(fd, "physics_worker", lambda w=where: w)
        fd.run_file(pipe, y=audio, sr=SAMPLE_RATE)
        tr = pipe.trace()
        runs[where] = ({k: v for k, v in vars(tr).items() if isinstance(v, np.ndarray)},
                       np.array(pipe.log.targets), pipe.sim.hip_strategy_steps,
                       pipe.sim.data.qpos.copy(), pipe.sim.loop.updates)
    (trace0, targets0, hip0, qpos0, n0), (trace1, targets1, hip1, qpos1, n1) = \
        runs[None], runs[mode]
    assert len(trace0["time"]) > 300
    assert np.array_equal(targets0, targets1)
    for k in trace0:
        assert np.array_equal(trace0[k], trace1[k], equal_nan=True), k
    assert (hip0, n0) == (hip1, n1) and np.array_equal(qpos0, qpos1)


@pytest.mark.parametrize("where", ["flush", "submit"])
def test_a_stopped_physics_child_fails_the_parent_within_the_deadline(
        monkeypatch, where: str) -> None:
    """``kill -STOP`` of the physics child: the parent's next wait on it (the state at a flush,
    or a submission its full pipe holds back) ends within the deadline with one line, and the
    child is gone (issue 49)."""
    import signal

    from gesture_sim.errors import GestureSimError
    from gesture_sim.sim import world

    monkeypatch.setenv(world.TIMEOUT_VARIABLE, "1.5")
    sim = HumanoidSim(seed=0)
    sim.reset()
    sim.begin_trace()
    loop = sim.loop
    loop.defer_s = 0.05
    loop.start_background("process")
    worker = loop._worker
    os.kill(worker._pid, signal.SIGSTOP)
    targets = RollingTargets(1.0 / 30.0)
    targets.push(0.0, np.zeros(sim.n))
    with pytest.raises(GestureSimError, match="stopped answering") as err:
        if where == "submit":      # far more than the pipe's buffer: a send blocks
            blob = np.zeros(4_000_000)
            for _ in range(8):
                worker.submit([(0.0, [blob])])
        loop.run_until(0.1, [targets.sample])
        loop.flush()
    assert "\n" not in str(err.value) and world.TIMEOUT_VARIABLE in str(err.value)
    loop.stop_background(cancel=True)
    assert _gone(worker._pid)


def test_the_physics_deadline_variable_is_checked(monkeypatch) -> None:
    from gesture_sim.errors import GestureSimError
    from gesture_sim.sim import world

    monkeypatch.setenv(world.TIMEOUT_VARIABLE, "soon")
    with pytest.raises(GestureSimError, match=world.TIMEOUT_VARIABLE):
        world.physics_timeout_s()
    monkeypatch.setenv(world.TIMEOUT_VARIABLE, "2.5")
    assert world.physics_timeout_s() == 2.5
    monkeypatch.delenv(world.TIMEOUT_VARIABLE)
    assert world.physics_timeout_s() == world.PHYSICS_TIMEOUT_S
