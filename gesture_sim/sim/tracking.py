"""PD + balance tracking of joint targets by the free-standing MuJoCo humanoid.

Control law (per control update, every ``control_every`` physics steps), for every actuated
joint j with position-actuator gains kp_j, kv_j (``humanoid.xml``)::

    force_j = clamp(kp_j (ctrl_j - q_j) - kv_j qd_j, forcerange_j)   (MuJoCo, every step)
    ctrl_j  = r_j + (kv_j v_j + tau_ff_j) / kp_j                     (here)
    => force_j = kp_j (r_j - q_j) + kv_j (v_j - qd_j) + tau_ff_j     (unless clamped)

where (r, v, a) is the shaped reference (:class:`~gesture_sim.sim.targets.TargetShaper`) of the
target stream (q*, qd*). The D part is the actuator's ``kv``, which ``implicitfast`` integrates
implicitly (MuJoCo's analogue of stable PD). A position actuator's ``kv`` alone damps towards
zero velocity (ENGINEERING_NOTES §3.4), so the velocity reference enters as the feed-forward
``kv v`` folded into the position target. The whole controller torque, P + D + feed-forward,
is therefore one actuator force, bounded by ``forcerange`` and recorded as ``actuator_force``
(saturation is measurable). Joints also have a small passive damping (2 % of kv).

Feed-forward ``tau_ff``:
  * upper body (spine, neck, head, face, arms): inverse dynamics of the reference,
    ``qfrc_bias + M a`` restricted to those joints (gravity, Coriolis and inertia of the
    subtree each joint carries; the root acceleration is taken as zero);
  * legs: the balance controller. A desired ground-reaction wrench on the body,
    ``F = m (g e_z + kp_c (s - c) - kd_c ċ)`` (horizontal COM regulation towards the support
    centre s, vertical weight support) and a moment ``M = kp_o e_pelvis - kd_o ω_pelvis``
    (pelvis upright and square to the feet: the heading is the feet's mean yaw, so a body that
    has turned on its feet is never twisted back against the floor), is split between the
    feet by where the COM lies between them (``F_i = w_i F``); the moment the soles must add
    about the COM, ``M - Σ_j (p_j - c) × F_j``, is shared with the same weights, clipped so
    that each foot's centre of pressure stays inside its sole, and mapped to hip/knee/ankle
    torques by ``tau = -J_iᵀ [F_i; M_i]`` (the torques that make the stance leg push on the
    ground with that wrench). The yaw part of the moment sent through each leg is bounded by
    ``yaw_moment_arm`` times that foot's normal force (a torsional-friction budget: the
    controller never asks a sole for more twist than friction
    holds). This is an ankle strategy with COM position/velocity feedback, a hip strategy
    through the pelvis moment, and stance-leg gravity compensation in one Jacobian-transpose
    (virtual model) law.

    The support centre is ``s = m_f + H o`` (m): ``m_f`` the mid-point of the two sole centres,
    ``H`` the heading (the feet's mean yaw), ``o`` = ``com_offset`` (m, heading frame). With
    ``BalanceGains.follow_target`` (the pipeline's ``legs="clip"``, whose leg targets shift the
    weight over a planted stance) the COM target follows the *reference pose's* own COM:
    ``s = m_f + H (o + Δ)``, ``Δ = clip((c_r - m_r) - (c_0 - m_0), ±target_com_limit)`` (m,
    heading frame), where ``c_r``, ``m_r`` are the COM and sole mid-point of the shaped
    reference pose r (forward kinematics, pelvis upright and square to its feet, expressed in
    its feet's heading frame) and ``c_0``, ``m_0`` those of the standing pose (q = 0). A weight
    shift of the reference thus moves the COM target with it, instead of the COM feedback
    pulling the body back to the middle against the legs' PD; the bound keeps the target well
    inside the support polygon (the soles reach ±0.135 m sideways and -0.10 … +0.17 m fore-aft
    of the sole centres). Off (Δ = 0), the law is the one above, unchanged.

No force acts on the free root: nothing holds, welds or pushes the body. ``SimTrace.assist``
is therefore zero; a test disturbance (a push) is applied only through :meth:`HumanoidSim.run`'s
``pushes`` and recorded separately as ``disturbance``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import TargetShaper, TargetStream
from gesture_sim.sim.trace import TRACKED_SITES, SimTrace, TraceRecorder
from gesture_sim.sim.world import PhysicsLoop, Sample

TargetsFn = Callable[[float], "tuple[np.ndarray, np.ndarray] | np.ndarray"]


def _span(idx) -> slice | np.ndarray:
    """``idx`` (ascending int indices) as a slice when it is a contiguous run, else as an array:
    a slice reads and writes the same elements as the index array, without numpy's fancy
    indexing (a copy and an index check per call) at the control rate."""
    a = np.asarray(idx, dtype=int).reshape(-1)
    if len(a) and np.array_equal(a, np.arange(a[0], a[0] + len(a))):
        return slice(int(a[0]), int(a[0]) + len(a))
    return a


@dataclass(frozen=True)
class BalanceGains:
    """Gains of the balance controller.

    Attributes:
        kp_com: COM position gain (1/s²): horizontal force per kg per metre of COM error.
        kd_com: COM velocity gain (1/s).
        kp_ori: pelvis orientation gain (N·m/rad).
        kd_ori: pelvis angular-velocity gain (N·m·s/rad).
        com_offset: support-centre offset from the mid-point of the sole centres, (x, y) in the
            heading frame (m).
        cop_margin: fraction of the sole half-length/width the centre of pressure may use.
        yaw_moment_arm: bound of the pelvis yaw moment sent through each stance leg, as a
            moment arm times that foot's normal force (m): a torsional-friction budget, so the
            heading controller never asks the floor for more twist than a sole can hold.
        follow_target: shift the support centre by the reference pose's own COM offset Δ
            (module docstring), so that the COM target follows a weight shift of the target.
        target_com_limit: bounds (|Δx| fore-aft, |Δy| lateral) of that shift (m, heading frame).
        hip_guard: the hip strategy's band (back, front) of the capture point ξ = c + ċ/ω
            (ω = √(g / 0.95 m)) fore-aft of the sole mid-point (m, heading frame): outside
            it the pelvis orientation target pitches towards the danger (forward when ξ
            nears the heels), by ``hip_gain`` rad per metre beyond the band, at most
            ``hip_max`` rad; ``None`` switches it off. The feet's torque cannot hold a
            centre of pressure past the heel: once the capture point gets there the soles roll
            onto their heels and only the trunk can bring the COM back (docs/history.md,
            "hip strategy").
        hip_gain, hip_max: as above (rad/m, rad).
    """

    kp_com: float = 40.0
    kd_com: float = 12.0
    kp_ori: float = 600.0
    kd_ori: float = 60.0
    com_offset: tuple[float, float] = (-0.03, 0.0)
    cop_margin: float = 0.85
    yaw_moment_arm: float = 0.03
    follow_target: bool = False
    target_com_limit: tuple[float, float] = (0.03, 0.05)
    hip_guard: tuple[float, float] | None = (-0.05, 0.12)
    hip_gain: float = 5.0
    hip_max: float = 0.3


@dataclass(frozen=True)
class Push:
    """A test disturbance: a constant world-frame force on a body for a while.

    Attributes:
        t_start: start time (s); duration: how long (s); force: (3,) newtons; body: body name.
    """

    t_start: float
    duration: float
    force: tuple[float, float, float]
    body: str = "chest"

    @property
    def impulse(self) -> float:
        """Magnitude of the impulse (N·s)."""
        return float(np.linalg.norm(self.force) * self.duration)


#: Sole extent around each ``*_foot_site`` in the foot frame (m): x back, x front, y half-width.
_SOLE_X = (-0.10, 0.17)
_SOLE_Y = 0.045
#: 1/ω of the capture point, ω = √(g / l) with l = 0.95 m, the standing COM height (s).
_INV_OMEGA = math.sqrt(0.95 / 9.81)

#: Velocity (rad/s) and acceleration (rad/s²) bounds of the reference per joint group. The arm
#: bounds (shoulder 60, elbow/forearm 90 rad/s², below the mocap p99 of 142 / 134) keep the
#: reaction of a sudden two-arm switch within what two soles can hold by friction: at 90 / 120
#: a wide sweep unloaded one foot and spun the body several degrees on the other.
_SHAPER_LIMITS = {
    "spine": (3.0, 40.0), "neck_head": (6.0, 80.0), "face": (0.5, 20.0),
    "clavicle": (2.0, 30.0), "shoulder": (6.0, 60.0), "elbow_forearm": (8.0, 90.0),
    "wrist": (10.0, 150.0), "hip": (3.0, 40.0), "knee": (3.0, 40.0), "ankle_toe": (3.0, 40.0),
}

#: The jaw's own bounds (rad/s, rad/s²) within the ``face`` group: a talking jaw opens and closes
#: ≈ 0.2 rad within a syllable (≈ 3 rad/s); at the face group's 0.5 rad/s it lagged the speech
#: envelope by ≈ 50 ms more than the causal frames do (``tools/jaw_lag.py``).
_JAW_LIMITS = (4.0, 80.0)


#: Bounds (rad/s, rad/s²) of the reference while a joint's stream is smooth (real motion, no
#: jump being realised; see :class:`TargetShaper`): about the 99.9th percentile of real motion
#: capture (``tests/data/physics/mocap_accel_reference.json``: shoulder 390, elbow/forearm
#: 400, wrist 343, clavicle 54, spine 54, neck/head 103 rad/s²), so the reference reproduces
#: real clips instead of lagging behind them. Legs and face keep :data:`_SHAPER_LIMITS`.
_SHAPER_FAST = {
    "spine": (4.0, 54.0), "neck_head": (8.0, 100.0), "clavicle": (10.0, 300.0),
    "shoulder": (14.0, 390.0), "elbow_forearm": (20.0, 400.0), "wrist": (20.0, 340.0),
}


class HumanoidSim:
    """The free-standing humanoid tracking joint targets with PD + balance control.

    Typical use::

        sim = HumanoidSim()
        sim.reset()                                   # standing, settled, time 0
        trace = sim.run(TargetStream(q, rate=30.0))   # q: (T, n_act)

    Args:
        model: a compiled scene (default :func:`gesture_sim.sim.humanoid.load_model`).
        seed: seeds the (tiny) initial-state noise, so runs are reproducible.
        control_every: physics steps per control update (default: 100 Hz, i.e. 5 at the
            model's 500 Hz; the P term and joint damping still act at every physics step inside
            MuJoCo).
        record_every: physics steps per :class:`SimTrace` row (default ``control_every``), a
            multiple of ``control_every`` (checked here, once).
        inertia_feedforward: add ``M a`` of the reference to the upper-body feed-forward.
        balance: balance gains; ``shaper_omega``: reference-model bandwidth (rad/s).
        fast_shaper: shape smooth streams with the wide real-motion bounds
            (:data:`_SHAPER_FAST`) and only jumps with the tight :data:`_SHAPER_LIMITS`.
        yaw_reaction_limit: bound (N·m) of the yaw moment about the vertical that the upper
            body's reference acceleration may ask of the free root (``M[root, ub] a_ub``, the
            inverse-dynamics reaction the soles must hold by friction); a larger ask scales the
            upper body's reference acceleration down for that update. None: no bound.
        timestep: physics step (s), set on ``model`` (default: the model's 0.002 s). 1/300 s
            (3 steps per 100 Hz update) runs about 1.5x faster, with feet that jitter more
            (docs/history.md, "physics step").
        prefix: name prefix of this body's joints, bodies, sites, geoms and actuators in a scene
            of several humanoids (:mod:`gesture_sim.sim.scene`, e.g. ``"b/"``); "" for the
            single-person scene.
        data: the ``MjData`` to act on, shared by every body of a multi-body scene (default: a
            new one); such bodies are stepped together by :class:`~gesture_sim.sim.scene.
            SceneSim`, which calls :meth:`place`, :meth:`control` and :meth:`record_row`.

    Every run steps the physics through one :class:`~gesture_sim.sim.world.PhysicsLoop`.
    """

    def __init__(self, model: mujoco.MjModel | None = None, seed: int = 0,
                 control_every: int | None = None, record_every: int | None = None,
                 inertia_feedforward: bool = True, balance: BalanceGains | None = None,
                 shaper_omega: float = 30.0, fast_shaper: bool = False,
                 timestep: float | None = None, yaw_reaction_limit: float | None = None,
                 prefix: str = "", data: mujoco.MjData | None = None) -> None:
        self.model = hm.load_model() if model is None else model
        if timestep is not None:
            if not 0.0 < timestep <= 0.01:
                raise GestureSimError(f"timestep must be in (0, 0.01] s, got {timestep}")
            self.model.opt.timestep = float(timestep)
        if control_every is None:                # 100 Hz control updates
            control_every = max(1, int(round(0.01 / self.model.opt.timestep)))
        if record_every is None:
            record_every = control_every
        self.data = mujoco.MjData(self.model) if data is None else data
        self._kin = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(seed)
        self._loop = PhysicsLoop(self.model, self.data, [self], control_every, record_every)
        self.control_every = self._loop.control_every
        self.record_every = self._loop.record_every
        self._stream_rec: TraceRecorder | None = None
        self.inertia_feedforward = inertia_feedforward
        self.yaw_reaction_limit = None if yaw_reaction_limit is None else float(yaw_reaction_limit)
        self.balance = balance or BalanceGains()
        m = self.model
        self.prefix = prefix
        joints = [prefix + j for j in hm.ACTUATED_JOINTS]
        self.n = len(joints)
        try:
            root = m.joint(prefix + "root").id
        except KeyError as exc:
            raise GestureSimError(f"the scene has no humanoid with prefix {prefix!r}") from exc
        # this body's free root and its contiguous qpos / qvel spans (its trace keeps only these,
        # in the single-person layout: root (7 / 6) then the actuated joints)
        self.root_q, self.root_v = int(m.jnt_qposadr[root]), int(m.jnt_dofadr[root])
        self.qadr = hm.qpos_addresses(m, joints)
        self.dadr = hm.qvel_addresses(m, joints)
        self.qspan = slice(self.root_q, self.root_q + 7 + self.n)
        self.vspan = slice(self.root_v, self.root_v + 6 + self.n)
        if (int(self.qadr.max()) >= self.qspan.stop or int(self.qadr.min()) < self.root_q
                or int(self.dadr.max()) >= self.vspan.stop):
            raise GestureSimError(f"humanoid {prefix!r}: joints are not contiguous after the root")
        self._qadr_local = self.qadr - self.root_q
        self._dadr_local = self.dadr - self.root_v
        self._root_w = slice(self.root_v + 3, self.root_v + 6)    # the root's angular dofs
        self.act = hm.actuator_ids(m, joints)
        self.kp = m.actuator_gainprm[self.act, 0].copy()
        self.kd = -m.actuator_biasprm[self.act, 2].copy()
        self.force_range = m.actuator_forcerange[self.act].copy()
        self.joint_range = m.jnt_range[hm.joint_ids(m, joints)].copy()
        self.slide = np.array([j in hm.SLIDE_JOINTS for j in hm.ACTUATED_JOINTS])
        self.leg_idx = hm.actuated_index(hm.LEG_JOINTS)
        self.ub_idx = hm.actuated_index(hm.UPPER_BODY_JOINTS)
        self.ub_dofs = self.dadr[self.ub_idx]
        self.side_leg_idx = [hm.actuated_index([j for j in hm.LEG_JOINTS if j.startswith(s)])
                             for s in ("left", "right")]
        self.side_ankle_idx = [hm.actuated_index(
            [j for j in hm.LEG_JOINTS if j.startswith(s) and ("ankle" in j or "toe" in j)])
            for s in ("left", "right")]
        self.side_hipknee_idx = [hm.actuated_index(
            [j for j in hm.LEG_JOINTS if j.startswith(s) and ("hip" in j or "knee" in j)])
            for s in ("left", "right")]
        self.pelvis = m.body(prefix + "pelvis").id
        self.mass = float(m.body_subtreemass[self.pelvis])
        self.gravity = float(-m.opt.gravity[2])
        self.foot_site = [m.site(prefix + s).id for s in hm.FOOT_SITES]
        self.foot_body = [m.site_bodyid[s] for s in self.foot_site]
        self.track_site = np.array([m.site(prefix + s).id for s in TRACKED_SITES])
        floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        self.floor = int(floor)
        self.foot_geom_side = np.full(m.ngeom, -1)
        for side, names in enumerate(hm.FOOT_GEOMS.values()):
            for g in names:
                self.foot_geom_side[m.geom(prefix + g).id] = side
        self.shaper = TargetShaper(self.n, omega=shaper_omega)
        for group, (vmax, amax) in _SHAPER_LIMITS.items():
            idx = hm.actuated_index(hm.JOINT_GROUPS[group])
            self.shaper.v_max[idx] = vmax
            self.shaper.a_max[idx] = amax
        jaw = hm.actuated_index(["jaw_open"])
        self.shaper.v_max[jaw], self.shaper.a_max[jaw] = _JAW_LIMITS
        if fast_shaper:
            self.shaper.v_fast = self.shaper.v_max.copy()
            self.shaper.a_fast = self.shaper.a_max.copy()
            for group, (vmax, amax) in _SHAPER_FAST.items():
                idx = hm.actuated_index(hm.JOINT_GROUPS[group])
                self.shaper.v_fast[idx] = vmax
                self.shaper.a_fast[idx] = amax
        self._jac6 = np.zeros((6, m.nv))
        self._tau = np.zeros(self.n)
        self._force = np.zeros(3)
        self._wrench = np.zeros(6)
        self._com_offset = np.asarray(self.balance.com_offset, dtype=float)
        self.side_ankle_dofs = [self.dadr[i] for i in self.side_ankle_idx]
        self.side_hipknee_dofs = [self.dadr[i] for i in self.side_hipknee_idx]
        self._jcom = np.zeros((3, m.nv))
        self._jcom_xy = self._jcom[:2]
        self._vec = np.zeros(m.nv)
        self._mv = np.zeros(m.nv)
        self._wrench2 = np.zeros((2, 6))
        self._inv_kp = 1.0 / self.kp
        self._com_offset_xy = tuple(float(x) for x in self.balance.com_offset)
        self._hc, self._hs = 1.0, 0.0
        #: control steps at which the hip strategy acted (``BalanceGains.hip_guard``)
        self.hip_strategy_steps = 0
        # recorded sites: the two sole centres, then the tracked sites
        self._rec_sites = np.array([m.site(prefix + s).id
                                    for s in (*hm.FOOT_SITES, *TRACKED_SITES)])
        self._support_sites = [m.site(prefix + s).id
                               for s in (*hm.FOOT_SITES, *hm.HEEL_SITES, *hm.TOE_SITES)]
        # contact kind per geom pair: 0 / 1 left / right sole on the floor, 2 another geom of
        # this body on the floor, 3 this body on itself (self contact), 4 not this body's
        own = m.body_rootid[m.geom_bodyid] == self.pelvis                     # (ngeom,)
        side = self.foot_geom_side
        kind = np.full((m.ngeom, m.ngeom), 4, dtype=np.int8)
        kind[np.ix_(own, own)] = 3
        kind[self.floor, :] = np.where(own, np.where(side >= 0, side, 2), 4)
        kind[:, self.floor] = kind[self.floor, :]
        self._pair_kind = kind
        self._ones_body = np.ones(m.nbody)
        self._wrench6 = np.zeros(6)
        self._target_com: _PoseCom | None = None
        if self.balance.follow_target:
            self._target_com = _PoseCom(m, prefix, self.qspan, self.qadr, self.foot_site)
        self._cache_views()
        self.q_target = np.zeros(self.n)
        self.qd_target = np.zeros(self.n)

    def _cache_views(self) -> None:
        """Keep numpy views of the ``MjData`` arrays used at the control rate (each attribute
        access of the bindings builds a new array object; the buffers themselves never move),
        and the index sets used there as slices where they are contiguous (:func:`_span`)."""
        d = self.data
        self._qvel, self._ctrl, self._qfrc_bias = d.qvel, d.ctrl, d.qfrc_bias
        self._subtree_com, self._xmat = d.subtree_com, d.xmat
        self._site_xpos, self._site_xmat = d.site_xpos, d.site_xmat
        self._qpos, self._act_force, self._xfrc = d.qpos, d.actuator_force, d.xfrc_applied
        # single rows of MjData (views): the pelvis COM and frame, the soles' frames
        self._pelvis_com = d.subtree_com[self.pelvis]
        self._pelvis_xmat = d.xmat[self.pelvis]
        self._foot_xpos = [d.site_xpos[s] for s in self.foot_site]
        self._foot_xmat = [d.site_xmat[s] for s in self.foot_site]
        self._act_sl = _span(self.act)
        self._ub_sl, self._ub_dofs_sl = _span(self.ub_idx), _span(self.ub_dofs)
        self._side_ankle_sl = [_span(i) for i in self.side_ankle_idx]
        self._side_ankle_dofs_sl = [_span(i) for i in self.side_ankle_dofs]
        self._side_hipknee_sl = [_span(i) for i in self.side_hipknee_idx]
        self._side_hipknee_dofs_sl = [_span(i) for i in self.side_hipknee_dofs]
        self._g = np.zeros((2, self.model.nv))
        self._kdv = np.zeros(self.n)

    @property
    def loop(self) -> PhysicsLoop:
        """The :class:`~gesture_sim.sim.world.PhysicsLoop` that steps this body's streamed runs
        (:meth:`advance_to`)."""
        return self._loop

    @property
    def heading(self) -> np.ndarray:
        """The balance controller's heading frame (a yaw rotation), shape (3, 3)."""
        c, s = self._hc, self._hs
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    # ----------------------------------------------------------------------------- state
    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        """Actuated joint positions, shape (n_act,)."""
        return self.data.qpos[self.qadr].copy()

    def standing_pose(self) -> np.ndarray:
        """The default standing targets (all zero: upright, arms at the sides), (n_act,)."""
        return np.zeros(self.n)

    def reset(self, q0: np.ndarray | None = None, settle: float = 0.6) -> None:
        """Stand the body up in pose ``q0`` (default :meth:`standing_pose`), soles on the floor.

        The root is placed so that the lowest sole point touches z = 0, then the body settles
        for ``settle`` seconds tracking ``q0``; time then restarts at 0.
        """
        m, d = self.model, self.data
        self._loop.flush()                  # deferred physics first (world.PhysicsLoop.defer_s)
        mujoco.mj_resetData(m, d)
        q0 = self.place(q0)
        mujoco.mj_forward(m, d)
        self._loop.settle([q0], settle)

    def place(self, q0: np.ndarray | None = None) -> np.ndarray:
        """Pose this body in ``q0`` (n_act,) where the model places its root, soles at z = 0.

        Writes only this body's qpos / qvel span (with tiny seeded velocity noise) and resets
        its reference and heading; nothing is stepped. Returns ``q0`` clipped to the ranges.
        """
        m, d = self.model, self.data
        self._loop.flush()
        q0 = self.standing_pose() if q0 is None else np.asarray(q0, dtype=float)
        if q0.shape != (self.n,):
            raise GestureSimError(f"q0 must have shape ({self.n},), got {q0.shape}")
        q0 = np.clip(q0, self.joint_range[:, 0], self.joint_range[:, 1])
        d.qpos[self.qspan] = m.qpos0[self.qspan]
        d.qpos[self.root_q + 2] = hm.ROOT_HEIGHT
        d.qpos[self.qadr] = q0
        mujoco.mj_kinematics(m, d)
        lowest = min(float(d.site_xpos[s][2]) for s in self._support_sites)
        d.qpos[self.root_q + 2] -= lowest - 0.0005
        d.qvel[self.vspan] = 1e-4 * self.rng.standard_normal(6 + self.n)
        self._hc, self._hs = 1.0, 0.0
        self.shaper.reset(q0)
        self.q_target, self.qd_target = q0.copy(), np.zeros(self.n)
        return q0

    # ----------------------------------------------------------------------------- control
    def _balance_torques(self) -> np.ndarray:
        """Leg feed-forward torques of the balance controller, shape (n_act,) (zeros elsewhere).

        Works on preallocated buffers and cached views of ``MjData`` with scalar arithmetic
        for the 3-vectors (it runs at the control rate, where numpy's per-call overhead on
        3-element arrays would dominate): two MuJoCo calls (the feet's Jacobians) and one
        (2, 6) x (6, nv) product per foot.
        """
        m, d, b = self.model, self.data, self.balance
        tau = self._tau
        tau.fill(0.0)
        cx, cy, cz = self._pelvis_com.tolist()
        mujoco.mj_jacSubtreeCom(m, d, self._jcom, self.pelvis)
        vx, vy = (self._jcom_xy @ self._qvel).tolist()
        f0x, f0y, f0z = self._foot_xpos[0].tolist()
        f1x, f1y, f1z = self._foot_xpos[1].tolist()
        fm = (self._foot_xmat[0].tolist(), self._foot_xmat[1].tolist())  # row-major rotations
        # heading: the mean yaw of the two feet (the pelvis is kept square to the stance, so a
        # body that has turned on its feet is not twisted back against the floor)
        hx, hy = fm[0][0] + fm[1][0], fm[0][3] + fm[1][3]
        norm = math.hypot(hx, hy)
        if norm > 1e-9:
            self._hc, self._hs = hx / norm, hy / norm
        hc, hs = self._hc, self._hs
        ox, oy = self._com_offset_xy
        if self._target_com is not None:
            lx, ly = b.target_com_limit
            dx, dy = self._target_com.offset(self.shaper.r)
            ox += min(max(dx, -lx), lx)
            oy += min(max(dy, -ly), ly)
        sx = 0.5 * (f0x + f1x) + hc * ox - hs * oy
        sy = 0.5 * (f0y + f1y) + hs * ox + hc * oy
        mass = self.mass
        fx = mass * (b.kp_com * (sx - cx) - b.kd_com * vx)
        fy = mass * (b.kp_com * (sy - cy) - b.kd_com * vy)
        fz = mass * self.gravity
        # pelvis orientation error (rotation vector, world frame) and angular velocity:
        # p = rot @ heading^T, err = vee(p - p^T) / 2 with heading a yaw rotation (hc, hs)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self._pelvis_xmat.tolist()
        p01 = r00 * hs + r01 * hc
        p02 = r02
        p10 = r10 * hc - r11 * hs
        p12 = r12
        p20 = r20 * hc - r21 * hs
        p21 = r20 * hs + r21 * hc
        w0, w1, w2 = self._qvel[self._root_w].tolist()            # local angular velocity
        kpo, kdo = b.kp_ori, b.kd_ori
        mx = kpo * 0.5 * (p12 - p21) - kdo * (r00 * w0 + r01 * w1 + r02 * w2)
        my = kpo * 0.5 * (p20 - p02) - kdo * (r10 * w0 + r11 * w1 + r12 * w2)
        mz = kpo * 0.5 * (p01 - p10) - kdo * (r20 * w0 + r21 * w1 + r22 * w2)
        guard = b.hip_guard
        if guard is not None:
            # hip strategy: the capture point near the heels (toes) pitches the pelvis, and the
            # trunk it carries, forward (back), about the heading frame's lateral axis
            xi = (hc * (cx - 0.5 * (f0x + f1x) + vx * _INV_OMEGA)
                  + hs * (cy - 0.5 * (f0y + f1y) + vy * _INV_OMEGA))
            bias = 0.0
            if xi < guard[0]:
                bias = min(b.hip_gain * (guard[0] - xi), b.hip_max)
            elif xi > guard[1]:
                bias = -min(b.hip_gain * (xi - guard[1]), b.hip_max)
            if bias:
                self.hip_strategy_steps += 1
                mx -= kpo * bias * hs
                my += kpo * bias * hc
        # weight split along the line between the feet
        ax, ay = f0x - f1x, f0y - f1y
        s = ((cx - sx) * ax + (cy - sy) * ay) / max(ax * ax + ay * ay, 1e-9)
        weights = (min(max(0.5 + s, 0.0), 1.0), min(max(0.5 - s, 0.0), 1.0))
        # the moment the soles must add about the COM, once each foot's share of the force acts
        # at its sole centre, is shared like the force (the feet's lever arms about the COM
        # cancel between them when the weights put the COM between the feet, so the soles are
        # not each asked to roll against the other): rem = M - sum_i (p_i - c) x (w_i F)
        rx, ry, rz = mx, my, mz
        for w, (px, py, pz) in zip(weights, ((f0x, f0y, f0z), (f1x, f1y, f1z)), strict=True):
            dx, dy, dz = px - cx, py - cy, pz - cz
            rx -= w * (dy * fz - dz * fy)
            ry -= w * (dz * fx - dx * fz)
            rz -= w * (dx * fy - dy * fx)
        jac, wr, g = self._jac6, self._wrench2, self._g
        margin, yaw_arm = b.cop_margin, b.yaw_moment_arm
        for side in (0, 1):
            w = weights[side]
            if w <= 0.0:
                continue
            a00, a01, a02, a10, a11, a12, a20, a21, a22 = fm[side]
            fix, fiy, fiz = w * fx, w * fy, w * fz
            mix, miy, miz = w * rx, w * ry, w * rz
            # keep the centre of pressure inside the sole (foot frame)
            l0 = a00 * mix + a10 * miy + a20 * miz
            l1 = a01 * mix + a11 * miy + a21 * miz
            l2 = a02 * mix + a12 * miy + a22 * miz
            lim = margin * max(a02 * fix + a12 * fiy + a22 * fiz, 0.0)
            l0 = min(max(l0, -lim * _SOLE_Y), lim * _SOLE_Y)
            l1 = min(max(l1, -lim * _SOLE_X[1]), -lim * _SOLE_X[0])
            mujoco.mj_jacSite(m, d, jac[:3], jac[3:], self.foot_site[side])
            # row 0, ankle strategy: the whole wrench at the ankle (and toe) joints; row 1,
            # hips and knees: weight support and the pelvis-orientation moment (hip strategy),
            # the yaw part bounded by what the sole's friction can hold about the vertical
            ymax = yaw_arm * max(fiz, 0.0)
            wr[0] = (fix, fiy, fiz, a00 * l0 + a01 * l1 + a02 * l2,
                     a10 * l0 + a11 * l1 + a12 * l2, a20 * l0 + a21 * l1 + a22 * l2)
            wr[1] = (0.0, 0.0, fiz, w * mx, w * my, min(max(w * mz, -ymax), ymax))
            np.matmul(wr, jac, out=g)                             # (2, nv)
            tau[self._side_ankle_sl[side]] = -g[0, self._side_ankle_dofs_sl[side]]
            tau[self._side_hipknee_sl[side]] = -g[1, self._side_hipknee_dofs_sl[side]]
        return tau

    def control(self, q_target: np.ndarray, qd_target: np.ndarray) -> None:
        """Set this body's ``data.ctrl`` for the next ``control_every`` physics steps."""
        self.q_target, self.qd_target = q_target, qd_target
        self._control(q_target, qd_target)

    def _control(self, q_target: np.ndarray, qd_target: np.ndarray) -> None:
        """Set ``data.ctrl`` for the next ``control_every`` physics steps."""
        m, d = self.model, self.data
        dt = m.opt.timestep * self.control_every
        limit = self.yaw_reaction_limit
        if limit is not None:
            r0, v0 = self.shaper.r.copy(), self.shaper.v.copy()
        r, v, a = self.shaper.step(q_target, qd_target, dt)
        tau = self._balance_torques()
        ub, ub_dofs = self._ub_sl, self._ub_dofs_sl
        tau[ub] = self._qfrc_bias[ub_dofs]
        if self.inertia_feedforward or limit is not None:
            self._vec[ub_dofs] = a[ub]
            mujoco.mj_mulM(m, d, self._mv, self._vec)
            if limit is not None:
                # the yaw moment the upper body's reference acceleration asks of the free root
                # (M[root, ub] a_ub, pelvis frame -> world z): scaled down to what the soles hold
                yaw = float(self._xmat[self.pelvis, 6:9] @ self._mv[self._root_w])
                if abs(yaw) > limit:
                    k = limit / abs(yaw)
                    a[ub] *= k
                    v[ub] = v0[ub] + a[ub] * dt
                    r[ub] = r0[ub] + v[ub] * dt
                    self._mv *= k
            if self.inertia_feedforward:
                tau[ub] += self._mv[ub_dofs]
        tau += np.multiply(self.kd, v, out=self._kdv)
        tau *= self._inv_kp
        tau += r
        self._ctrl[self._act_sl] = tau

    def step(self, q_target: np.ndarray, qd_target: np.ndarray | None = None,
             n_substeps: int = 1) -> None:
        """Hold targets (q*, qd*) (each (n_act,)) for ``n_substeps`` physics steps."""
        q_target = np.asarray(q_target, dtype=float)
        qd_target = np.zeros(self.n) if qd_target is None else np.asarray(qd_target, dtype=float)
        self.q_target, self.qd_target = q_target, qd_target
        self._loop.flush()
        done = 0
        while done < n_substeps:
            k = min(self.control_every, n_substeps - done)
            self._control(q_target, qd_target)
            mujoco.mj_step(self.model, self.data, k)
            done += k

    # ----------------------------------------------------------------------------- running
    def run(self, targets: TargetStream | np.ndarray | TargetsFn, duration: float | None = None,
            rate: float = 30.0, pushes: Sequence[Push] = (), show_progress: bool = False
            ) -> SimTrace:
        """Track a target stream for ``duration`` seconds and record a :class:`SimTrace`.

        Args:
            targets: a :class:`TargetStream`, an array (T, n_act) sampled at ``rate`` Hz, or a
                function ``t -> q`` or ``t -> (q, qd)`` (each (n_act,)); for a function without
                qd, qd is the finite difference over one physics step.
            duration: seconds to simulate (default: the stream's duration).
            pushes: test disturbances applied through ``xfrc_applied`` (not an assist), set at
                the start of every control update and cleared at the end.
        """
        if isinstance(targets, np.ndarray):
            targets = TargetStream(targets, rate=rate)
        if isinstance(targets, TargetStream):
            if targets.q.shape[1] != self.n:
                raise GestureSimError(
                    f"targets have {targets.q.shape[1]} joints, the humanoid has {self.n}")
            sample = targets.sample
            if duration is None:
                duration = targets.duration
        else:
            sample = _wrap_fn(targets, self.model.opt.timestep)
            if duration is None:
                raise GestureSimError("duration is required when targets is a function")
        m, d = self.model, self.data
        n_updates = int(round(duration / (m.opt.timestep * self.control_every)))
        rec = self._new_recorder(n_updates // (self.record_every // self.control_every) + 1)
        loop = PhysicsLoop(m, d, [_RunBody(self, rec)], self.control_every, self.record_every)
        push_body = {p.body: m.body(p.body).id for p in pushes}

        def apply_pushes(t: float) -> None:
            d.xfrc_applied[:] = 0.0
            for p in pushes:
                if p.t_start <= t < p.t_start + p.duration:
                    d.xfrc_applied[push_body[p.body], :3] += p.force

        from gesture_sim.progress import progress
        bar = progress(total=n_updates, desc="simulating", enabled=show_progress, unit="step")

        def report(k: int) -> None:
            if show_progress and k % 500 == 0:
                bar.update(min(500, n_updates - k))

        loop.begin()
        self._record(rec, sample(0.0)[0])
        try:
            loop.run_updates(n_updates, [sample], before_control=apply_pushes,
                             after_update=report)
        finally:
            d.xfrc_applied[:] = 0.0
            bar.close()
        return self._finish(rec)

    # ----------------------------------------------------------------------------- streaming
    def begin_trace(self, record: bool = True, expected_s: float = 60.0) -> None:
        """Start a streamed run at the current state (see :meth:`advance_to`).

        With ``record`` false nothing is kept (the live loop: memory stays flat).
        """
        m = self.model
        rows = int(expected_s / (m.opt.timestep * self.record_every)) + 1
        self._stream_rec = self._new_recorder(rows) if record else None
        self._loop.begin(record)
        if self._stream_rec is not None:
            self._record(self._stream_rec, self.q_target)

    def advance_to(self, t_end: float, sample: Sample) -> None:
        """Step the physics until stream time ``t_end`` (s), tracking ``sample(t) -> (q, qd)``
        (each (n_act,)).

        Stream time is simulation time since :meth:`begin_trace`. Targets are re-sampled at the
        control rate (every ``control_every`` physics steps); rows are recorded every
        ``record_every`` steps when recording (the phase carries over between calls).
        """
        self._loop.run_until(t_end, [sample])

    def export_state(self) -> dict:
        """What stepping changes besides the ``MjData`` (which the loop hands over itself):
        the streamed trace's rows, the reference, the targets, the heading, the hip-strategy
        count. For :meth:`PhysicsLoop.start_background`'s child process."""
        sh = self.shaper
        return {"rec": self._stream_rec, "shaper": (sh.r, sh.v, sh.a),
                "targets": (self.q_target, self.qd_target), "heading": (self._hc, self._hs),
                "hip_strategy_steps": self.hip_strategy_steps}

    def adopt_state(self, state: dict) -> None:
        """Take :meth:`export_state`'s state (from the child process) as this body's own."""
        self._stream_rec = state["rec"]
        self.shaper.r, self.shaper.v, self.shaper.a = (np.array(a) for a in state["shaper"])
        self.q_target, self.qd_target = state["targets"]
        self._hc, self._hs = state["heading"]
        self.hip_strategy_steps = state["hip_strategy_steps"]

    def record_row(self, q_target: np.ndarray) -> None:
        """Append one row, with target q* (n_act,), to the streamed trace for the current state
        (nothing when not recording). The physics loop calls it at the record rate; a
        multi-body scene (:class:`~gesture_sim.sim.scene.SceneSim`) steps the shared data and
        records each body."""
        if self._stream_rec is not None:
            self._record(self._stream_rec, q_target)

    def trace(self) -> SimTrace:
        """The :class:`SimTrace` of the streamed run so far."""
        if self._stream_rec is None:
            raise GestureSimError("no recorded stream: call begin_trace(record=True) first")
        self._loop.flush()
        return self._finish(self._stream_rec)

    def _new_recorder(self, rows: int) -> TraceRecorder:
        return TraceRecorder(rows, self.n, 7 + self.n, 6 + self.n, self.model.nsite,
                             n_target_sites=len(self._rec_sites))

    def _record(self, rec: TraceRecorder, q_target: np.ndarray) -> None:
        """Append one raw row (see :class:`TraceRecorder`) for the current ``MjData``: plain
        copies into preallocated buffers; the contact summaries are derived when the trace is
        built (:meth:`TraceRecorder.contact_summary`)."""
        d = self.data
        if rec.i >= rec.rows:
            rec.grow()
        i, b = rec.i, rec.buf
        b["time"][i] = d.time
        b["qpos"][i] = self._qpos[self.qspan]
        b["qvel"][i] = self._qvel[self.vspan]
        b["act_force"][i] = self._act_force[self._act_sl]
        b["q_target"][i] = q_target
        b["q_ref"][i] = self.shaper.r
        b["sites"][i] = self._site_xpos
        b["com"][i] = self._pelvis_com
        if self._xfrc.any():                 # a test push (the rows start at zero)
            np.dot(self._ones_body, self._xfrc, out=self._wrench6)   # summed over bodies
            b["disturbance"][i, :3] = self._wrench6[:3]
        if d.ncon:
            con = d.contact
            rec.add_contacts(con.geom, con.dist, con.pos)
        rec.close_row()

    def _derive_target_sites(self, rec: TraceRecorder) -> None:
        """Fill ``target_sites`` of the rows recorded since the last call: the kinematic target
        pose q* posed with each row's simulated free root (forward kinematics)."""
        m, kin = self.model, self._kin
        b = rec.buf
        sites = self._rec_sites[2:]
        for i in range(rec.derived, rec.i):
            kin.qpos[self.qspan] = b["qpos"][i]
            kin.qpos[self.qadr] = b["q_target"][i]
            mujoco.mj_kinematics(m, kin)
            b["target_sites"][i, 2:] = kin.site_xpos[sites]
        rec.derived = rec.i

    def _finish(self, rec: TraceRecorder) -> SimTrace:
        self._derive_target_sites(rec)
        a = rec.trimmed()
        qpos, qvel, sites = a["qpos"], a["qvel"], a["sites"][:, self._rec_sites]
        a.update(rec.contact_summary(self._pair_kind))
        return SimTrace(
            time=a["time"], q=qpos[:, self._qadr_local], qd=qvel[:, self._dadr_local],
            q_target=a["q_target"],
            q_ref=a["q_ref"], act_force=a["act_force"], com=a["com"],
            pelvis_height=qpos[:, 2].copy(), foot_pos=sites[:, :2],
            foot_contact=a["foot_contact"], support_points=a["support_points"],
            ground_penetration=a["ground_penetration"],
            self_contact_count=a["self_contact_count"], self_penetration=a["self_penetration"],
            sim_sites=sites[:, 2:], target_sites=a["target_sites"][:, 2:],
            assist=np.zeros((len(qpos), 6)), disturbance=a["disturbance"], qpos=qpos, qvel=qvel,
            joint_names=hm.ACTUATED_JOINTS, joint_range=self.joint_range.copy(),
            force_range=self.force_range.copy(), slide=self.slide.copy(),
            joint_groups=dict(hm.JOINT_GROUPS), site_names=TRACKED_SITES,
            standing_height=hm.standing_height(self.model), timestep=self.model.opt.timestep,
            record_every=self.record_every,
        )


class _PoseCom:
    """COM of a pose relative to its own sole mid-point, in its feet's heading frame (m).

    Forward kinematics of one humanoid's actuated joints ``q`` (n_act,) with its root upright at
    the origin, on a private ``MjData``: ``offset(q) = (c - m) - (c_0 - m_0)`` as (x, y), with
    c the COM, m the mid-point of the sole centres and 0 the standing pose (q = 0).
    """

    def __init__(self, model: mujoco.MjModel, prefix: str, qspan: slice, qadr: np.ndarray,
                 foot_site: Sequence[int]) -> None:
        self.model, self.data = model, mujoco.MjData(model)
        self.qadr, self.foot_site = qadr, list(foot_site)
        root = slice(qspan.start, qspan.start + 7)
        self.data.qpos[root] = (0.0, 0.0, hm.ROOT_HEIGHT, 1.0, 0.0, 0.0, 0.0)
        pelvis = model.body(prefix + "pelvis").id
        bodies = np.flatnonzero(model.body_rootid == pelvis)
        self._bodies = bodies
        self._mass = model.body_mass[bodies] / float(model.body_mass[bodies].sum())
        d = self.data
        self._qpos, self._qadr_sl = d.qpos, _span(qadr)
        bodies_sl = _span(bodies)
        self._xipos_xy = d.xipos[bodies_sl, :2] if isinstance(bodies_sl, slice) else None
        self._xipos = d.xipos
        self._xy = np.zeros((len(bodies), 2))     # the bodies' COM xy, contiguous (one matmul)
        self._c = np.zeros(2)
        self._foot_xpos = [d.site_xpos[s] for s in self.foot_site]
        self._foot_xmat = [d.site_xmat[s] for s in self.foot_site]
        self._c0 = (0.0, 0.0)
        self._c0 = self.offset(np.zeros(len(qadr)))

    def offset(self, q: np.ndarray) -> tuple[float, float]:
        self._qpos[self._qadr_sl] = q
        mujoco.mj_kinematics(self.model, self.data)
        xy = self._xy
        if self._xipos_xy is not None:
            xy[...] = self._xipos_xy
        else:
            xy[...] = self._xipos[self._bodies, :2]
        cx, cy = np.matmul(self._mass, xy, out=self._c).tolist()
        f0x, f0y, _ = self._foot_xpos[0].tolist()
        f1x, f1y, _ = self._foot_xpos[1].tolist()
        m0, m1 = self._foot_xmat[0], self._foot_xmat[1]
        hx, hy = float(m0[0] + m1[0]), float(m0[3] + m1[3])
        norm = math.hypot(hx, hy)
        hc, hs = (hx / norm, hy / norm) if norm > 1e-9 else (1.0, 0.0)
        rx, ry = cx - 0.5 * (f0x + f1x), cy - 0.5 * (f0y + f1y)
        return hc * rx + hs * ry - self._c0[0], -hs * rx + hc * ry - self._c0[1]


class StanceLegs:
    """Leg joint angles that keep both soles flat where they stand while the pelvis moves.

    A planted stance: the soles stay flat at their standing places (the pose q = 0) and the
    pelvis, upright and square to the feet, is displaced by (dx, dy) forward / left and lowered
    by dz (m). :meth:`solve` finds hip flexion, abduction and twist, knee and ankle flexion and
    inversion of both legs (toes at 0) by Newton steps on the feet's position and orientation
    error (``mj_jacSite``), warm-started from the previous solution. The knees keep at least
    ``min_knee_deg`` of flexion (the pelvis is lowered as far as that needs), which keeps the
    solution off the straight-knee singularity and on the forward-bending branch.

    Args:
        model: the humanoid (default :func:`gesture_sim.sim.humanoid.load_model` without the
            scene, mannequin look: only its kinematics are used).
        min_knee_deg: the least knee flexion (degrees).
    """

    def __init__(self, model: mujoco.MjModel | None = None, min_knee_deg: float = 5.0) -> None:
        m = hm.load_model(scene=False, look="mannequin") if model is None else model
        self.model, self.data = m, mujoco.MjData(m)
        legs = list(hm.LEG_JOINTS)
        joints = [j for j in legs if "toe" not in j]
        self.n_legs = len(legs)
        self.cols = np.array([legs.index(j) for j in joints], dtype=int)
        self.qadr = hm.qpos_addresses(m, joints)
        self.dadr = hm.qvel_addresses(m, joints)
        lo, hi = m.jnt_range[hm.joint_ids(m, joints)].T.copy()
        knee = np.array(["knee" in j for j in joints])
        lo[knee] = np.maximum(lo[knee], np.deg2rad(1.0))
        self.lo, self.hi = lo, hi
        self.sites = [m.site(s).id for s in hm.FOOT_SITES]
        root = int(m.jnt_qposadr[m.joint("root").id])
        self.root = slice(root, root + 3)
        d = self.data
        d.qpos[:] = m.qpos0
        d.qpos[root + 2] = hm.ROOT_HEIGHT
        mujoco.mj_kinematics(m, d)
        self.feet = d.site_xpos[self.sites].copy()
        hips = np.array([d.xpos[m.body(b).id] for b in ("left_thigh", "right_thigh")])
        self._ankles = np.array([d.xpos[m.body(b).id] for b in ("left_foot", "right_foot")])
        self._hip_rel = hips - np.array([0.0, 0.0, hm.ROOT_HEIGHT])
        leg = float(np.linalg.norm(self._ankles[0] - hips[0]))       # straight, hip to ankle
        # leg length (hip to ankle) at the least knee flexion, two links of about equal length
        self.max_length = leg * math.cos(math.radians(min_knee_deg) / 2.0)
        start = {"hip_flex": 5.0, "knee_flex": 10.0, "ankle_flex": 5.0}
        self.q0 = np.deg2rad([start.get(j.split("_", 1)[1], 0.0) for j in joints])
        self.q = self.q0.copy()
        self._jp = np.zeros((3, m.nv))
        self._jr = np.zeros((3, m.nv))
        self._jac = np.zeros((12, len(joints)))
        self._err = np.zeros(12)
        self._reg = 1e-8 * np.eye(len(joints))
        self._qpos, self._qadr_sl, self._dadr_sl = d.qpos, _span(self.qadr), _span(self.dadr)
        self._site_rows = [(d.site_xpos[s], d.site_xmat[s]) for s in self.sites]
        self.error = 0.0

    def reset(self) -> None:
        """Forget the warm start."""
        self.q = self.q0.copy()

    def least_drop(self, dx: float, dy: float) -> float:
        """The least pelvis lowering (m) at which both legs reach their soles with the knees
        flexed at least ``min_knee_deg``."""
        need = 0.0
        for side in (0, 1):
            hx, hy, hz = self._hip_rel[side]
            ax, ay, az = self._ankles[side]
            rx, ry = hx + dx - ax, hy + dy - ay
            room = self.max_length ** 2 - rx * rx - ry * ry
            need = max(need, hz + hm.ROOT_HEIGHT - az - math.sqrt(max(room, 1e-6)))
        return need

    def solve(self, dx: float, dy: float, dz: float, iterations: int = 3) -> np.ndarray:
        """Leg angles (len(LEG_JOINTS),) for the pelvis displaced by (dx, dy) and lowered by
        ``max(dz, least_drop)`` (m) over flat soles at their standing places, at most
        ``iterations`` Newton steps (none once the feet are within 10 µm / 10 µrad). ``error``
        keeps the largest foot error (m or rad) before the last step."""
        m, d = self.model, self.data
        d.qpos[self.root] = (dx, dy, hm.ROOT_HEIGHT - max(dz, self.least_drop(dx, dy)))
        q, err, jac = self.q, self._err, self._jac
        jp, jr, dadr = self._jp, self._jr, self._dadr_sl
        for _ in range(iterations):
            self._qpos[self._qadr_sl] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            for k, site in enumerate(self.sites):
                xpos, xmat = self._site_rows[k]
                r = xmat.tolist()
                np.subtract(self.feet[k], xpos, out=err[6 * k: 6 * k + 3])
                err[6 * k + 3: 6 * k + 6] = (0.5 * (r[5] - r[7]), 0.5 * (r[6] - r[2]),
                                             0.5 * (r[1] - r[3]))
                mujoco.mj_jacSite(m, d, jp, jr, site)
                jac[6 * k: 6 * k + 3] = jp[:, dadr]
                jac[6 * k + 3: 6 * k + 6] = jr[:, dadr]
            self.error = float(np.abs(err).max())
            if self.error < 1e-5:
                break
            q = np.clip(q + np.linalg.solve(jac.T @ jac + self._reg, jac.T @ err),
                        self.lo, self.hi)
        self.q = q
        out = np.zeros(self.n_legs)
        out[self.cols] = q
        return out


class _RunBody:
    """A :class:`HumanoidSim` as the body of :meth:`HumanoidSim.run`'s own loop: controlled as
    usual, its rows kept in ``rec`` (apart from any streamed trace)."""

    def __init__(self, sim: HumanoidSim, rec: TraceRecorder) -> None:
        self.sim, self.rec = sim, rec

    def control(self, q_target: np.ndarray, qd_target: np.ndarray) -> None:
        self.sim.control(q_target, qd_target)

    def record_row(self, q_target: np.ndarray) -> None:
        self.sim._record(self.rec, q_target)


def _wrap_fn(fn: TargetsFn, dt: float) -> Sample:
    """Adapt ``t -> q`` or ``t -> (q, qd)`` to ``t -> (q, qd)``."""

    def sample(t: float) -> tuple[np.ndarray, np.ndarray]:
        out = fn(t)
        if isinstance(out, tuple):
            return np.asarray(out[0], dtype=float), np.asarray(out[1], dtype=float)
        q = np.asarray(out, dtype=float)
        return q, (q - np.asarray(fn(max(t - dt, 0.0)), dtype=float)) / dt if t > 0 else 0 * q

    return sample
