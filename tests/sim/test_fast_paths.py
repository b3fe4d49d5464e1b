"""The physics loop's fast paths give what the plain per-row / per-call code gave, bit for bit.

Issue 35 item 3 moved work out of the 100 Hz physics loop: the trace recorder logs each row's
contacts raw and summarises them once when the trace is built; the rolling target stream
computes a step's difference once per push; the controller reads contiguous index sets as
slices. Each test here compares a fast path with the plain computation it replaced.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from gesture_sim.sim.targets import RollingTargets
from gesture_sim.sim.trace import TraceRecorder
from gesture_sim.sim.tracking import BalanceGains, HumanoidSim, _span


def _reference_row(kinds: list[int], dist: list[float], pos: np.ndarray, cap: int) -> dict:
    """One row's contact summary as the recorder computed it per row before (plain Python)."""
    out = {"foot_contact": (False, False), "support": np.full((cap, 2), np.nan),
           "ground": 0.0, "self_count": 0, "self_pen": 0.0}
    if not kinds:
        return out
    floor_d = [x for k, x in zip(kinds, dist, strict=True) if k <= 2]
    if floor_d:
        out["ground"] = max(0.0, -min(floor_d))
    out["foot_contact"] = (0 in kinds, 1 in kinds)
    feet = [j for j, k in enumerate(kinds) if k <= 1][:cap]
    if feet:
        out["support"][: len(feet)] = pos[feet, :2]
    self_d = [x for k, x in zip(kinds, dist, strict=True) if k == 3 and x < 0.0]
    if self_d:
        out["self_count"] = len(self_d)
        out["self_pen"] = -min(self_d)
    return out


def _check_summary(rec: TraceRecorder, pair_kind: np.ndarray) -> None:
    got = rec.contact_summary(pair_kind)
    start = rec.buf["con_start"]
    for i in range(rec.i):
        a, b = int(start[i]), int(start[i + 1])
        kinds = [int(pair_kind[g0, g1]) for g0, g1 in rec.con_geom[a:b].tolist()]
        ref = _reference_row(kinds, rec.con_dist[a:b].tolist(), rec.con_pos[a:b],
                             rec.max_support)
        assert tuple(got["foot_contact"][i]) == ref["foot_contact"]
        np.testing.assert_array_equal(got["support_points"][i], ref["support"])
        assert got["ground_penetration"][i] == ref["ground"]
        assert got["self_contact_count"][i] == ref["self_count"]
        assert got["self_penetration"][i] == ref["self_pen"]


def test_contact_summary_matches_the_per_row_rules_on_synthetic_rows():
    rng = np.random.default_rng(3)
    ngeom = 7
    pair_kind = rng.integers(0, 5, size=(ngeom, ngeom)).astype(np.int8)
    rec = TraceRecorder(2, n=1, nq=1, nv=1, n_sites=1, max_support=3)
    for _ in range(40):                               # grows rows and the contact log
        if rec.i >= rec.rows:
            rec.grow()
        c = int(rng.integers(0, 9))
        rec.add_contacts(rng.integers(0, ngeom, size=(c, 2)), rng.normal(0.0, 0.01, size=c),
                         rng.normal(size=(c, 3)))
        rec.close_row()
    assert rec.rows >= 40
    _check_summary(rec, pair_kind)


def test_contact_summary_of_no_contacts_at_all():
    rec = TraceRecorder(4, n=1, nq=1, nv=1, n_sites=1)
    for _ in range(3):
        rec.add_contacts(np.zeros((0, 2), dtype=int), np.zeros(0), np.zeros((0, 3)))
        rec.close_row()
    got = rec.contact_summary(np.zeros((2, 2), dtype=np.int8))
    assert not got["foot_contact"].any() and np.isnan(got["support_points"]).all()
    assert not got["ground_penetration"].any() and not got["self_contact_count"].any()


@pytest.fixture(scope="module")
def moved_sim():
    """A standing humanoid waving its arms for 1 s, its trace recorded."""
    sim = HumanoidSim(balance=BalanceGains(follow_target=True))
    sim.reset()
    sim.begin_trace(expected_s=0.2)                   # forces the recorder to grow
    t = np.arange(31) / 30.0
    q = np.zeros((len(t), sim.n))
    arms = [i for i, j in enumerate(sim.model.actuator(k).name for k in range(sim.n))
            if "shoulder" in j or "elbow" in j]
    q[:, arms] = 0.6 * np.sin(2 * np.pi * t)[:, None]
    stream = RollingTargets(1.0 / 30.0)
    for k, tk in enumerate(t):
        stream.push(float(tk), q[k])
        sim.advance_to(float(tk), stream.sample)
    return sim


def test_streamed_trace_contacts_match_the_per_row_rules(moved_sim):
    rec = moved_sim._stream_rec
    assert rec.n_con > 0
    _check_summary(rec, moved_sim._pair_kind)
    tr = moved_sim.trace()
    assert tr.foot_contact.all()                      # standing: both soles on the floor
    assert len(tr) == rec.i


def test_streamed_trace_sites_are_the_rows_sites(moved_sim):
    """The recorder copies every site; the trace keeps the soles and the tracked sites."""
    tr = moved_sim.trace()
    d = moved_sim.data
    np.testing.assert_array_equal(tr.sim_sites[-1], d.site_xpos[moved_sim._rec_sites[2:]])
    np.testing.assert_array_equal(tr.foot_pos[-1], d.site_xpos[moved_sim._rec_sites[:2]])


def test_rolling_targets_sample_the_same_blend():
    rng = np.random.default_rng(0)
    dt = 1.0 / 30.0
    stream = RollingTargets(dt)
    q0, q1 = rng.normal(size=5), rng.normal(size=5)
    stream.push(0.0, q0)
    q, qd = stream.sample(0.01)
    assert q is q0 and not qd.any()
    stream.push(dt, q1)
    for t in (0.0, 0.004, 0.02, dt - 1e-6, dt, 0.05):
        q, qd = stream.sample(t)
        if t >= dt:
            np.testing.assert_array_equal(q, q1)
            assert not qd.any()
            continue
        a = min(max((t - (dt - dt)) / dt, 0.0), 1.0)
        np.testing.assert_array_equal(q, q0 + a * (q1 - q0))
        np.testing.assert_array_equal(qd, (q1 - q0) / dt)
        assert not qd.flags.writeable                  # shared between samples: read-only


def test_span_is_a_slice_only_for_contiguous_runs():
    assert _span([3, 4, 5]) == slice(3, 6)
    assert isinstance(_span([3, 5]), np.ndarray)
    x = np.arange(10.0)
    for idx in ([2, 3, 4], [1, 4, 7]):
        np.testing.assert_array_equal(x[_span(idx)], x[np.array(idx)])


def test_balance_torques_touch_only_the_legs():
    sim = HumanoidSim()
    sim.reset()
    mujoco.mj_step(sim.model, sim.data, 5)
    tau = sim._balance_torques().copy()
    assert np.abs(tau[sim.leg_idx]).max() > 0
    others = np.setdiff1d(np.arange(sim.n), sim.leg_idx)
    assert not tau[others].any()
