"""Each plausibility metric on a hand-made trace whose answer is known."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gesture_sim.metrics.physics import (
    convex_hull,
    physics_metrics,
    support_margin,
    switch_rows,
)
from gesture_sim.sim.trace import SimTrace

DT = 0.01


def make_trace(rows: int = 100, **overrides) -> SimTrace:
    """A still, well-behaved trace of two hinges and one slide; override any field."""
    t = np.arange(rows) * DT
    square = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    support = np.full((rows, 8, 2), np.nan)
    support[:, :4] = square
    fields = dict(
        time=t, q=np.zeros((rows, 3)), qd=np.zeros((rows, 3)), q_target=np.zeros((rows, 3)),
        q_ref=np.zeros((rows, 3)), act_force=np.zeros((rows, 3)), com=np.zeros((rows, 3)),
        pelvis_height=np.full(rows, 1.0), foot_pos=np.zeros((rows, 2, 3)),
        foot_contact=np.ones((rows, 2), dtype=bool), support_points=support,
        ground_penetration=np.zeros(rows), self_contact_count=np.zeros(rows, dtype=int),
        self_penetration=np.zeros(rows), sim_sites=np.zeros((rows, 3, 3)),
        target_sites=np.zeros((rows, 3, 3)), assist=np.zeros((rows, 6)),
        disturbance=np.zeros((rows, 6)), joint_names=("a_flex", "b_flex", "c_slide"),
        joint_range=np.array([[-1.0, 1.0], [-1.0, 1.0], [0.0, 0.01]]),
        force_range=np.array([[-100.0, 100.0], [-50.0, 50.0], [-1.0, 1.0]]),
        slide=np.array([False, False, True]),
        joint_groups={"ga": ("a_flex",), "gb": ("b_flex",), "gc": ("c_slide",)},
        site_names=("left_hand_site", "right_hand_site", "head_site"),
        standing_height=1.0, timestep=DT, record_every=1,
    )
    fields.update(overrides)
    return SimTrace(**fields)


def test_fall_detected_below_sixty_percent_of_standing_height():
    h = np.full(100, 1.0)
    h[50:] = 0.55
    assert physics_metrics(make_trace(pelvis_height=h)).fell
    h[50:] = 0.65
    m = physics_metrics(make_trace(pelvis_height=h))
    assert not m.fell
    assert m.min_pelvis_height_ratio == pytest.approx(0.65)


def test_convex_hull_drops_interior_points():
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.2, 0.7]])
    hull = convex_hull(pts)
    assert len(hull) == 4
    assert {tuple(p) for p in hull} == {(0, 0), (1, 0), (1, 1), (0, 1)}


@pytest.mark.parametrize(("point", "expected"), [
    ((0.05, 0.0), 0.05), ((0.0, 0.0), 0.1), ((0.2, 0.0), -0.1), ((0.13, 0.14), -0.05),
])
def test_support_margin_signed_distance_to_square(point, expected):
    square = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1], [0.0, 0.0]])
    assert support_margin(np.array(point), square) == pytest.approx(expected)


def test_support_margin_degenerate_and_empty():
    assert support_margin(np.zeros(2), np.array([[0.3, 0.4]])) == pytest.approx(-0.5)
    seg = np.array([[-1.0, 1.0], [1.0, 1.0]])
    assert support_margin(np.zeros(2), seg) == pytest.approx(-1.0)
    assert np.isnan(support_margin(np.zeros(2), np.full((3, 2), np.nan)))


def test_com_margin_min_and_mean_from_trace():
    com = np.zeros((100, 3))
    com[:50, 0] = 0.05   # margin 0.05
    com[50:, 0] = 0.15   # margin -0.05
    m = physics_metrics(make_trace(com=com))
    assert m.com_margin_min_m == pytest.approx(-0.05)
    assert m.com_margin_mean_m == pytest.approx(0.0)


def test_foot_skating_counts_only_contact_frames():
    feet = np.zeros((100, 2, 3))
    feet[:, 0, 0] = np.arange(100) * DT * 0.003   # left foot slides at 3 mm/s
    feet[:, 1, 1] = np.arange(100) * DT * 1.0     # right foot moves at 1 m/s ...
    contact = np.ones((100, 2), dtype=bool)
    contact[:, 1] = False                          # ... but in the air
    m = physics_metrics(make_trace(foot_pos=feet, foot_contact=contact))
    assert m.foot_skate_mm_s == pytest.approx(3.0)
    assert m.foot_skate_max_mm_s == pytest.approx(3.0)


def test_ground_and_self_penetration():
    pen = np.zeros(100)
    pen[:40] = 0.002
    pen[40] = 0.004
    count = np.zeros(100, dtype=int)
    count[10:20] = 2
    depth = np.zeros(100)
    depth[10:20] = 0.003
    m = physics_metrics(make_trace(ground_penetration=pen, self_contact_count=count,
                                   self_penetration=depth))
    assert m.ground_penetration_max_mm == pytest.approx(4.0)
    assert m.ground_penetration_mean_mm == pytest.approx((40 * 2.0 + 4.0) / 41)
    assert m.self_contact_share == pytest.approx(0.1)
    assert m.self_contact_mean_count == pytest.approx(0.2)
    assert m.self_penetration_max_mm == pytest.approx(3.0)


def test_joint_limit_violations_share_and_excess():
    q = np.zeros((100, 3))
    q[:10, 0] = 1.0 + np.deg2rad(3.0)      # 3 deg beyond the upper limit
    q[10:20, 1] = -1.0 - np.deg2rad(0.2)   # within tolerance
    q[20, 2] = 0.012                       # slide 2 mm beyond
    m = physics_metrics(make_trace(q=q, q_target=q))
    assert m.joint_limit_max_excess_deg == pytest.approx(3.0)
    assert m.joint_limit_max_excess_mm == pytest.approx(2.0)
    assert m.joint_limit_violation_share == pytest.approx(0.11)


def test_saturation_share_per_group():
    f = np.zeros((100, 3))
    f[:2, 0] = 99.5     # >= 99 % of 100
    f[2:5, 0] = 98.0    # not saturated
    f[:7, 1] = -50.0
    m = physics_metrics(make_trace(act_force=f))
    assert m.saturation_share["ga"] == pytest.approx(0.02)
    assert m.saturation_share["gb"] == pytest.approx(0.07)
    assert m.saturation_share["gc"] == 0.0
    assert m.saturation_share_any == pytest.approx(0.07)


def test_tracking_errors_joint_hand_head():
    q = np.full((100, 3), np.deg2rad(2.0))
    sim = np.zeros((100, 3, 3))
    sim[:, 0, 0] = 0.010     # left hand 10 mm off
    sim[:, 1, 1] = 0.020     # right hand 20 mm off
    sim[:, 2, 2] = 0.005     # head 5 mm off
    m = physics_metrics(make_trace(q=q, sim_sites=sim))
    assert m.joint_rms_deg == pytest.approx(2.0)
    assert m.hand_error_rms_mm == pytest.approx(np.sqrt((10**2 + 20**2) / 2))
    assert m.head_error_rms_mm == pytest.approx(5.0)
    assert m.n_switches == 0


def test_settled_error_excludes_rows_after_a_switch():
    target = np.zeros((100, 3))
    target[50:, 0] = 0.5                     # jump at row 50: 50 rad/s
    sim = np.zeros((100, 3, 3))
    sim[50:70, 0, 0] = 0.1                   # 100 mm error for 0.2 s after the switch
    tr = make_trace(q_target=target, q=target, sim_sites=sim)
    assert list(switch_rows(tr)) == [50]
    m = physics_metrics(tr, transition_window=0.4)
    assert m.n_switches == 1
    assert m.hand_error_settled_rms_mm == pytest.approx(0.0)
    assert m.hand_error_rms_mm == pytest.approx(100 * np.sqrt(20 / 200))


def test_peak_acceleration_of_constant_acceleration():
    rows = 200
    qd = np.zeros((rows, 3))
    qd[:, 0] = 50.0 * np.arange(rows) * DT     # 50 rad/s^2
    m = physics_metrics(make_trace(rows=rows, qd=qd), smooth_s=0.05)
    assert m.peak_accel_rad_s2["ga"] == pytest.approx(50.0, rel=1e-6)
    assert m.max_accel_rad_s2["ga"] == pytest.approx(50.0, rel=1e-6)
    assert m.peak_accel_rad_s2["gb"] == pytest.approx(0.0)
    assert m.peak_jerk_rad_s3["ga"] == pytest.approx(0.0, abs=1e-6)


def test_peak_jerk_of_constant_jerk():
    rows = 300
    t = np.arange(rows) * DT
    qd = np.zeros((rows, 3))
    qd[:, 1] = 0.5 * 400.0 * t**2              # jerk 400 rad/s^3
    m = physics_metrics(make_trace(rows=rows, qd=qd), smooth_s=0.05)
    assert m.peak_jerk_rad_s3["gb"] == pytest.approx(400.0, rel=0.02)


def test_assist_impulse_per_second():
    rows = 1000                                # 10 s
    assist = np.zeros((rows, 6))
    assist[:100, 2] = 10.0                     # 10 N for 1 s
    assist[:50, 3:] = [3.0, 4.0, 0.0]          # 5 N·m for 0.5 s
    m = physics_metrics(make_trace(rows=rows, assist=assist))
    duration = (rows - 1) * DT
    assert m.assist_impulse_per_s == pytest.approx(10.0 / duration)
    assert m.assist_angular_impulse_per_s == pytest.approx(2.5 / duration)
    assert physics_metrics(make_trace()).assist_impulse_per_s == 0.0


def test_to_json_is_valid_and_maps_nan_to_null():
    support = np.full((100, 8, 2), np.nan)      # no contact: margin undefined
    m = physics_metrics(make_trace(support_points=support))
    data = json.loads(m.to_json())
    assert data["com_margin_min_m"] is None
    assert data["fell"] is False
    assert set(data["saturation_share"]) == {"ga", "gb", "gc"}


def test_trace_save_load_roundtrip(tmp_path):
    tr = make_trace(rows=10)
    path = tmp_path / "trace.npz"
    tr.save(str(path))
    back = SimTrace.load(str(path))
    assert back.joint_names == tr.joint_names
    assert back.joint_groups == tr.joint_groups
    np.testing.assert_array_equal(back.support_points, tr.support_points)
    assert back.dt == pytest.approx(DT)
