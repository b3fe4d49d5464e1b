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
    actuator forces, the targets and the shaped reference, the positions of all ``n_sites``
    sites of the model (a plain copy of ``site_xpos``; the caller picks its sites when it
    builds the trace) and the COM, the test disturbance, and the row's contacts, raw (geom
    pair, distance, position; one contact log for all rows, :meth:`add_contacts`). Everything
    else in a :class:`SimTrace` (joint angles, pelvis height, the kinematic target pose's
    sites, the contact summaries of :meth:`contact_summary`) is derived from these rows when
    the trace is built, in one vectorised pass: the row itself is a handful of copies.

    Args:
        rows: initial capacity (grows by doubling); n: actuated joints; nq, nv: MuJoCo sizes;
        n_sites: sites per row (the model's ``nsite``); max_support: foot-floor contact points
        kept per row; n_target_sites: sites of the kinematic target pose per row (default
        ``n_sites``).
    """

    def __init__(self, rows: int, n: int, nq: int, nv: int, n_sites: int,
                 max_support: int = 24, n_target_sites: int | None = None) -> None:
        self.i = 0
        self.rows = max(int(rows), 1)
        rows = self.rows
        nt = n_sites if n_target_sites is None else int(n_target_sites)
        self.buf: dict[str, np.ndarray] = {
            "time": np.zeros(rows), "qpos": np.zeros((rows, nq)), "qvel": np.zeros((rows, nv)),
            "act_force": np.zeros((rows, n)), "q_target": np.zeros((rows, n)),
            "q_ref": np.zeros((rows, n)), "sites": np.zeros((rows, n_sites, 3)),
            "com": np.zeros((rows, 3)), "disturbance": np.zeros((rows, 6)),
            "target_sites": np.zeros((rows, nt, 3)),
            # the row's contacts: log entries con_start[i] .. con_start[i + 1] - 1
            "con_start": np.zeros(rows + 1, dtype=np.int64),
        }
        self.max_support = max_support
        cap = 16 * rows
        self.con_geom = np.zeros((cap, 2), dtype=np.int64)
        self.con_dist = np.zeros(cap)
        self.con_pos = np.zeros((cap, 3))
        self.n_con = 0
        #: rows whose ``target_sites`` (filled by the simulator when the trace is built) are done
        self.derived = 0

    def grow(self) -> None:
        """Double every row buffer (for streams of unknown length)."""
        for k, v in self.buf.items():
            if k == "con_start":
                self.buf[k] = np.concatenate([v, np.zeros(self.rows, dtype=v.dtype)])
            else:
                self.buf[k] = np.concatenate([v, np.zeros_like(v)])
        self.rows *= 2

    def add_contacts(self, geom: np.ndarray, dist: np.ndarray, pos: np.ndarray) -> None:
        """Log the current row's contacts (``geom`` (c, 2), ``dist`` (c,), ``pos`` (c, 3)); call
        once per row, before the row is closed (``i`` advanced); c may be 0."""
        c = len(dist)
        j = self.n_con
        if j + c > len(self.con_dist):
            size = max(2 * len(self.con_dist), j + c)
            for name in ("con_geom", "con_dist", "con_pos"):
                old = getattr(self, name)
                new = np.zeros((size, *old.shape[1:]), dtype=old.dtype)
                new[:j] = old[:j]
                setattr(self, name, new)
        self.con_geom[j:j + c] = geom
        self.con_dist[j:j + c] = dist
        self.con_pos[j:j + c] = pos
        self.n_con = j + c

    def close_row(self) -> None:
        """End the current row (its contacts logged)."""
        self.i += 1
        self.buf["con_start"][self.i] = self.n_con

    def trimmed(self) -> dict[str, np.ndarray]:
        """The filled rows of every row buffer (views; ``con_start`` has one entry more)."""
        return {k: v[: self.i + 1] if k == "con_start" else v[: self.i]
                for k, v in self.buf.items()}

    def contact_summary(self, pair_kind: np.ndarray) -> dict[str, np.ndarray]:
        """The per-row contact fields of a :class:`SimTrace` from the contact log.

        ``pair_kind`` (ngeom, ngeom) classifies a geom pair: 0 / 1 the left / right sole on the
        floor, 2 another geom of the body on the floor, 3 the body on itself, else not the
        body's. Returns ``foot_contact`` (T, 2), ``support_points`` (T, max_support, 2; the
        first foot-floor contacts of the row in MuJoCo's order, NaN-padded),
        ``ground_penetration`` (T,; deepest floor contact, >= 0), ``self_contact_count`` and
        ``self_penetration`` (T,; body-body contacts with distance < 0 and the deepest)."""
        rows, cap = self.i, self.max_support
        start = self.buf["con_start"][: rows + 1]
        c = int(start[-1]) - int(start[0])
        geom = self.con_geom[start[0]:start[-1]]
        dist = self.con_dist[start[0]:start[-1]]
        pos = self.con_pos[start[0]:start[-1]]
        row = np.repeat(np.arange(rows), np.diff(start))
        kind = pair_kind[geom[:, 0], geom[:, 1]] if c else np.zeros(0, dtype=np.int8)
        foot_contact = np.zeros((rows, 2), dtype=bool)
        support = np.full((rows, cap, 2), np.nan)
        ground = np.zeros(rows)
        self_count = np.zeros(rows, dtype=int)
        self_pen = np.zeros(rows)
        if c:
            foot_contact[row[kind == 0], 0] = True
            foot_contact[row[kind == 1], 1] = True
            floor = kind <= 2
            deepest = np.full(rows, np.inf)
            np.minimum.at(deepest, row[floor], dist[floor])
            has = np.isfinite(deepest)
            ground[has] = np.maximum(0.0, -deepest[has])
            feet = np.flatnonzero(kind <= 1)
            if len(feet):
                fr = row[feet]
                first = np.searchsorted(fr, fr, side="left")      # rows are ascending
                rank = np.arange(len(feet)) - first
                keep = rank < cap
                support[fr[keep], rank[keep]] = pos[feet[keep], :2]
            inner = (kind == 3) & (dist < 0.0)
            self_count[:] = np.bincount(row[inner], minlength=rows)
            deepest = np.full(rows, np.inf)
            np.minimum.at(deepest, row[inner], dist[inner])
            has = self_count > 0
            self_pen[has] = -deepest[has]
        return {"foot_contact": foot_contact, "support_points": support,
                "ground_penetration": ground, "self_contact_count": self_count,
                "self_penetration": self_pen}
