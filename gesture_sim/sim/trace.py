"""``SimTrace``: what a simulation run hands to the plausibility metrics and to the renderers.

One row per recorded physics step (every ``record_every``-th step of the simulation). All
quantities are SI: seconds, metres, radians, newtons, newton-metres. Shapes use T for the number
of rows, n for the number of actuated joints (``joint_names``), S for tracked sites and P for
the maximum number of support (foot-floor contact) points per row.

The class holds plain numpy arrays, so tests can build hand-made traces without MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

#: Sites compared between the simulated body and the kinematic target pose.
TRACKED_SITES = ("left_hand_site", "right_hand_site", "head_site")


@dataclass
class SimTrace:
    """A recorded simulation run.

    Attributes:
        time: (T,) s.
        q: (T, n) actuated joint positions (rad; m for slide joints).
        qd: (T, n) actuated joint velocities (rad/s; m/s).
        q_target: (T, n) the target stream q*(t) at the row's time.
        q_ref: (T, n) the shaped reference the PD tracked (see ``targets.TargetShaper``).
        act_force: (T, n) actuator forces (N·m; N for slides), P + feed-forward, after clamping.
        com: (T, 3) whole-body centre of mass (m).
        pelvis_height: (T,) height of the pelvis (root) origin (m).
        foot_pos: (T, 2, 3) left and right ``*_foot_site`` (sole centre) positions (m).
        foot_contact: (T, 2) bool, whether the left / right foot geoms touch the floor.
        support_points: (T, P, 2) xy of foot-floor contact points (m), NaN-padded.
        ground_penetration: (T,) deepest floor contact of any geom (m, >= 0).
        self_contact_count: (T,) number of body-body contacts with distance < 0.
        self_penetration: (T,) deepest body-body contact (m, >= 0).
        sim_sites: (T, S, 3) positions of ``site_names`` on the simulated body (m).
        target_sites: (T, S, 3) the same sites in the kinematic target pose q*, posed with the
            simulated body's free root (forward kinematics), m.
        assist: (T, 6) external assist wrench on the root (force N, torque N·m): zero by design.
        disturbance: (T, 6) test disturbance wrench (force N, torque N·m), e.g. a push.
        joint_names: the n joint names (``ACTUATED_JOINTS``).
        joint_range: (n, 2) joint limits (rad; m for slides).
        force_range: (n, 2) actuator force limits.
        slide: (n,) bool, True for slide joints.
        joint_groups: group name -> joint names (for per-group statistics).
        site_names: the S tracked site names.
        standing_height: pelvis height of the upright pose (m).
        timestep: physics step (s); ``record_every``: physics steps per row.
        qpos, qvel: (T, nq), (T, nv) full MuJoCo state, for replay and rendering.
    """

    time: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_target: np.ndarray
    q_ref: np.ndarray
    act_force: np.ndarray
    com: np.ndarray
    pelvis_height: np.ndarray
    foot_pos: np.ndarray
    foot_contact: np.ndarray
    support_points: np.ndarray
    ground_penetration: np.ndarray
    self_contact_count: np.ndarray
    self_penetration: np.ndarray
    sim_sites: np.ndarray
    target_sites: np.ndarray
    assist: np.ndarray
    disturbance: np.ndarray
    joint_names: tuple[str, ...]
    joint_range: np.ndarray
    force_range: np.ndarray
    slide: np.ndarray
    joint_groups: dict[str, tuple[str, ...]]
    site_names: tuple[str, ...] = TRACKED_SITES
    standing_height: float = 0.98
    timestep: float = 0.002
    record_every: int = 1
    qpos: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    qvel: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def __len__(self) -> int:
        return len(self.time)

    @property
    def dt(self) -> float:
        """Time between rows (s)."""
        return self.timestep * self.record_every

    @property
    def duration(self) -> float:
        """Time covered by the rows (s)."""
        return float(self.time[-1] - self.time[0]) if len(self.time) > 1 else 0.0

    def save(self, path: str) -> None:
        """Write the trace as a compressed ``.npz`` (atomically)."""
        from gesture_sim.fileio import atomic_path

        arrays = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "joint_groups":
                arrays["joint_groups_keys"] = np.array(list(value))
                arrays["joint_groups_values"] = np.array(["|".join(v) for v in value.values()])
            elif isinstance(value, tuple):
                arrays[f.name] = np.array(value)
            else:
                arrays[f.name] = np.asarray(value)
        with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)

    @classmethod
    def load(cls, path: str) -> SimTrace:
        """Read a trace written by :meth:`save`."""
        with np.load(path) as z:
            kwargs = {}
            for f in fields(cls):
                if f.name == "joint_groups":
                    kwargs[f.name] = {
                        str(k): tuple(str(v).split("|")) if v else ()
                        for k, v in zip(z["joint_groups_keys"], z["joint_groups_values"],
                                        strict=True)}
                elif f.name in ("joint_names", "site_names"):
                    kwargs[f.name] = tuple(str(s) for s in z[f.name])
                elif f.name in ("standing_height", "timestep"):
                    kwargs[f.name] = float(z[f.name])
                elif f.name == "record_every":
                    kwargs[f.name] = int(z[f.name])
                else:
                    kwargs[f.name] = z[f.name]
        return cls(**kwargs)


class TraceRecorder:
    """Preallocated row buffers of what a simulation step leaves in ``MjData`` (raw rows).

    A row holds only what cannot be recomputed afterwards: time, the full state (qpos, qvel),
    actuator forces, the targets and the shaped reference, the positions of ``n_sites`` sites
    and the COM, the test disturbance, and a summary of the contacts. Everything else in a
    :class:`SimTrace` (joint angles, pelvis height, the kinematic target pose's sites) is
    derived from these rows when the trace is built, in one pass.

    Args:
        rows: initial capacity (grows by doubling); n: actuated joints; nq, nv: MuJoCo sizes;
        n_sites: recorded sites per row; max_support: foot-floor contact points kept per row.
    """

    def __init__(self, rows: int, n: int, nq: int, nv: int, n_sites: int,
                 max_support: int = 24) -> None:
        self.i = 0
        self.rows = max(int(rows), 1)
        rows = self.rows
        self.buf: dict[str, np.ndarray] = {
            "time": np.zeros(rows), "qpos": np.zeros((rows, nq)), "qvel": np.zeros((rows, nv)),
            "act_force": np.zeros((rows, n)), "q_target": np.zeros((rows, n)),
            "q_ref": np.zeros((rows, n)), "sites": np.zeros((rows, n_sites, 3)),
            "com": np.zeros((rows, 3)), "disturbance": np.zeros((rows, 6)),
            "foot_contact": np.zeros((rows, 2), dtype=bool),
            "support_points": np.full((rows, max_support, 2), np.nan),
            "ground_penetration": np.zeros(rows), "self_contact_count": np.zeros(rows, dtype=int),
            "self_penetration": np.zeros(rows), "target_sites": np.zeros((rows, n_sites, 3)),
        }
        self.max_support = max_support
        #: rows whose ``target_sites`` (filled by the simulator when the trace is built) are done
        self.derived = 0

    def grow(self) -> None:
        """Double every buffer (for streams of unknown length)."""
        for k, v in self.buf.items():
            extra = np.full_like(v, np.nan) if k == "support_points" else np.zeros_like(v)
            self.buf[k] = np.concatenate([v, extra])
        self.rows *= 2

    def trimmed(self) -> dict[str, np.ndarray]:
        """The filled rows of every buffer (views)."""
        return {k: v[: self.i] for k, v in self.buf.items()}
