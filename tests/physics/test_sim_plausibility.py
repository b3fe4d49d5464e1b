"""Physics-plausibility suite: the free-standing humanoid stands, gestures and recovers.

No assist force exists in the simulation (the root is free, nothing holds it); the push test's
disturbance is applied through xfrc_applied and recorded separately from the assist.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.metrics.physics import physics_metrics
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import TargetShaper, TargetStream
from gesture_sim.sim.tracking import HumanoidSim, Push
from gesture_sim.testing.procedural import gesture_stream

MOCAP_REF = Path(__file__).resolve().parents[1] / "data" / "physics" / "mocap_accel_reference.json"


def test_target_stream_is_linear_with_finite_difference_velocity():
    q = np.array([[0.0, 1.0], [0.3, 1.0], [0.3, 0.4]])
    s = TargetStream(q, rate=10.0)
    pos, vel = s.sample(0.05)
    np.testing.assert_allclose(pos, [0.15, 1.0])
    np.testing.assert_allclose(vel, [3.0, 0.0])
    pos, vel = s.sample(0.15)
    np.testing.assert_allclose(pos, [0.3, 0.7])
    np.testing.assert_allclose(vel, [0.0, -6.0])
    pos, vel = s.sample(5.0)                              # holds after the end
    np.testing.assert_allclose(pos, [0.3, 0.4])
    np.testing.assert_allclose(vel, [0.0, 0.0])
    rq, rv = s.resample(np.array([0.05, 0.15]))
    np.testing.assert_allclose(rq, [[0.15, 1.0], [0.3, 0.7]])
    np.testing.assert_allclose(rv, [[3.0, 0.0], [0.0, -6.0]])


def test_shaper_bounds_acceleration_and_converges_to_a_jump():
    sh = TargetShaper(1, omega=30.0, v_max=8.0, a_max=100.0)
    sh.reset(np.zeros(1))
    acc = []
    for k in range(1000):                                  # 1 s at 1 kHz; a jump of 1 rad
        qd = 30.0 if k < 33 else 0.0                       # spread over one 30 Hz interval
        r, v, a = sh.step(np.array([min(k / 33, 1.0)]), np.array([qd]), 0.001)
        acc.append(abs(a[0]))
    assert max(acc) <= 100.0 + 1e-9
    assert r[0] == pytest.approx(1.0, abs=1e-3) and abs(v[0]) < 1e-2


def test_shaper_follows_a_smooth_ramp_without_lag():
    sh = TargetShaper(1, omega=30.0)
    sh.reset(np.zeros(1), np.array([1.0]))
    for k in range(1, 501):
        r, _, _ = sh.step(np.array([k * 0.002]), np.array([1.0]), 0.002)
    assert r[0] == pytest.approx(1.0, abs=0.0021)         # at most one step (2 ms) ahead


@pytest.fixture(scope="module")
def sim():
    return HumanoidSim(seed=0)


def _assert_plausible(m, skate_mm_s=2.0):
    assert not m.fell
    assert m.assist_impulse_per_s == 0.0 and m.assist_angular_impulse_per_s == 0.0
    assert m.foot_skate_mm_s < skate_mm_s
    assert m.ground_penetration_max_mm < 5.0
    assert m.joint_limit_max_excess_deg < 2.0
    assert max(m.saturation_share.values()) < 0.01


@pytest.mark.slow
def test_stands_still_for_60_seconds(sim):
    sim.reset()
    trace = sim.run(np.zeros((60 * 30 + 1, sim.n)), rate=30.0)
    m = physics_metrics(trace)
    _assert_plausible(m, skate_mm_s=0.5)
    assert trace.duration == pytest.approx(60.0, abs=0.02)
    assert m.com_margin_min_m > 0.02                      # COM well inside the feet
    assert m.min_pelvis_height_ratio > 0.98
    drift = np.linalg.norm(trace.foot_pos[-1, :, :2] - trace.foot_pos[0, :, :2], axis=1)
    assert drift.max() < 0.002                             # feet planted (m)


@pytest.fixture(scope="module")
def gesture_metrics(sim):
    stream, _ = gesture_stream(60.0, seed=7)
    sim.reset(stream.q[0])
    return physics_metrics(sim.run(stream))


@pytest.mark.slow
def test_tracks_60_seconds_of_procedural_gestures(gesture_metrics):
    m = gesture_metrics
    _assert_plausible(m)
    assert m.n_switches >= 15                              # the stream really switches
    assert m.hand_error_settled_rms_mm < 30.0
    assert m.head_error_settled_rms_mm < 30.0
    assert m.hand_error_rms_mm < 180.0                     # all rows, switches included: 133
    assert m.self_penetration_max_mm < 6.0                 # stiff arm contacts: 2.8 mm
    ref = json.loads(MOCAP_REF.read_text())["groups"]
    for group in ("shoulder", "elbow_forearm", "wrist", "neck_head", "spine", "clavicle"):
        assert m.peak_accel_rad_s2[group] < ref[group]["p999"], group


@pytest.mark.slow
def test_feet_do_not_skate_during_gestures(gesture_metrics):
    assert gesture_metrics.foot_skate_mm_s < 1.0     # measured 0.58 (0.96 before the leg armature)
    assert gesture_metrics.min_pelvis_height_ratio > 0.95


def _hip_twist_torques(sim):
    idx = hm.actuated_index([f"{s}_hip_twist" for s in ("left", "right")])
    return sim._balance_torques()[idx]


def test_heading_follows_the_feet_so_a_turned_body_is_not_twisted_back():
    """Standing turned 20 degrees on the floor, the balance law asks for no yaw torque."""
    import mujoco
    sim = HumanoidSim(seed=0)
    sim.reset(settle=0.0)
    q = sim.data.qpos
    half = np.deg2rad(20.0) / 2
    q[3:7] = [np.cos(half), 0.0, 0.0, np.sin(half)]            # the whole body yawed 20 deg
    sim.data.qvel[:] = 0.0
    mujoco.mj_forward(sim.model, sim.data)
    assert np.all(np.abs(_hip_twist_torques(sim)) < 2.0)        # N·m; a world heading: ~100


def test_yaw_moment_is_bounded_by_the_soles_friction_budget():
    """A fast pelvis spin: hip-twist feed-forward stays within yaw_moment_arm x weight."""
    import mujoco
    sim = HumanoidSim(seed=0)
    sim.reset(settle=0.0)
    sim.data.qvel[:] = 0.0
    sim.data.qvel[5] = 3.0                                      # rad/s about the vertical
    mujoco.mj_forward(sim.model, sim.data)
    budget = sim.balance.yaw_moment_arm * sim.mass * sim.gravity
    assert sim.balance.kd_ori * 3.0 > 5 * budget                # the unbounded ask is far more
    assert np.abs(_hip_twist_torques(sim)).sum() <= budget * 1.01


@pytest.mark.slow
@pytest.mark.parametrize("force", [(200.0, 0.0, 0.0), (0.0, 150.0, 0.0), (-100.0, 0.0, 0.0)])
def test_recovers_from_a_push(sim, force):
    """A 0.1 s push on the chest: 20 N·s forward, 15 N·s sideways, 10 N·s backward."""
    sim.reset()
    push = Push(t_start=1.0, duration=0.1, force=force, body="chest")
    trace = sim.run(np.zeros((4 * 30 + 1, sim.n)), pushes=[push])
    m = physics_metrics(trace)
    assert m.disturbance_impulse_ns == pytest.approx(push.impulse, rel=0.1)
    assert not m.fell
    assert m.assist_impulse_per_s == 0.0
    assert np.all(trace.foot_contact[-50:])                # both feet down again
    assert m.foot_skate_mm_s < 2.0
    start = trace.com[0, :2]
    assert np.linalg.norm(trace.com[-1, :2] - start) < 0.02  # back over the feet
