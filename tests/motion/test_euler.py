"""Continuous Euler angles (issue 49): every triple equals its rotation, and the triples of a
smooth motion through gimbal lock never jump (SciPy's principal triples jump by 180 degrees)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gesture_sim.motion.euler import continuous_euler


def _through_lock(n: int = 61) -> np.ndarray:
    """(n, 3, 3): a rotation whose ZXY middle angle (X) sweeps 0 -> 180 degrees, with some Z
    and Y turning along, so it passes 90 degrees (and lands on it exactly at the middle)."""
    t = np.linspace(0.0, 1.0, n)
    return Rotation.from_euler("ZXY", np.stack([40 * t, 180 * t, -30 * t], axis=1),
                               degrees=True).as_matrix()


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX", "ZXZ"])
def test_each_triple_is_the_rotation_and_none_jumps(order) -> None:
    rot = _through_lock()
    if order == "ZXZ":      # proper Euler: lock at 0 / 180, so sweep X from 20 to 200
        t = np.linspace(0.0, 1.0, 61)
        rot = Rotation.from_euler("ZXZ", np.stack([40 * t, 20 + 180 * t, -30 * t], axis=1),
                                  degrees=True).as_matrix()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)           # SciPy's "Gimbal lock"
        principal = Rotation.from_matrix(rot).as_euler(order, degrees=True)
    scipy_steps = np.abs(np.diff(principal, axis=0)).max()
    ang = continuous_euler(rot, order)
    back = Rotation.from_euler(order, ang, degrees=True).as_matrix()
    np.testing.assert_allclose(back, rot, atol=1e-9)
    steps = np.abs(np.diff(ang, axis=0)).max()
    assert steps < 12.0, steps                 # the sweep moves 3 degrees a frame on X
    if order == "ZXY":
        assert scipy_steps > 90.0, scipy_steps # the flip this is about


def test_whole_turns_are_unwrapped_and_other_axes_broadcast() -> None:
    angle = np.linspace(0.0, 720.0, 49)         # two turns about Y, 15 degrees a frame
    rot = Rotation.from_euler("Y", angle[:, None], degrees=True).as_matrix()
    two = np.stack([rot, np.swapaxes(rot, -1, -2)], axis=1)      # (F, 2, 3, 3)
    ang = continuous_euler(two, "ZXY")
    assert ang.shape == (49, 2, 3)
    np.testing.assert_allclose(ang[:, 0, 2], angle, atol=1e-6)
    np.testing.assert_allclose(ang[:, 1, 2], -angle, atol=1e-6)
    np.testing.assert_allclose(ang[:, :, :2], 0.0, atol=1e-6)


def test_a_locked_frame_splits_the_angle_towards_the_previous_frame() -> None:
    ang = np.array([[30.0, 80.0, 20.0], [31.0, 90.0, 21.0], [32.0, 80.0, 22.0]])
    rot = Rotation.from_euler("ZXY", ang, degrees=True).as_matrix()
    out = continuous_euler(rot, "ZXY")
    np.testing.assert_allclose(Rotation.from_euler("ZXY", out, degrees=True).as_matrix(), rot,
                               atol=1e-9)
    assert np.abs(np.diff(out, axis=0)).max() < 15.0, out


def test_bad_arguments() -> None:
    with pytest.raises(ValueError):
        continuous_euler(np.eye(3), "ZXY")
    with pytest.raises(ValueError):
        continuous_euler(np.eye(3)[None], "ZZY")
    assert continuous_euler(np.zeros((0, 3, 3)), "ZXY").shape == (0, 3)
