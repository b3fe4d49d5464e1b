"""Segment distances D_seg, D_sp, D_in."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.motion.distances import (
    DistanceWeights,
    compute_distances,
    interruption_distance,
    pose_distance,
    segment_distance,
    successor_predecessor_distance,
)


def test_pose_distance_is_rms_over_keypoints():
    a = np.zeros((1, 4, 3))
    b = np.zeros((1, 4, 3))
    b[0, 0, 0] = 0.2  # one of four key points 20 cm away
    assert pose_distance(a, b)[0, 0] == pytest.approx(0.2 / 2)


def test_d_seg_symmetric_zero_diagonal_and_grows_with_difference():
    rng = np.random.default_rng(0)
    n = 50
    d = segment_distance(rng.integers(5, 40, n), rng.normal(0, 0.2, (n, 7, 3)),
                         rng.normal(0, 1, (n, 12)))
    np.testing.assert_allclose(d, d.T)
    np.testing.assert_allclose(np.diag(d), 0)
    assert np.all(d[~np.eye(n, dtype=bool)] > 0)
    # Only the length differs: the distance is w_L |log(l1 / l2)|.
    pose = np.zeros((2, 7, 3))
    sig = np.zeros((2, 12))
    w = DistanceWeights(length=2.0)
    assert segment_distance(np.array([10, 40]), pose, sig, w)[0, 1] == pytest.approx(
        2.0 * np.log(4))


def test_d_sp_follows_its_definition_on_a_hand_built_example():
    # Two takes: segments 0 -> 1 and 2 -> 3.
    pred = np.array([-1, 0, -1, 2])
    succ = np.array([1, -1, 3, -1])
    d_seg = np.array([[0, 1, 2, 3], [1, 0, 4, 5], [2, 4, 0, 6], [3, 5, 6, 0]], dtype=float)
    start = np.zeros((4, 1, 3))
    end = np.zeros((4, 1, 3))
    end[1, 0, 0] = 0.5   # segment 1 ends 0.5 m away from where everything starts
    w = DistanceWeights(pose=10.0)
    d_sp = successor_predecessor_distance(d_seg, pred, succ, end, start, w)
    assert d_sp[0, 1] == 0                        # the natural successor
    assert d_sp[2, 3] == 0
    assert d_sp[0, 3] == d_seg[1, 3] + d_seg[0, 2]  # D_seg(succ(0), 3) + D_seg(0, pred(3))
    assert d_sp[2, 1] == d_seg[3, 1] + d_seg[2, 0]
    # 1 has no successor, 2 no predecessor: the pose fallback (end of 1 -> start of 2) twice.
    assert d_sp[1, 2] == pytest.approx(2 * 10.0 * 0.5)
    # 0 -> 0: D_seg(1, 0) + pose fallback (0 has no predecessor; end 0 == start 0).
    assert d_sp[0, 0] == d_seg[1, 0] + 0.0


def test_d_in_is_pose_distance_plus_penalty():
    inter = np.zeros((2, 3, 1, 3))
    inter[0, 2, 0, 2] = 0.3
    start = np.zeros((2, 1, 3))
    d_in = interruption_distance(inter, start, penalty=1.5, weights=DistanceWeights(pose=10.0))
    assert d_in.shape == (2, 3, 2)
    assert d_in[0, 0, 1] == pytest.approx(1.5)
    assert d_in[0, 2, 1] == pytest.approx(1.5 + 3.0)


def test_compute_distances_shapes_and_default_penalty():
    rng = np.random.default_rng(2)
    n = 2000
    d = compute_distances(
        rng.integers(5, 40, n), rng.normal(0, 0.2, (n, 7, 3)), rng.normal(0, 0.2, (n, 7, 3)),
        rng.normal(0, 0.2, (n, 3, 7, 3)), rng.normal(0, 1, (n, 12)),
        np.r_[-1, np.arange(n - 1)], np.r_[np.arange(1, n), -1])
    assert d.d_seg.shape == (n, n) and d.d_sp.shape == (n, n) and d.d_in.shape == (n, 3, n)
    assert d.interrupt_penalty == pytest.approx(np.median(d.d_sp))
    assert np.all(np.diag(d.d_sp, 1) == 0)
    assert np.all(d.d_in >= d.interrupt_penalty)
