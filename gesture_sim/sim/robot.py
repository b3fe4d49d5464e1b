"""A robot body standing on its own feet, driven within its motors' limits.

The robot's motors are torque motors (``<motor>``, limit = ``ctrlrange``, N·m). Each is run as
its driver runs it on the real robot (Unitree's low-level command: q*, q̇*, kp, kd, τ_ff)::

    tau_j = clamp(kp_j (q*_j - q_j) + kd_j (qd*_j - qd_j) + tau_ff_j, ctrlrange_j)

evaluated by MuJoCo at every physics step (the motor is compiled as a PD actuator whose force
range is the motor's ``ctrlrange``: the applied torque never exceeds the motor's limit, and
``implicitfast`` integrates the kd term implicitly). The control update (100 Hz) sets
(q*, q̇*) from the shaped reference of the target stream and τ_ff:

* arms and spine: gravity and Coriolis of what each joint carries, ``qfrc_bias`` (the
  reference acceleration is left out);
* legs: PD to the map's standing pose plus a balance law adapted from
  :class:`~gesture_sim.sim.tracking.HumanoidSim`'s: a desired ground-reaction wrench on the
  body, ``F = m (g e_z + kp_c (s - c) - kd_c ċ)`` (COM c over the support centre s, the
  mid-point of the soles) and ``M = kp_o e_pelvis - kd_o ω`` (pelvis upright, square to the
  feet's mean heading), split between the feet by where the COM lies between them and mapped
  to leg torques by ``tau = -J_iᵀ [F_i; M_i]`` (J_i: the sole's Jacobian over that leg's
  joints). Not adapted: the humanoid's centre-of-pressure clipping, yaw budget, hip strategy
  and target-COM following (the robot's legs hold one stance).

Nothing holds, welds or pushes the robot: ``SimTrace.assist`` is zero. The trace's joint
order is the robot's actuator order.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim.bodies import RobotMap
from gesture_sim.sim.targets import TargetShaper
from gesture_sim.sim.trace import TRACKED_SITES, SimTrace, TraceRecorder
from gesture_sim.sim.world import PhysicsLoop, Sample

_SIDES = ("left", "right")
#: Balance gains for a robot: COM (1/s², 1/s), pelvis orientation (per kg: N·m/rad/kg,
#: N·m·s/rad/kg).
KP_COM, KD_COM = 30.0, 10.0
KP_ORI_PER_KG, KD_ORI_PER_KG = 8.0, 0.8
#: Reference acceleration bound (rad/s²) of every joint; the speed bound is 0.9 of the joint's.
A_MAX = 200.0


class RobotSim:
    """A free-standing robot tracking joint targets (module docstring).

    Args:
        robot: the robot's map; model: its compiled model (default ``robot.load_model()``).
        seed: the initial-state noise; control_every, record_every: physics steps per control
            update (default 100 Hz) and per trace row (default the same).
        shaper_omega: the reference model's bandwidth (rad/s); upper_gain: factor on the map's
            kp of the arms and spine (kd: its square root, the same damping ratio); default
            (None) the map's ``shaper_omega`` / ``upper_gain`` (30 rad/s and 1 where it has
            none). With the maker's gains and 30 rad/s the G1's hands trail their targets by
            ~40 ms (the H1's ~50 ms) and much of the targets' speech synchrony is lost; the G1
            map's 4x and 60 rad/s bring that to ~10 ms within its limits (torque peaks ~0.55 of
            the limit, feet planted; a faster 80 rad/s reference makes the stance skate,
            ~15 mm/s). The H1 keeps its map's gains: 4x (or 2.5x) and 60 rad/s would double its
            synchrony too, but its random-clip control then put the 18 N·m shoulder-yaw and
            elbow motors at their torque limit in 1-2.3 % of steps (the speed limits are
            Unitree's URDF's: 20 rad/s there); the H1 map's ``shaper_a_max`` 50 rad/s²
            (the reference's acceleration bound, default :data:`A_MAX`) keeps them under it.
    """

    def __init__(self, robot: RobotMap, model: mujoco.MjModel | None = None, seed: int = 0,
                 control_every: int | None = None, record_every: int | None = None,
                 shaper_omega: float | None = None, upper_gain: float | None = None) -> None:
        self.robot = robot
        m = robot.load_model() if model is None else model
        self.model = m
        if control_every is None:
            control_every = max(1, int(round(0.01 / m.opt.timestep)))
        record_every = control_every if record_every is None else record_every
        self.data = mujoco.MjData(m)
        self._kin = mujoco.MjData(m)
        self.rng = np.random.default_rng(seed)
        self.n = m.nu
        self.joint_names = tuple(m.joint(m.actuator_trnid[a, 0]).name for a in range(m.nu))
        jid = np.array([m.actuator_trnid[a, 0] for a in range(m.nu)], dtype=int)
        self.qadr = m.jnt_qposadr[jid].astype(int)
        self.dadr = m.jnt_dofadr[jid].astype(int)
        self.joint_range = m.jnt_range[jid].copy()
        self.force_range = m.actuator_ctrlrange.copy()
        self.v_max = np.array([robot.lookup(robot.velocity_limit, j, 1e9)
                               for j in self.joint_names])
        self.kp = np.array([robot.lookup(robot.kp, j, 50.0) for j in self.joint_names])
        self.kd = np.array([robot.lookup(robot.kd, j, 1.0) for j in self.joint_names])
        self.idle = self.force_range[:, 1] - self.force_range[:, 0] <= 0   # unused slots
        upper_gain = robot.upper_gain if upper_gain is None else float(upper_gain)
        shaper_omega = robot.shaper_omega if shaper_omega is None else float(shaper_omega)
        a_max = np.array([robot.lookup(robot.shaper_a_max, j, A_MAX) for j in self.joint_names])
        legs_set = set(robot.leg_joints)
        upper = np.array([j not in legs_set for j in self.joint_names]) & ~self.idle
        self.kp[upper] *= upper_gain
        self.kd[upper] *= math.sqrt(upper_gain)
        self.kp[self.idle], self.kd[self.idle] = 1.0, 0.0
        # the motors as their drivers run them: PD at every physics step, clamped at ctrlrange
        m.actuator_gaintype[:] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_biastype[:] = mujoco.mjtBias.mjBIAS_AFFINE
        m.actuator_gainprm[:, 0] = self.kp
        m.actuator_biasprm[:, :3] = np.stack([np.zeros(self.n), -self.kp, -self.kd], axis=1)
        m.actuator_forcerange[:] = self.force_range
        m.actuator_forcelimited[:] = 1
        m.actuator_ctrllimited[:] = 0
        root = next(j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
        self.root_q, self.root_v = int(m.jnt_qposadr[root]), int(m.jnt_dofadr[root])
        self.pelvis = m.body(robot.pelvis_body).id
        self.mass = float(m.body_subtreemass[self.pelvis])
        self.gravity = float(-m.opt.gravity[2])
        col = {j: i for i, j in enumerate(self.joint_names)}
        self.leg_cols = [np.array([col[j] for j in robot.legs[s]], dtype=int) for s in _SIDES]
        self.leg_dofs = [self.dadr[c] for c in self.leg_cols]
        legs = np.concatenate(self.leg_cols)
        self.ub_cols = np.array([i for i in range(self.n) if i not in set(legs.tolist())
                                 and not self.idle[i]], dtype=int)
        self.foot_site = [m.site(f"{s}_foot_site").id for s in _SIDES]
        self.foot_body = [m.site_bodyid[s] for s in self.foot_site]
        self.stand = np.zeros(self.n)
        for j, v in robot.stand.items():
            self.stand[col[j]] = v
        self.shaper = TargetShaper(self.n, omega=shaper_omega,
                                   v_max=np.minimum(0.9 * self.v_max, 30.0), a_max=a_max)
        self._loop = PhysicsLoop(m, self.data, [self], control_every, record_every)
        self.control_every = self._loop.control_every
        self.record_every = self._loop.record_every
        self._stream_rec: TraceRecorder | None = None
        self._rec_sites = np.array([m.site(s).id for s in
                                    ("left_foot_site", "right_foot_site", *TRACKED_SITES)])
        floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        if floor < 0:
            raise GestureSimError(f"robot {robot.name!r}: the scene has no geom 'floor'")
        own = m.body_rootid[m.geom_bodyid] == self.pelvis
        foot_side = np.full(m.ngeom, -1)
        for side, b in enumerate(self.foot_body):
            foot_side[m.geom_bodyid == b] = side
        kind = np.full((m.ngeom, m.ngeom), 4, dtype=np.int8)
        kind[np.ix_(own, own)] = 3
        kind[floor, :] = np.where(own, np.where(foot_side >= 0, foot_side, 2), 4)
        kind[:, floor] = kind[floor, :]
        self._pair_kind = kind
        self._jp = np.zeros((3, m.nv))
        self._jr = np.zeros((3, m.nv))
        self._jcom = np.zeros((3, m.nv))
        self.q_target = self.stand.copy()
        self.qd_target = np.zeros(self.n)

    # ------------------------------------------------------------------ state
    @property
    def loop(self) -> PhysicsLoop:
        """The physics loop stepping this body."""
        return self._loop

    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        """Actuated joint positions (n,), actuator order."""
        return self.data.qpos[self.qadr].copy()

    def standing_pose(self) -> np.ndarray:
        """The map's standing pose (n,) rad."""
        return self.stand.copy()

    def reset(self, q0: np.ndarray | None = None, settle: float = 1.0) -> None:
        """Stand the robot in ``q0`` (default the standing pose), lowest foot point at z = 0,
        and let it settle for ``settle`` s tracking ``q0``; time then restarts at 0."""
        m, d = self.model, self.data
        self._loop.flush()
        mujoco.mj_resetData(m, d)
        q0 = self.place(q0)
        mujoco.mj_forward(m, d)
        self._loop.settle([q0], settle)

    def place(self, q0: np.ndarray | None = None) -> np.ndarray:
        """Pose the robot in ``q0`` (n,) with its lowest foot geom touching the floor."""
        m, d = self.model, self.data
        q0 = self.stand.copy() if q0 is None else np.asarray(q0, dtype=float).copy()
        if q0.shape != (self.n,):
            raise GestureSimError(f"q0 must have shape ({self.n},), got {q0.shape}")
        q0 = np.clip(q0, self.joint_range[:, 0], self.joint_range[:, 1])
        d.qpos[:] = m.qpos0
        d.qpos[self.qadr] = q0
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        low = np.inf
        for g in range(m.ngeom):
            if m.geom_bodyid[g] in self.foot_body and m.geom_contype[g]:
                if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
                    i = m.geom_dataid[g]
                    a = m.mesh_vertadr[i]
                    v = m.mesh_vert[a:a + m.mesh_vertnum[i]]
                    z = d.geom_xpos[g][2] + v @ d.geom_xmat[g].reshape(3, 3)[2]
                    low = min(low, float(z.min()))
                else:
                    low = min(low, float(d.geom_xpos[g][2] - m.geom_size[g][0]))
        d.qpos[self.root_q + 2] -= low - 0.0005
        d.qvel[:] = 1e-4 * self.rng.standard_normal(m.nv)
        self.shaper.reset(q0)
        self.q_target, self.qd_target = q0.copy(), np.zeros(self.n)
        return q0

    # ------------------------------------------------------------------ control
    def _balance(self) -> np.ndarray:
        """Leg feed-forward torques (n,) of the balance law (zeros elsewhere)."""
        m, d = self.model, self.data
        tau = np.zeros(self.n)
        c = d.subtree_com[self.pelvis]
        mujoco.mj_jacSubtreeCom(m, d, self._jcom, self.pelvis)
        cdot = self._jcom @ d.qvel
        feet = [d.site_xpos[s].copy() for s in self.foot_site]
        mats = [d.site_xmat[s].reshape(3, 3) for s in self.foot_site]
        s = 0.5 * (feet[0] + feet[1])
        f = self.mass * np.array([KP_COM * (s[0] - c[0]) - KD_COM * cdot[0],
                                  KP_COM * (s[1] - c[1]) - KD_COM * cdot[1], self.gravity])
        hx, hy = mats[0][0, 0] + mats[1][0, 0], mats[0][1, 0] + mats[1][1, 0]
        yaw = math.atan2(hy, hx)
        r_goal = np.array([[math.cos(yaw), -math.sin(yaw), 0.0],
                           [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
        r_p = d.xmat[self.pelvis].reshape(3, 3)
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, (r_goal @ r_p.T).reshape(-1))
        e = np.zeros(3)
        mujoco.mju_quat2Vel(e, q, 1.0)
        w = d.qvel[self.root_v + 3: self.root_v + 6]
        w_world = r_p @ w                      # the free joint's angular velocity is local
        moment = self.mass * (KP_ORI_PER_KG * e - KD_ORI_PER_KG * w_world)
        # share by where the COM lies between the feet (along the line joining them)
        axis = feet[0] - feet[1]
        axis[2] = 0.0
        L = float(np.dot(axis, axis))
        share = 0.5 if L < 1e-9 else float(np.clip(np.dot(c - feet[1], axis) / L, 0.0, 1.0))
        for k, wgt in enumerate((share, 1.0 - share)):
            mujoco.mj_jac(m, d, self._jp, self._jr, feet[k], self.foot_body[k])
            dofs = self.leg_dofs[k]
            jac = np.vstack([self._jp[:, dofs], self._jr[:, dofs]])
            tau[self.leg_cols[k]] = -jac.T @ np.concatenate([wgt * f, wgt * moment])
        return tau

    def control(self, q_target: np.ndarray, qd_target: np.ndarray) -> None:
        """One control update: shape the reference and set the motors' (q*, τ_ff)."""
        d = self.data
        self.q_target, self.qd_target = q_target, qd_target
        dt = self.model.opt.timestep * self.control_every
        r, v, _ = self.shaper.step(q_target, qd_target, dt)
        tau = self._balance()
        ub = self.ub_cols
        tau[ub] = d.qfrc_bias[self.dadr[ub]]
        ctrl = r + (self.kd * v + tau) / self.kp
        ctrl[self.idle] = 0.0
        d.ctrl[:] = ctrl

    # ------------------------------------------------------------------ streaming
    def begin_trace(self, record: bool = True, expected_s: float = 60.0) -> None:
        """Start a streamed run at the current state (see :meth:`advance_to`)."""
        rows = int(expected_s / (self.model.opt.timestep * self.record_every)) + 1
        self._stream_rec = self._new_recorder(rows) if record else None
        self._loop.begin(record)
        if self._stream_rec is not None:
            self._record(self._stream_rec, self.q_target)

    def advance_to(self, t_end: float, sample: Sample) -> None:
        """Step until stream time ``t_end`` (s) tracking ``sample(t) -> (q, qd)`` (each (n,))."""
        self._loop.run_until(t_end, [sample])

    def export_state(self) -> dict:
        """What stepping changes besides the ``MjData`` (for a background process)."""
        sh = self.shaper
        return {"rec": self._stream_rec, "shaper": (sh.r, sh.v, sh.a),
                "targets": (self.q_target, self.qd_target)}

    def adopt_state(self, state: dict) -> None:
        """Take :meth:`export_state`'s state as this body's own."""
        self._stream_rec = state["rec"]
        self.shaper.r, self.shaper.v, self.shaper.a = (np.array(a) for a in state["shaper"])
        self.q_target, self.qd_target = state["targets"]

    def record_row(self, q_target: np.ndarray) -> None:
        """Append one row with target q* (n,) to the streamed trace (when recording)."""
        if self._stream_rec is not None:
            self._record(self._stream_rec, q_target)

    def trace(self) -> SimTrace:
        """The :class:`SimTrace` of the streamed run so far (robot joints, actuator order)."""
        if self._stream_rec is None:
            raise GestureSimError("no recorded stream: call begin_trace(record=True) first")
        self._loop.flush()
        return self._finish(self._stream_rec)

    def run(self, targets: np.ndarray, rate: float, seconds: float | None = None) -> SimTrace:
        """Track a whole target array (T, n) at ``rate`` Hz from the current state."""
        from gesture_sim.sim.targets import TargetStream

        stream = TargetStream(np.asarray(targets, dtype=float), rate=rate)
        self.begin_trace(expected_s=stream.duration + 1.0)
        self.advance_to(stream.duration if seconds is None else seconds, stream.sample)
        return self.trace()

    def _new_recorder(self, rows: int) -> TraceRecorder:
        m = self.model
        return TraceRecorder(rows, self.n, m.nq, m.nv, m.nsite,
                             n_target_sites=len(self._rec_sites))

    def _record(self, rec: TraceRecorder, q_target: np.ndarray) -> None:
        d = self.data
        if rec.i >= rec.rows:
            rec.grow()
        i, b = rec.i, rec.buf
        b["time"][i] = d.time
        b["qpos"][i] = d.qpos
        b["qvel"][i] = d.qvel
        b["act_force"][i] = d.actuator_force
        b["q_target"][i] = q_target
        b["q_ref"][i] = self.shaper.r
        b["sites"][i] = d.site_xpos
        b["com"][i] = d.subtree_com[self.pelvis]
        if d.ncon:
            con = d.contact
            rec.add_contacts(con.geom, con.dist, con.pos)
        rec.close_row()

    def _finish(self, rec: TraceRecorder) -> SimTrace:
        m, kin = self.model, self._kin
        b = rec.buf
        for i in range(rec.derived, rec.i):
            kin.qpos[:] = b["qpos"][i]
            kin.qpos[self.qadr] = b["q_target"][i]
            mujoco.mj_kinematics(m, kin)
            b["target_sites"][i] = kin.site_xpos[self._rec_sites]
        rec.derived = rec.i
        a = rec.trimmed()
        qpos, qvel, sites = a["qpos"], a["qvel"], a["sites"][:, self._rec_sites]
        a.update(rec.contact_summary(self._pair_kind))
        groups = {"legs": self.robot.leg_joints, "spine": self.robot.spine,
                  "arms": self.robot.arm_joints}
        return SimTrace(
            time=a["time"], q=qpos[:, self.qadr], qd=qvel[:, self.dadr],
            q_target=a["q_target"], q_ref=a["q_ref"], act_force=a["act_force"], com=a["com"],
            pelvis_height=qpos[:, self.root_q + 2].copy(), foot_pos=sites[:, :2],
            foot_contact=a["foot_contact"], support_points=a["support_points"],
            ground_penetration=a["ground_penetration"],
            self_contact_count=a["self_contact_count"], self_penetration=a["self_penetration"],
            sim_sites=sites[:, 2:], target_sites=a["target_sites"][:, 2:],
            assist=np.zeros((len(qpos), 6)), disturbance=a["disturbance"], qpos=qpos,
            qvel=qvel, joint_names=self.joint_names, joint_range=self.joint_range.copy(),
            force_range=self.force_range.copy(), slide=np.zeros(self.n, dtype=bool),
            joint_groups=groups, site_names=TRACKED_SITES,
            standing_height=self.standing_height, timestep=m.opt.timestep,
            record_every=self.record_every)

    @property
    def standing_height(self) -> float:
        """Pelvis height of the settled standing pose (m), as placed by :meth:`place`."""
        if not hasattr(self, "_standing_height"):
            kin = self._kin
            kin.qpos[:] = self.model.qpos0
            kin.qpos[self.qadr] = self.stand
            mujoco.mj_kinematics(self.model, kin)
            low = min(float(kin.site_xpos[s][2]) for s in self.foot_site)
            self._standing_height = float(kin.qpos[self.root_q + 2] - low)
        return self._standing_height
