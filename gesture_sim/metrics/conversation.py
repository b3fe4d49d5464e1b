"""Conversation figures from plain arrays: where the hands are when the partner speaks."""

from __future__ import annotations

from typing import Any

import numpy as np

#: Wrist speed (m/s) below which a hand counts as at rest.
REST_SPEED = 0.05


def inside(t: np.ndarray, spans: list[tuple[float, float]]) -> np.ndarray:
    """Which of the times ``t`` (n,) (s) lie in any of the ``[a, b)`` spans; (n,) bool."""
    mask = np.zeros(len(t), dtype=bool)
    for a, b in spans:
        mask |= (t >= a) & (t < b)
    return mask


def hand_rest_figures(trace: Any, partner_spans: list[tuple[float, float]],
                      settle_s: float = 1.0) -> dict[str, float | None]:
    """How still the hands are in the partner's turns, after ``settle_s`` s into each.

    Returns ``{"wrist_speed_p95_m_s", "rest_share"}`` over those frames (None without any):
    the 95th percentile of the faster wrist's speed, and the share of frames below
    :data:`REST_SPEED`.
    """
    hands = trace.sim_sites[:, :2]                                     # (T, 2, 3)
    dt = np.diff(trace.time)
    speed = np.max(np.linalg.norm(np.diff(hands, axis=0), axis=2), axis=1) / dt
    t = trace.time[1:]
    late = [(a + settle_s, b) for a, b in partner_spans if b - a > settle_s]
    mask = inside(t, late)
    if not mask.any():
        return {"wrist_speed_p95_m_s": None, "rest_share": None}
    return {"wrist_speed_p95_m_s": float(np.percentile(speed[mask], 95)),
            "rest_share": float(np.mean(speed[mask] < REST_SPEED))}
