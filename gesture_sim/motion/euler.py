"""Euler angles that stay continuous over time, for the BVH exporters' rotation channels.

A rotation has two Euler triples in every intrinsic order (and the multiples of 360 degrees of
each angle): for three different axes (``ZXY``) ``(a, b, c)`` and ``(a + 180, 180 - b, c +
180)``; for a repeated first axis (``ZXZ``) ``(a, b, c)`` and ``(a + 180, -b, c + 180)``.
SciPy's decomposition returns the one with the middle angle in [-90, 90] (resp. [0, 180]), so a
limb whose middle angle passes 90 degrees (gimbal lock) jumps by 180 degrees on the other two
channels in one frame, and tools that interpolate channels spin it. :func:`continuous_euler`
instead takes, per frame, of every triple equal to the rotation the one closest (Euclidean, in
angle space) to the previous frame's: the two branches, each angle shifted by whole turns
towards the previous value. At gimbal lock itself (the middle angle at 90 degrees, where only
the sum or difference of the other two is defined) it splits that sum between them as close to
the previous frame's as it can.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.spatial.transform import Rotation

#: |cos b| (three axes) or |sin b| (repeated axis) below which a frame counts as gimbal-locked.
LOCK_EPS = 1e-6


def continuous_euler(rotations: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles (F, ..., 3) of rotation matrices (F, ..., 3, 3), continuous in F.

    Args:
        rotations: (F, ..., 3, 3) rotation matrices; axis 0 is time.
        order: three upper-case axes, intrinsic (``"ZXY"``: first about Z, then about the new
            X, then about the newest Y), as BVH channels are listed.
        degrees: angles in degrees (else radians).

    Returns:
        (F, ..., 3) angles in ``order``; frame 0 is SciPy's principal triple, every later frame
        the equivalent triple nearest to the frame before (see the module docstring).
    """
    rotations = np.asarray(rotations, dtype=float)
    if rotations.ndim < 3 or rotations.shape[-2:] != (3, 3):
        raise ValueError(f"expected rotation matrices (F, ..., 3, 3), got {rotations.shape}")
    if len(order) != 3 or not set(order) <= set("XYZ") or order[0] == order[1] or \
            order[1] == order[2]:
        raise ValueError(f"not an Euler order: {order!r}")
    shape = rotations.shape[:-2]
    if rotations.shape[0] == 0:
        return np.zeros((*shape, 3))
    flat = rotations.reshape(-1, 3, 3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)       # SciPy's "Gimbal lock detected"
        ang = Rotation.from_matrix(flat).as_euler(order).reshape(shape[0], -1, 3)
    proper = order[0] == order[2]
    alt = ang.copy()
    alt[..., 0] += np.pi
    alt[..., 1] = -ang[..., 1] if proper else np.pi - ang[..., 1]
    alt[..., 2] += np.pi
    mid = np.sin(ang[..., 1]) if proper else np.cos(ang[..., 1])
    locked = np.abs(mid) < LOCK_EPS
    # the sign s with which the third angle enters at lock: R(a + t, b, c + s t) = R(a, b, c)
    sign = np.zeros(ang.shape[:-1])
    if np.any(locked):
        sign[locked] = _lock_sign(ang[locked], order)
    out = np.empty_like(ang)
    out[0] = ang[0]
    turn = 2.0 * np.pi
    for t in range(1, len(ang)):
        prev = out[t - 1]
        best = None
        for cand in (ang[t], alt[t]):
            c = cand + turn * np.round((prev - cand) / turn)
            lk = locked[t]
            if np.any(lk):       # slide along the locked family towards the previous triple
                s = sign[t][lk]
                shift = ((prev[lk, 0] - c[lk, 0]) + s * (prev[lk, 2] - c[lk, 2])) / 2.0
                c[lk, 0] += shift
                c[lk, 2] += s * shift
            dist = np.sum((c - prev) ** 2, axis=-1)
            if best is None:
                best, best_dist = c, dist
            else:
                better = dist < best_dist
                best = np.where(better[:, None], c, best)
                best_dist = np.minimum(dist, best_dist)
        out[t] = best
    out = out.reshape(*shape, 3)
    return np.degrees(out) if degrees else out


def _lock_sign(ang: np.ndarray, order: str) -> np.ndarray:
    """(N,) +1 or -1: whether the third angle moves with (+1) or against (-1) the first along
    the family of triples of one gimbal-locked rotation (N, 3)."""
    base = Rotation.from_euler(order, ang).as_matrix()
    probe = ang.copy()
    probe[:, 0] += 0.1
    probe[:, 2] += 0.1
    same = np.abs(Rotation.from_euler(order, probe).as_matrix() - base).max(axis=(1, 2)) < 1e-6
    return np.where(same, 1.0, -1.0)
