"""The six kinematic parameters of a gesture segment (Gesture Controllers §4.3).

Per segment, from the two hands' positions p_i (6-D), velocities v_i and accelerations a_i:

    T = log(t_n - t_1)                         temporal extent (s)
    D = log(mean_i ||p_i - p_1||)              spatial extent (m)
    V = log(mean_i ||v_i||)                    velocity (m/s)
    A = log(mean_i ||a_i||)                    acceleration (m/s^2)
    C = log(mean_i curvature(v_i, a_i))        curvature (1/m), ||v x a|| / ||v||^3 per hand
    H = log(mean_i sum of hand heights)        hand height above the floor (m)

and the normalisation ``X = W_X * log(B_X * x)`` with ``B_X = 1 / median(x)`` (the log argument
is 1 at the library's median) and ``W_X = 1 / std(log x)`` (unit spread), as suggested in the
digest where the paper's constants are lost. B_X and W_X are stored with a library so that other
motion (e.g. the inference layer's training take) maps into the same space.
"""

from __future__ import annotations

import numpy as np

#: Parameter names, in the order of the columns.
PARAM_NAMES = ("T", "D", "V", "A", "C", "H")
#: Floor of each raw parameter before the log (SI units), so a still segment stays finite.
RAW_FLOOR = np.array([1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2])
#: Speed (m/s) below which curvature is computed as if the hand moved at this speed.
CURVATURE_MIN_SPEED = 0.05
#: Largest curvature (1/m) counted per frame (a 1 cm radius).
CURVATURE_MAX = 100.0


def derivatives(pos: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration by central differences.

    Args:
        pos: (T, ...) positions (m) sampled at ``fps`` (Hz).

    Returns:
        velocity (T, ...) in m/s and acceleration (T, ...) in m/s².
    """
    if pos.shape[0] < 2:
        z = np.zeros_like(pos, dtype=float)
        return z, z.copy()
    vel = np.gradient(pos, 1.0 / fps, axis=0)
    acc = np.gradient(vel, 1.0 / fps, axis=0)
    return vel, acc


def raw_parameters(
    hand_pos: np.ndarray, hand_height: np.ndarray, fps: float,
    segments: list[tuple[int, int]] | np.ndarray,
) -> np.ndarray:
    """The six raw (unlogged) parameters of each segment of one clip.

    Args:
        hand_pos: (T, 2, 3) hand positions (m) in a body-relative frame (pelvis heading frame).
        hand_height: (T, 2) hand heights above the floor (m).
        fps: frame rate (Hz).
        segments: (n, 2) frame ranges ``[start, end)``.

    Returns:
        (n, 6) raw T (s), D (m), V (m/s), A (m/s²), C (1/m), H (m), floored at :data:`RAW_FLOOR`.
    """
    pos = np.asarray(hand_pos, dtype=float)
    vel, acc = derivatives(pos, fps)
    speed = np.linalg.norm(vel, axis=-1)                                   # (T, 2)
    cross = np.linalg.norm(np.cross(vel, acc), axis=-1)
    curvature = np.minimum(cross / np.maximum(speed, CURVATURE_MIN_SPEED) ** 3, CURVATURE_MAX)
    flat_p = pos.reshape(len(pos), -1)
    speed6 = np.linalg.norm(vel.reshape(len(pos), -1), axis=-1)
    acc6 = np.linalg.norm(acc.reshape(len(pos), -1), axis=-1)
    curv = curvature.mean(axis=-1)
    height = np.asarray(hand_height, dtype=float).sum(axis=-1)
    out = np.empty((len(segments), 6))
    for k, (a, b) in enumerate(np.asarray(segments, dtype=int)):
        out[k] = (
            (b - a) / fps,
            np.linalg.norm(flat_p[a:b] - flat_p[a], axis=-1).mean(),
            speed6[a:b].mean(), acc6[a:b].mean(), curv[a:b].mean(), height[a:b].mean(),
        )
    return np.maximum(out, RAW_FLOOR)


def dynamics_signature(
    hand_pos: np.ndarray, fps: float, segments: list[tuple[int, int]] | np.ndarray,
) -> np.ndarray:
    """Per-axis log velocity and log displacement of the hands (for D_seg, Levine 2009 §2.3).

    Both hands go into one 6-D vector so the idle hand of a one-handed gesture counts little.

    Returns:
        (n, 12): ``log(1 + mean |v| / 0.1 m/s)`` per axis and hand (6), then
        ``log(1 + max |p - p_1| / 0.05 m)`` per axis and hand (6).
    """
    pos = np.asarray(hand_pos, dtype=float).reshape(len(hand_pos), -1)
    vel, _ = derivatives(pos, fps)
    out = np.empty((len(segments), 12))
    for k, (a, b) in enumerate(np.asarray(segments, dtype=int)):
        out[k, :6] = np.abs(vel[a:b]).mean(axis=0) / 0.1
        out[k, 6:] = np.abs(pos[a:b] - pos[a]).max(axis=0) / 0.05
    return np.log1p(out)


def fit_normalisation(raw: np.ndarray) -> dict:
    """B_X and W_X from a library's raw parameters (n, 6): B = 1/median, W = 1/std(log).

    Returns:
        ``{"names": [...], "B": [6 floats], "W": [6 floats]}`` (JSON-ready).
    """
    logs = np.log(np.maximum(np.asarray(raw, dtype=float), RAW_FLOOR))
    b = 1.0 / np.exp(np.median(logs, axis=0))
    std = logs.std(axis=0) if len(logs) > 1 else np.ones(6)
    w = 1.0 / np.where(std > 1e-6, std, 1.0)
    return {"names": list(PARAM_NAMES), "B": b.tolist(), "W": w.tolist()}


def normalise(raw: np.ndarray, normalisation: dict) -> np.ndarray:
    """Normalised log parameters ``W_X * log(B_X * x)`` of raw parameters (n, 6)."""
    b = np.asarray(normalisation["B"], dtype=float)
    w = np.asarray(normalisation["W"], dtype=float)
    return w * np.log(b * np.maximum(np.asarray(raw, dtype=float), RAW_FLOOR))


def interruption_frames(length: int) -> tuple[int, int, int]:
    """Three uniformly spaced interruption offsets ``0 < f1 < f2 < f3 < length`` (frames).

    Requires ``length >= 4``.
    """
    if length < 4:
        raise ValueError(f"a segment needs 4 frames for 3 interruption frames, got {length}")
    f = [int(round(length * k / 4)) for k in (1, 2, 3)]
    f[0] = max(f[0], 1)
    f[1] = max(f[1], f[0] + 1)
    f[2] = min(max(f[2], f[1] + 1), length - 1)
    return f[0], f[1], f[2]
