"""Head and face figures of a run (for ``--metrics``, eval and the tests), from plain arrays.

Columns of every (T, n) array follow :data:`~gesture_sim.signals.ruth.SIGNAL_JOINTS`
(neck flex/bend/twist, head flex/bend/twist, jaw, brows, eyelids, inner brows, mouth corners);
rad, m, rad/s, m/s, N·m, N.

Nods are counted the same way on the simulated body and on motion capture
(:func:`nod_times` on the head's pitch relative to the chest: :func:`smplx_head_pitch` for an
SMPL-X take), so a nod rate can be compared with a real speaker's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gesture_sim.signals.ruth import SIGNAL_JOINTS

_J = {n: i for i, n in enumerate(SIGNAL_JOINTS)}


def head_speed(qvel: np.ndarray) -> np.ndarray:
    """Head angular speed relative to the torso (rad/s), (T,): the norm over flex, bend and
    twist of the neck + head joint rates. ``qvel``: (T, 11) or at least its first 6 columns."""
    v = np.asarray(qvel, dtype=float)
    return np.linalg.norm(v[:, 0:3] + v[:, 3:6], axis=1)


def speed_peaks(times: np.ndarray, speed: np.ndarray, min_speed: float) -> np.ndarray:
    """Times (s) of the local maxima of ``speed`` at or above ``min_speed``."""
    s = np.asarray(speed, dtype=float)
    if len(s) < 3:
        return np.zeros(0)
    k = np.flatnonzero((s[1:-1] >= s[:-2]) & (s[1:-1] > s[2:]) & (s[1:-1] >= min_speed)) + 1
    return np.asarray(times)[k]


def accent_to_peak(accents: Sequence[float], peaks: np.ndarray, lo: float = -0.2,
                   hi: float = 0.4) -> np.ndarray:
    """Per accent, the signed delay (s) to the nearest peak in [t + lo, t + hi] (NaN if none)."""
    out = []
    for t in accents:
        d = np.asarray(peaks) - t
        d = d[(d >= lo) & (d <= hi)]
        out.append(float(d[np.argmin(np.abs(d))]) if len(d) else np.nan)
    return np.array(out)


#: A nod: a downward excursion of the head's pitch of at least this prominence (degrees) over
#: its 1.5 s running median, lasting ``NOD_WIDTH_S`` (at half prominence).
NOD_MIN_DEG = 2.0
NOD_WIDTH_S = (0.08, 1.0)


def nod_times(times: np.ndarray, pitch_rad: np.ndarray, min_deg: float = NOD_MIN_DEG
              ) -> np.ndarray:
    """Times (s) of the nods in a head pitch track (rad, > 0 down; (T,) at a steady rate)."""
    from scipy.ndimage import median_filter
    from scipy.signal import find_peaks

    t = np.asarray(times, dtype=float)
    x = np.degrees(np.asarray(pitch_rad, dtype=float))
    if len(t) < 5:
        return np.zeros(0)
    fps = 1.0 / float(np.median(np.diff(t)))
    base = median_filter(x, size=int(round(1.5 * fps)) | 1, mode="nearest")
    k, _ = find_peaks(x - base, prominence=min_deg,
                      width=(NOD_WIDTH_S[0] * fps, NOD_WIDTH_S[1] * fps))
    return t[k]


def smplx_head_pitch(poses: np.ndarray) -> np.ndarray:
    """The head's pitch relative to the chest (rad, > 0 down), (T,), from SMPL-X ``poses``
    (T, 165) axis-angle: the neck's and head's local rotations composed, as XYZ Euler angles
    about SMPL-X's left (x) axis."""
    from scipy.spatial.transform import Rotation

    from gesture_sim.motion.smplx import SMPLX_JOINTS

    p = np.asarray(poses, dtype=float)
    n, h = SMPLX_JOINTS.index("neck"), SMPLX_JOINTS.index("head")
    rot = Rotation.from_rotvec
    rel = rot(p[:, 3 * n: 3 * n + 3]) * rot(p[:, 3 * h: 3 * h + 3])
    return rel.as_euler("XYZ")[:, 0]


def signal_kinds(events: Sequence[tuple[float, str]]) -> list[str]:
    """The kind (first word: ``nod``, ``jog``, ``brow``, ``blink``, …) of each signal event
    ``(t, text)`` that starts a signal; a channel's release (``"brow end"``, ``"jog end"``) is
    no new signal and is left out."""
    return [text.split()[0] for _, text in events if text and not text.endswith(" end")]


