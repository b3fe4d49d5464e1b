"""Physical-plausibility metrics of a simulation run (ENGINEERING_NOTES §7 items 10-15).

Everything is computed from a :class:`~gesture_sim.sim.trace.SimTrace` alone (no MuJoCo), so
each metric can be checked on a hand-made trace. Units are in the field names (``_mm``,
``_deg``, ``_mm_s``, ``_rad_s2`` ...); shares are fractions of trace rows in [0, 1].
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from gesture_sim.fileio import jsonable
from gesture_sim.sim.trace import SimTrace

#: Pelvis height below this fraction of the standing height counts as a fall.
FALL_FRACTION = 0.6
#: Force at or above this fraction of the actuator's force range counts as saturated.
SATURATION_FRACTION = 0.99
#: Joint-limit excess below this (degrees; mm for slides) is solver softness, not a violation.
LIMIT_TOLERANCE_DEG = 0.5
LIMIT_TOLERANCE_MM = 0.5
#: A target speed above this (rad/s, any hinge) marks a target switch (a jump of q*).
SWITCH_SPEED = 5.0
#: Rows within this time after a switch are excluded from the settled tracking error (s).
TRANSITION_WINDOW = 0.4
#: Moving-average window on joint velocities before differentiating (s) ("light smoothing").
SMOOTH_S = 0.05


@dataclass
class PhysicsMetrics:
    """Plausibility figures of one run. See :func:`physics_metrics` for the definitions."""

    duration_s: float
    fell: bool
    min_pelvis_height_ratio: float
    com_margin_min_m: float
    com_margin_mean_m: float
    foot_skate_mm_s: float
    foot_skate_max_mm_s: float
    ground_penetration_max_mm: float
    ground_penetration_mean_mm: float
    self_contact_share: float
    self_contact_mean_count: float
    self_penetration_max_mm: float
    joint_limit_violation_share: float
    joint_limit_max_excess_deg: float
    joint_limit_max_excess_mm: float
    saturation_share: dict[str, float]
    saturation_share_any: float
    joint_rms_deg: float
    hand_error_rms_mm: float
    head_error_rms_mm: float
    hand_error_settled_rms_mm: float
    head_error_settled_rms_mm: float
    n_switches: int
    peak_accel_rad_s2: dict[str, float]
    max_accel_rad_s2: dict[str, float]
    peak_jerk_rad_s3: dict[str, float]
    assist_impulse_per_s: float
    assist_angular_impulse_per_s: float
    disturbance_impulse_ns: float
    notes: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """A JSON-ready dict (NaN becomes None)."""
        return jsonable(asdict(self))

    def to_json(self, indent: int | None = 1) -> str:
        """The metrics as JSON text."""
        return json.dumps(self.to_dict(), indent=indent)


# --------------------------------------------------------------------------------- geometry
def convex_hull(points: np.ndarray) -> np.ndarray:
    """2-D convex hull (Andrew's monotone chain), counter-clockwise, shape (k, 2).

    Duplicate points are removed; fewer than three distinct points are returned as they are.
    """
    pts = np.unique(np.round(np.asarray(points, dtype=float), 9), axis=0)
    if len(pts) < 3:
        return pts

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[np.ndarray] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[np.ndarray] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    hull = np.array(lower[:-1] + upper[:-1])
    return hull


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    denom = float(ab @ ab)
    s = 0.0 if denom == 0 else min(max(float((p - a) @ ab) / denom, 0.0), 1.0)
    return float(np.linalg.norm(p - (a + s * ab)))


def support_margin(point: np.ndarray, support: np.ndarray) -> float:
    """Signed distance (m) of ``point`` (2,) to the convex hull of ``support`` (k, 2).

    Positive inside the hull (distance to the nearest edge), negative outside (distance to the
    hull), NaN without support points. One or two points form a degenerate hull (a point or a
    segment): the margin is minus the distance to it.
    """
    pts = np.asarray(support, dtype=float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        return math.nan
    hull = convex_hull(pts)
    p = np.asarray(point, dtype=float)
    if len(hull) == 1:
        return -float(np.linalg.norm(p - hull[0]))
    if len(hull) == 2:
        return -_segment_distance(p, hull[0], hull[1])
    edges = np.roll(hull, -1, axis=0) - hull
    rel = p - hull
    crosses = edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0]
    dists = [_segment_distance(p, hull[i], hull[(i + 1) % len(hull)]) for i in range(len(hull))]
    inside = bool(np.all(crosses >= 0))
    return min(dists) if inside else -min(dists)


# --------------------------------------------------------------------------------- helpers
def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average along axis 0 with edge padding; width in rows (>= 1)."""
    if width <= 1 or len(x) < width:
        return x
    pad = width // 2
    xp = np.pad(x, [(pad, width - 1 - pad)] + [(0, 0)] * (x.ndim - 1), mode="edge")
    c = np.cumsum(xp, axis=0)
    c = np.concatenate([np.zeros((1, *x.shape[1:])), c], axis=0)
    return (c[width:] - c[:-width]) / width


def _anatomical_joints(names: tuple[str, ...]) -> dict[str, list[int]]:
    """Group hinge columns by anatomical joint: the name without its last word."""
    out: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        out.setdefault(n.rsplit("_", 1)[0], []).append(i)
    return out


def switch_rows(trace: SimTrace, speed: float = SWITCH_SPEED) -> np.ndarray:
    """Row indices where the target stream jumps (hinge target speed above ``speed`` rad/s)."""
    if len(trace) < 2:
        return np.zeros(0, dtype=int)
    hinge = ~np.asarray(trace.slide, dtype=bool)
    rate = np.abs(np.diff(trace.q_target[:, hinge], axis=0)) / trace.dt
    fast = np.any(rate > speed, axis=1)
    starts = np.flatnonzero(fast & ~np.concatenate([[False], fast[:-1]])) + 1
    return starts


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else math.nan


# --------------------------------------------------------------------------------- metrics
def physics_metrics(trace: SimTrace, switch_speed: float = SWITCH_SPEED,
                    transition_window: float = TRANSITION_WINDOW,
                    smooth_s: float = SMOOTH_S) -> PhysicsMetrics:
    """All plausibility metrics of ``trace``.

    Definitions (T rows, dt = time between rows):
      * fall: pelvis height < 0.6 x standing height in any row.
      * COM margin: signed distance of the COM's ground projection to the convex hull of the
        foot-floor contact points (positive inside), min and mean over rows with contact.
      * foot skating: horizontal speed of a foot site between consecutive rows in which that
        foot touches the floor, mean (and max) over both feet, mm/s.
      * ground penetration: deepest floor contact per row; max, and mean over rows with floor
        contact, mm. Self-penetration: body-body contacts with distance < 0.
      * joint limits: a row violates when a hinge exceeds its range by more than 0.5 deg (or a
        slide by 0.5 mm); share of rows and the largest excess.
      * saturation: per joint group, share of rows where any of its actuators is at >= 99 % of
        its force limit.
      * tracking: RMS of hinge angle error q - q* (deg); RMS of the hand (both pooled) and head
        site position error between the simulated body and the kinematic target pose (mm), over
        all rows and over "settled" rows (more than ``transition_window`` s after a target
        switch, a row where some hinge target moves faster than ``switch_speed`` rad/s).
      * peak joint acceleration / jerk: joint velocities smoothed by a ``smooth_s`` moving
        average, differentiated; per anatomical joint the norm over its hinges; per joint group
        the 99.9th percentile (``peak_*``) and maximum (``max_accel``), rad/s², rad/s³.
      * assist: ∫|assist force| dt / duration (N·s per s) and the same for its torque.
    """
    n_rows = len(trace)
    dt = trace.dt
    duration = trace.duration
    names = tuple(trace.joint_names)
    slide = np.asarray(trace.slide, dtype=bool)
    hinge = ~slide

    ratio = trace.pelvis_height / trace.standing_height
    fell = bool(np.any(ratio < FALL_FRACTION))

    margins = np.array([
        support_margin(trace.com[i, :2], trace.support_points[i]) for i in range(n_rows)])
    margins = margins[np.isfinite(margins)]

    both = trace.foot_contact[1:] & trace.foot_contact[:-1]
    speed = np.linalg.norm(np.diff(trace.foot_pos[:, :, :2], axis=0), axis=-1) / dt
    skate = speed[both]

    floor_rows = trace.ground_penetration > 0
    pen = trace.ground_penetration

    lo, hi = trace.joint_range[:, 0], trace.joint_range[:, 1]
    excess = np.maximum(lo - trace.q, trace.q - hi)
    excess = np.maximum(excess, 0.0)
    ex_deg = np.rad2deg(excess[:, hinge]) if hinge.any() else np.zeros((n_rows, 0))
    ex_mm = excess[:, slide] * 1000.0 if slide.any() else np.zeros((n_rows, 0))
    violating = np.any(ex_deg > LIMIT_TOLERANCE_DEG, axis=1) | np.any(
        ex_mm > LIMIT_TOLERANCE_MM, axis=1)

    limit = np.maximum(np.abs(trace.force_range[:, 0]), np.abs(trace.force_range[:, 1]))
    sat = np.abs(trace.act_force) >= SATURATION_FRACTION * limit
    col = {n: i for i, n in enumerate(names)}
    sat_share = {}
    for group, joints in trace.joint_groups.items():
        idx = [col[j] for j in joints if j in col]
        sat_share[group] = float(np.mean(np.any(sat[:, idx], axis=1))) if idx else 0.0

    err_q = np.rad2deg(trace.q[:, hinge] - trace.q_target[:, hinge])
    site_err = np.linalg.norm(trace.sim_sites - trace.target_sites, axis=-1)
    hand_cols = [i for i, s in enumerate(trace.site_names) if "hand" in s]
    head_cols = [i for i, s in enumerate(trace.site_names) if "head" in s]
    switches = switch_rows(trace, switch_speed)
    settled = np.ones(n_rows, dtype=bool)
    win = int(round(transition_window / dt))
    for r in switches:
        settled[max(r - 1, 0): r + win] = False

    width = max(int(round(smooth_s / dt)), 1)
    qd = _moving_average(trace.qd, width)
    acc = np.gradient(qd, dt, axis=0) if n_rows > 2 else np.zeros_like(qd)
    jerk = np.gradient(_moving_average(acc, width), dt, axis=0) if n_rows > 2 else acc
    edge = 2 * width                      # smoothing and differences are one-sided at the ends
    if n_rows > 4 * edge + 2:
        acc, jerk = acc[edge:-edge], jerk[edge:-edge]
    peak_acc, max_acc, peak_jerk = {}, {}, {}
    anat = _anatomical_joints(names)
    for group, joints in trace.joint_groups.items():
        acc_g, jerk_g = [], []
        for cols in anat.values():
            cols = [c for c in cols if names[c] in joints and hinge[c]]
            if cols:
                acc_g.append(np.linalg.norm(acc[:, cols], axis=1))
                jerk_g.append(np.linalg.norm(jerk[:, cols], axis=1))
        if acc_g and n_rows:
            a = np.concatenate(acc_g)
            peak_acc[group] = float(np.percentile(a, 99.9))
            max_acc[group] = float(a.max())
            peak_jerk[group] = float(np.percentile(np.concatenate(jerk_g), 99.9))

    force_mag = np.linalg.norm(trace.assist[:, :3], axis=1)
    torque_mag = np.linalg.norm(trace.assist[:, 3:], axis=1)
    per_s = 1.0 / duration if duration > 0 else 0.0
    dist_mag = np.linalg.norm(trace.disturbance[:, :3], axis=1)

    return PhysicsMetrics(
        duration_s=float(duration),
        fell=fell,
        min_pelvis_height_ratio=float(ratio.min()) if n_rows else math.nan,
        com_margin_min_m=float(margins.min()) if margins.size else math.nan,
        com_margin_mean_m=float(margins.mean()) if margins.size else math.nan,
        foot_skate_mm_s=float(skate.mean() * 1000) if skate.size else 0.0,
        foot_skate_max_mm_s=float(skate.max() * 1000) if skate.size else 0.0,
        ground_penetration_max_mm=float(pen.max() * 1000) if n_rows else 0.0,
        ground_penetration_mean_mm=float(pen[floor_rows].mean() * 1000) if floor_rows.any()
        else 0.0,
        self_contact_share=float(np.mean(trace.self_contact_count > 0)) if n_rows else 0.0,
        self_contact_mean_count=float(np.mean(trace.self_contact_count)) if n_rows else 0.0,
        self_penetration_max_mm=float(trace.self_penetration.max() * 1000) if n_rows else 0.0,
        joint_limit_violation_share=float(violating.mean()) if n_rows else 0.0,
        joint_limit_max_excess_deg=float(ex_deg.max()) if ex_deg.size else 0.0,
        joint_limit_max_excess_mm=float(ex_mm.max()) if ex_mm.size else 0.0,
        saturation_share=sat_share,
        saturation_share_any=float(np.mean(np.any(sat, axis=1))) if n_rows else 0.0,
        joint_rms_deg=_rms(err_q),
        hand_error_rms_mm=_rms(site_err[:, hand_cols]) * 1000,
        head_error_rms_mm=_rms(site_err[:, head_cols]) * 1000,
        hand_error_settled_rms_mm=_rms(site_err[settled][:, hand_cols]) * 1000,
        head_error_settled_rms_mm=_rms(site_err[settled][:, head_cols]) * 1000,
        n_switches=int(len(switches)),
        peak_accel_rad_s2=peak_acc,
        max_accel_rad_s2=max_acc,
        peak_jerk_rad_s3=peak_jerk,
        assist_impulse_per_s=float(force_mag.sum() * dt * per_s),
        assist_angular_impulse_per_s=float(torque_mag.sum() * dt * per_s),
        disturbance_impulse_ns=float(dist_mag.sum() * dt),
        notes={
            "peak_accel": f"99.9th percentile of |joint angular acceleration| per anatomical "
                          f"joint (norm over its hinges), velocities smoothed {smooth_s} s",
            "settled": f"rows more than {transition_window} s after a target switch "
                       f"(hinge target speed > {switch_speed} rad/s)",
        },
    )