def face_head_figures(times: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
                      q_target: np.ndarray, force: np.ndarray, ranges: np.ndarray,
                      force_ranges: np.ndarray, events: Sequence[tuple[float, str]],
                      accents: Sequence[float], duration_s: float,
                      min_head_speed: float = 0.3) -> dict:
    """JSON-ready head and face figures.

    Args:
        times: (T,) s; qpos, qvel, q_target, force: (T, 11) of the signal joints.
        ranges, force_ranges: (11, 2) joint and actuator force limits.
        events: the signal events ``(t, text)``; accents: accent times (s).
        min_head_speed: a head-speed peak counts from this (rad/s).
    """
    t = np.asarray(times, dtype=float)
    q, qd = np.asarray(qpos, float), np.asarray(qvel, float)
    minutes = max(duration_s, 1e-9) / 60.0
    kinds = signal_kinds(events)
    counts = {k: kinds.count(k) for k in ("nod", "jog", "brow", "blink", "calm")}
    counts["underliners"] = sum(1 for _, x in events if x.startswith("jog ")
                                and not x.endswith(("*", "end")))
    spd = head_speed(qd)
    peaks = speed_peaks(t, spd, min_head_speed)
    lag = accent_to_peak(accents, peaks)
    sig_t = np.array([x for x, text in events if text.startswith(("nod", "jog", "brow"))
                      and not text.endswith("end")])
    met = [bool(len(sig_t) and np.min(np.abs(sig_t - a)) <= 0.2) for a in accents]
    ok = np.isfinite(lag)
    r = np.asarray(ranges, float)
    excess = np.maximum(r[:, 0] - q, 0) + np.maximum(q - r[:, 1], 0)
    fr = np.asarray(force_ranges, float)
    sat = (np.asarray(force) <= fr[:, 0] + 1e-6) | (np.asarray(force) >= fr[:, 1] - 1e-6)
    err = np.sqrt(np.mean((q[:, :6] - np.asarray(q_target)[:, :6]) ** 2))
    return {
        "counts": counts,
        "blinks_per_min": counts["blink"] / minutes,
        "nods_per_min": counts["nod"] / minutes,
        "brow_raises_per_min": counts["brow"] / minutes,
        "accents": len(accents),
        "accents_met_share": float(np.mean(met)) if met else None,
        "accent_to_head_peak_s": {
            "median": float(np.median(lag[ok])) if ok.any() else None,
            "mean_abs": float(np.mean(np.abs(lag[ok]))) if ok.any() else None,
            "sd": float(np.std(lag[ok])) if ok.any() else None,
            "share_within_0.2s": float(np.mean(np.abs(lag) <= 0.2)) if len(lag) else None},
        "head_speed_peaks_per_min": len(peaks) / minutes,
        "head_nods_per_min": len(nod_times(t, q[:, 0] + q[:, 3])) / minutes if len(q) else 0.0,
        "head_speed_max_rad_s": float(spd.max()) if len(spd) else 0.0,
        "head_tracking_rms_deg": float(np.degrees(err)),
        "jaw_open_max_deg": float(np.degrees(q[:, _J["jaw_open"]].max())) if len(q) else 0.0,
        "brow_raise_max_mm": float(1e3 * q[:, 7:9].max()) if len(q) else 0.0,
        "eyelid_close_max_mm": float(1e3 * q[:, 9:11].max()) if len(q) else 0.0,
        "range_excess_max": {n: float(excess[:, i].max()) for i, n in enumerate(SIGNAL_JOINTS)
                             if len(q)},
        "force_saturation_share": float(sat.mean()) if sat.size else 0.0,
    }


def trace_figures(trace, model, events: Sequence[tuple[float, str]], accents: Sequence[float],
                  duration_s: float) -> dict:
    """:func:`face_head_figures` of a :class:`~gesture_sim.sim.trace.SimTrace` of ``model``
    (the humanoid's MuJoCo model; its joint and force ranges by name)."""
    jid = np.array([model.joint(n).id for n in SIGNAL_JOINTS])
    aid = np.array([model.actuator(n).id for n in SIGNAL_JOINTS])
    qadr, dadr = model.jnt_qposadr[jid], model.jnt_dofadr[jid]
    names = [model.actuator(i).name for i in range(model.nu)]
    col = np.array([names.index(n) for n in SIGNAL_JOINTS])
    return face_head_figures(
        trace.time - trace.time[0], trace.qpos[:, qadr], trace.qvel[:, dadr],
        trace.q_target[:, col], trace.act_force[:, col], model.jnt_range[jid],
        model.actuator_forcerange[aid], events, accents, duration_s)
