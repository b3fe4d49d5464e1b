"""The humanoid's targets on a robot: inverse kinematics on the robot's own kinematics.

For a humanoid target pose q_h (:data:`~gesture_sim.sim.humanoid.ACTUATED_JOINTS`, rad), the
robot's target (its actuated joints, in its actuator order, rad) is found in two steps on a
private ``MjData`` of the robot with its pelvis fixed upright at the origin:

1. **Trunk.** The spine/waist joints s minimise the rotation error between the robot's torso
   over its pelvis and the humanoid's chest over its pelvis (Levenberg–Marquardt on the rotation
   vector, ``mj_jacBody``); where the robot has no neck, ``nod_gain`` times the humanoid's neck +
   head flexion is added to the map's ``nod_joint`` (a waist pitch: the nods become small bows).
2. **Arms.** In the robot's torso frame each arm's targets are the humanoid's elbow and hand
   points relative to its shoulder, expressed in the humanoid's chest frame and scaled by the
   ratio of arm lengths (robot shoulder→elbow→hand over the humanoid's), added to the robot's
   shoulder point: E* = p_sh + R_t s e_h, H* = p_sh + R_t s w_h. Where the robot has wrists
   (``orient``) the hand's orientation is matched too, R* = R_t R_cᵀ R_hand,h · Aᵀ (A: the map's
   ``hand_axes``). The arm's joints minimise ``|H* - h(q)|² + w_e² |E* - e(q)|² +
   w_o² |log(R*ᵀ R(q))|² + w_p² |q - q_stand|²`` by damped least squares (``mj_jac``), each
   step bounded (:data:`MAX_STEP`) and clamped to the joint limits (less a 0.01 rad margin);
   the posture term, the damping and the warm start (the previous solution) keep consecutive
   frames on the same, natural branch. Where the warm start ends more than
   :data:`RESTART_ERROR` from the hand target (it is caught in a fold of the arm's
   workspace), the arm is solved again from the standing pose and the better solution kept.

Each solution is then held within the joint velocity limits of the map: its change from the
previous frame is clipped to ``min(0.9 v_max, MAX_SPEED) dt`` (:data:`MAX_SPEED`). The legs
take the map's standing pose.

:func:`retarget_library` runs this along every clip of a library (warm-started frame to frame)
and caches the result on disk, keyed by the robot's fingerprint (map + model files), the
library's fingerprint and :data:`RETARGET_VERSION`; the pipeline's per-step mapping
(:class:`RobotRetarget`) uses the same solver, warm-started from the previous step.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.bodies import RobotMap

#: Bumped whenever the solver changes what it computes (part of the cache key).
RETARGET_VERSION = "2"
#: Weights of the elbow point and of the hand orientation (m per rad) against the hand point.
ELBOW_WEIGHT = 0.5
ORIENT_WEIGHT = 0.08
#: Weight (m per rad) of the pull of each arm joint towards the standing pose: it makes the
#: solution unique where the arm is redundant and keeps it on the natural branch.
POSTURE_WEIGHT = 0.02
#: Damping (m²) of the arms' least squares: near a singular arm (straight up, where the
#: shoulder's axes align) it trades a few millimetres of the hand for no joint racing.
DAMPING = 1e-2
#: Largest joint speed of a retargeted stream (rad/s), besides 0.9 of the joint's own limit:
#: faster is a branch change, not a gesture (the library's arms move below 10 rad/s).
MAX_SPEED = 8.0
#: Largest change of a joint in one solver iteration (rad).
MAX_STEP = 0.4
#: A warm-started arm whose hand misses its target by more than this (m) is solved again from
#: the standing pose (more iterations), and the better solution is kept.
RESTART_ERROR = 0.04
_MARGIN = 0.01
_SIDES = ("left", "right")


def cache_dir() -> Path:
    """Where retargeted libraries are cached: ``$GESTURE_SIM_CACHE`` or
    ``~/.cache/gesture_sim`` (``robots/`` below it)."""
    root = os.environ.get("GESTURE_SIM_CACHE") or Path.home() / ".cache" / "gesture_sim"
    return Path(root) / "robots"


def _rotvec(r: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of a rotation matrix (3, 3)."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(r).reshape(-1))
    v = np.zeros(3)
    mujoco.mju_quat2Vel(v, q, 1.0)
    return v


class RobotRetarget:
    """Maps humanoid target poses onto one robot (module docstring).

    Args:
        robot: the robot's map; model: its compiled model (default ``robot.load_model()``).

    Attributes:
        joint_names: the robot's actuated joints in actuator order (the target vector's order).
        joint_range: (n, 2) their limits (rad); v_max: (n,) their speed limits (rad/s).
        scale: per side, robot arm length / humanoid arm length.
    """

    def __init__(self, robot: RobotMap, model: mujoco.MjModel | None = None) -> None:
        self.robot = robot
        m = robot.load_model() if model is None else model
        self.model, self.data = m, mujoco.MjData(m)
        self.joint_names = tuple(m.joint(m.actuator_trnid[a, 0]).name for a in range(m.nu))
        jid = np.array([m.actuator_trnid[a, 0] for a in range(m.nu)])
        self.qadr = m.jnt_qposadr[jid].astype(int)
        self.dadr = m.jnt_dofadr[jid].astype(int)
        self.joint_range = m.jnt_range[jid].copy()
        limited = m.jnt_limited[jid].astype(bool)
        self.joint_range[~limited] = (-np.pi, np.pi)
        self.n = m.nu
        self.v_max = np.array([robot.lookup(robot.velocity_limit, j, 1e9)
                               for j in self.joint_names])
        self.stand = np.zeros(self.n)
        for j, v in robot.stand.items():
            self.stand[self.joint_names.index(j)] = v
        self._col = {j: i for i, j in enumerate(self.joint_names)}
        root = next(j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
        self._root_q = int(m.jnt_qposadr[root])
        self.spine_cols = np.array([self._col[j] for j in robot.spine], dtype=int)
        self.arm_cols = {s: np.array([self._col[j] for j in robot.arms[s].joints], dtype=int)
                         for s in _SIDES}
        self.nod_col = self._col[robot.nod_joint] if robot.nod_joint else -1
        self.torso = m.body(robot.torso_body).id
        self.pelvis = m.body(robot.pelvis_body).id
        self._arm_body = {s: tuple(m.body(b).id for b in (a.shoulder_body, a.elbow_body,
                                                          a.hand_body))
                          for s, a in robot.arms.items()}
        self._hand_off = {s: np.array(a.hand_offset) for s, a in robot.arms.items()}
        self._axes_t = {s: np.array(a.hand_axes, dtype=float).T for s, a in robot.arms.items()}
        self._speed = np.minimum(0.9 * self.v_max, MAX_SPEED)   # the clip's speeds (rad/s)
        self._reg = {s: (POSTURE_WEIGHT ** 2 + DAMPING) * np.eye(len(a.joints))
                     for s, a in robot.arms.items()}
        self._lo = self.joint_range[:, 0] + _MARGIN
        self._hi = self.joint_range[:, 1] - _MARGIN
        # the humanoid's kinematics
        h = hm.load_model(scene=False, look="mannequin")
        self.h_model, self.h_data = h, mujoco.MjData(h)
        self._h_qadr = hm.qpos_addresses(h)
        self._h_chest, self._h_pelvis = h.body("chest").id, h.body("pelvis").id
        self._h_sites = {s: tuple(h.site(f"{s}_{k}_site").id for k in ("shoulder", "elbow",
                                                                        "hand"))
                         for s in _SIDES}
        self._h_hand = {s: h.body(f"{s}_hand").id for s in _SIDES}
        nod = [hm.ACTUATED_JOINTS.index(j) for j in ("neck_flex", "head_flex")]
        self._h_nod = np.array(nod)
        self._jp = np.zeros((3, m.nv))
        self._jr = np.zeros((3, m.nv))
        self._pose(self.stand)
        self.scale = {}
        for s in _SIDES:
            sh, el, ha = self._robot_points(s)
            robot_len = np.linalg.norm(el - sh) + np.linalg.norm(ha - el)
            self._h_pose(np.zeros(len(hm.ACTUATED_JOINTS)))
            hs, he, hh = (self.h_data.site_xpos[i] for i in self._h_sites[s])
            self.scale[s] = float(robot_len / (np.linalg.norm(he - hs) + np.linalg.norm(hh - he)))
        self.q_prev: np.ndarray | None = None
        self.hand_error = 0.0
        #: solves between two restarts at least (0: any solve may restart); the pipeline's
        #: per-step mapping sets it so that an unreachable target costs one restart per 0.5 s
        self.restart_every = 0
        self._since_restart = 0
        self._nod_prev = 0.0           # the nod (rad) added to the last solution's nod joint

    # ------------------------------------------------------------------ kinematics
    def _pose(self, q: np.ndarray) -> None:
        d = self.data
        d.qpos[:] = self.model.qpos0
        d.qpos[self._root_q: self._root_q + 7] = (0, 0, 0, 1, 0, 0, 0)
        d.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)

    def _h_pose(self, q_h: np.ndarray) -> None:
        d = self.h_data
        d.qpos[:] = self.h_model.qpos0
        d.qpos[self._h_qadr] = q_h
        mujoco.mj_kinematics(self.h_model, d)

    def _robot_points(self, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = self.data
        sh, el, ha = self._arm_body[side]
        hand = d.xpos[ha] + d.xmat[ha].reshape(3, 3) @ self._hand_off[side]
        return d.xpos[sh].copy(), d.xpos[el].copy(), hand

    # ------------------------------------------------------------------ the solver
    def solve(self, q_h: np.ndarray, q_prev: np.ndarray | None = None, iterations: int = 6,
              dt: float | None = None) -> np.ndarray:
        """The robot target (n,) for humanoid pose ``q_h`` (n_act,), warm-started from
        ``q_prev`` (default: the previous solution, else the standing pose); ``dt`` (s): time
        since that previous frame, for the velocity clip (None: no clip)."""
        q_h = np.asarray(q_h, dtype=float)
        if q_h.shape != (len(hm.ACTUATED_JOINTS),):
            raise GestureSimError(f"humanoid pose must have shape ({len(hm.ACTUATED_JOINTS)},)")
        prev = self.q_prev if q_prev is None else np.asarray(q_prev, dtype=float)
        start = self.stand.copy() if prev is None else prev.copy()
        q = start.copy()
        q[self.robot_leg_cols] = self.stand[self.robot_leg_cols]
        self._h_pose(q_h)
        hd = self.h_data
        r_hp = hd.xmat[self._h_pelvis].reshape(3, 3)
        r_hc = hd.xmat[self._h_chest].reshape(3, 3)
        r_rel = r_hp.T @ r_hc                      # chest over pelvis
        # 1. the trunk
        cols = self.spine_cols
        if len(cols):
            for _ in range(iterations):
                self._pose(q)
                r_t = self.data.xmat[self.torso].reshape(3, 3)
                err = _rotvec(r_t.T @ r_rel)                  # torso frame
                err = r_t @ err                               # world (= pelvis) frame
                if np.abs(err).max() < 1e-4:
                    break
                mujoco.mj_jacBody(self.model, self.data, self._jp, self._jr, self.torso)
                jac = self._jr[:, self.dadr[cols]]
                dq = np.linalg.solve(jac.T @ jac + 1e-3 * np.eye(len(cols)), jac.T @ err)
                q[cols] = np.clip(q[cols] + dq, self._lo[cols], self._hi[cols])
        if self.nod_col >= 0:
            c = self.nod_col
            q[c] = np.clip(q[c] + self.robot.nod_gain * float(q_h[self._h_nod].sum()),
                           self._lo[c], self._hi[c])
        # 2. the arms
        self._pose(q)
        r_t = self.data.xmat[self.torso].reshape(3, 3).copy()
        m_map = r_t @ r_hc.T
        err_h = 0.0
        may_restart, restarted = self._since_restart >= self.restart_every, False
        for s in _SIDES:
            hs, he, hh = (hd.site_xpos[i].copy() for i in self._h_sites[s])
            sh_r, _, _ = self._robot_points(s)
            k = self.scale[s]
            e_t = sh_r + k * (m_map @ (he - hs))
            h_t = sh_r + k * (m_map @ (hh - hs))
            r_goal = m_map @ hd.xmat[self._h_hand[s]].reshape(3, 3) @ self._axes_t[s]
            e_hand = self._solve_arm(q, s, e_t, h_t, r_goal, iterations)
            if e_hand > RESTART_ERROR and may_restart:
                restarted = True
                alt = q.copy()
                alt[self.arm_cols[s]] = self.stand[self.arm_cols[s]]
                e_alt = self._solve_arm(alt, s, e_t, h_t, r_goal, 4 * iterations + 8)
                if e_alt < 0.5 * e_hand:
                    q[:], e_hand = alt, e_alt
            err_h = max(err_h, e_hand)
        self.hand_error = err_h
        self._nod_prev = (self.robot.nod_gain * float(q_h[self._h_nod].sum())
                          if self.nod_col >= 0 else 0.0)
        self._since_restart = 0 if restarted else self._since_restart + 1
        if dt is not None and prev is not None:
            step = np.minimum(0.9 * self.v_max, MAX_SPEED) * dt
            q = np.clip(q, prev - step, prev + step)
        self.q_prev = q
        return q

    def _solve_arm(self, q: np.ndarray, s: str, e_t: np.ndarray, h_t: np.ndarray,
                   r_goal: np.ndarray, iterations: int) -> float:
        """Damped least squares of arm ``s`` in place on ``q`` (module docstring); returns the
        hand's distance from ``h_t`` (m) at the end."""
        arm = self.robot.arms[s]
        cols = self.arm_cols[s]
        dofs = self.dadr[cols]
        _, el_b, ha_b = self._arm_body[s]
        lam = DAMPING * np.eye(len(cols))
        w_p = POSTURE_WEIGHT
        for it in range(iterations + 1):
            self._pose(q)
            _, el, ha = self._robot_points(s)
            e_hand = h_t - ha
            if it == iterations:
                break
            rows = [e_hand, ELBOW_WEIGHT * (e_t - el), w_p * (self.stand[cols] - q[cols])]
            mujoco.mj_jac(self.model, self.data, self._jp, self._jr, ha, ha_b)
            jacs = [self._jp[:, dofs].copy()]
            jr = self._jr[:, dofs].copy()
            mujoco.mj_jac(self.model, self.data, self._jp, self._jr, el, el_b)
            jacs += [ELBOW_WEIGHT * self._jp[:, dofs], w_p * np.eye(len(cols))]
            if arm.orient:
                r_now = self.data.xmat[ha_b].reshape(3, 3)
                rows.append(ORIENT_WEIGHT * (r_now @ _rotvec(r_now.T @ r_goal)))
                jacs.append(ORIENT_WEIGHT * jr)
            err = np.concatenate(rows)
            jac = np.vstack(jacs)
            dq = np.linalg.solve(jac.T @ jac + lam, jac.T @ err)
            dq = np.clip(dq, -MAX_STEP, MAX_STEP)
            q[cols] = np.clip(q[cols] + dq, self._lo[cols], self._hi[cols])
        return float(np.linalg.norm(e_hand))

    def track(self, q_h: np.ndarray, start: np.ndarray, dt: float | None = None,
              iterations: int = 1) -> tuple[np.ndarray, float]:
        """The cheap per-step form of :meth:`solve` for a stream: from ``start`` (n,) — the
        previous step's solution, a few milliseconds of motion from this one — one trunk
        Gauss–Newton step and ``iterations`` damped least-squares steps of both arms, each
        arm's step taken from one shared forward-kinematics pass (the two arms are
        independent chains once the trunk is set); no restart. Returns (q (n,), the larger
        hand miss (m) *before* the last arm step: an upper bound of the miss after it, which
        the caller compares with :data:`RESTART_ERROR` to fall back to :meth:`solve`).

        Adapted from :meth:`solve`: same targets, weights, bounds and velocity clip, fewer
        kinematics passes (one iteration per control step is the classic closed-loop IK; the
        residual is carried to, and corrected at, the next step)."""
        q_h = np.asarray(q_h, dtype=float)
        prev = np.asarray(start, dtype=float)
        q = prev.copy()
        self._h_pose(q_h)
        hd = self.h_data
        r_hc = hd.xmat[self._h_chest].reshape(3, 3)
        r_rel = hd.xmat[self._h_pelvis].reshape(3, 3).T @ r_hc
        cols = self.spine_cols
        nod = self.robot.nod_gain * float(q_h[self._h_nod].sum()) if self.nod_col >= 0 else 0.0
        if self.nod_col >= 0:          # the start carries the previous nod: the trunk's own
            q[self.nod_col] -= self._nod_prev      # solution is without it
        self._pose(q)
        if len(cols):
            r_t = self.data.xmat[self.torso].reshape(3, 3)
            err = r_t @ _rotvec(r_t.T @ r_rel)
            if np.abs(err).max() >= 1e-4:
                mujoco.mj_jacBody(self.model, self.data, self._jp, self._jr, self.torso)
                jac = self._jr[:, self.dadr[cols]]
                dq = np.linalg.solve(jac.T @ jac + 1e-3 * np.eye(len(cols)), jac.T @ err)
                q[cols] = np.clip(q[cols] + dq, self._lo[cols], self._hi[cols])
        if self.nod_col >= 0:
            c = self.nod_col
            q[c] = np.clip(q[c] + nod, self._lo[c], self._hi[c])
        self._nod_prev = nod
        miss = 0.0
        for _ in range(max(1, iterations)):
            self._pose(q)
            r_t = self.data.xmat[self.torso].reshape(3, 3).copy()
            m_map = r_t @ r_hc.T
            for s in _SIDES:
                hs, he, hh = (hd.site_xpos[i] for i in self._h_sites[s])
                sh_r, el, ha = self._robot_points(s)
                k = self.scale[s]
                e_t = sh_r + k * (m_map @ (he - hs))
                h_t = sh_r + k * (m_map @ (hh - hs))
                e_hand = h_t - ha
                miss = max(miss, float(np.linalg.norm(e_hand)))
                arm, acols = self.robot.arms[s], self.arm_cols[s]
                dofs = self.dadr[acols]
                _, el_b, ha_b = self._arm_body[s]
                w_p = POSTURE_WEIGHT
                mujoco.mj_jac(self.model, self.data, self._jp, self._jr, ha, ha_b)
                jp_h, jr = self._jp[:, dofs].copy(), self._jr[:, dofs].copy()
                mujoco.mj_jac(self.model, self.data, self._jp, self._jr, el, el_b)
                jp_e = self._jp[:, dofs]
                # the normal equations summed term by term (no stacking)
                ata = jp_h.T @ jp_h + ELBOW_WEIGHT ** 2 * (jp_e.T @ jp_e)
                atb = jp_h.T @ e_hand + ELBOW_WEIGHT ** 2 * (jp_e.T @ (e_t - el))
                ata += self._reg[s]
                atb += w_p ** 2 * (self.stand[acols] - q[acols])
                if arm.orient:
                    r_now = self.data.xmat[ha_b].reshape(3, 3)
                    e_o = r_now @ _rotvec(r_now.T @ r_goal_of(hd, self, s, m_map))
                    ata += ORIENT_WEIGHT ** 2 * (jr.T @ jr)
                    atb += ORIENT_WEIGHT ** 2 * (jr.T @ e_o)
                dq = np.minimum(np.maximum(np.linalg.solve(ata, atb), -MAX_STEP), MAX_STEP)
                q[acols] = np.minimum(np.maximum(q[acols] + dq, self._lo[acols]),
                                      self._hi[acols])
        if dt is not None:
            step = self._speed * dt
            q = np.minimum(np.maximum(q, prev - step), prev + step)
        self.q_prev = q
        self.hand_error = miss
        return q, miss

    @property
    def robot_leg_cols(self) -> np.ndarray:
        """Columns of the legs' joints (held at the standing pose)."""
        return np.array([self._col[j] for j in self.robot.leg_joints], dtype=int)

    def hand_points(self, q: np.ndarray) -> np.ndarray:
        """(2, 3) the robot's left and right hand points (m, pelvis at the origin) in pose q."""
        self._pose(np.asarray(q, dtype=float))
        return np.array([self._robot_points(s)[2] for s in _SIDES])

    def hand_targets(self, q_h: np.ndarray) -> np.ndarray:
        """(2, 3) where :meth:`solve` puts the hands for humanoid pose ``q_h`` (scaled targets,
        with the robot's trunk as solved for ``q_h``)."""
        q = self.solve(q_h, q_prev=self.stand, iterations=8)
        self._pose(q)
        r_t = self.data.xmat[self.torso].reshape(3, 3).copy()
        self._h_pose(q_h)
        r_hc = self.h_data.xmat[self._h_chest].reshape(3, 3)
        out = []
        for s in _SIDES:
            hs, _, hh = (self.h_data.site_xpos[i] for i in self._h_sites[s])
            out.append(self._robot_points(s)[0] + self.scale[s] * (r_t @ r_hc.T @ (hh - hs)))
        return np.array(out)


def r_goal_of(hd: mujoco.MjData, rt: RobotRetarget, side: str, m_map: np.ndarray
              ) -> np.ndarray:
    """The robot hand's goal orientation (3, 3) for the humanoid pose in ``hd``: R_t R_cᵀ
    R_hand,h Aᵀ (``m_map`` = R_t R_cᵀ)."""
    return m_map @ hd.xmat[rt._h_hand[side]].reshape(3, 3) @ rt._axes_t[side]


#: Humanoid joints whose angles decide the retarget (the trunk and the arms; fingers, face and
#: legs do not enter it, the neck and head only through the nod).
RETARGET_JOINTS = tuple(j for j in hm.ACTUATED_JOINTS if "spine" in j or j.startswith(
    tuple(f"{s}_{k}" for s in _SIDES for k in ("clavicle", "shoulder", "elbow", "forearm",
                                                 "wrist"))))


class RobotTargets:
    """Each control step's humanoid target on the robot: the cached library frame when the
    step plays a library frame unchanged (its trunk and arm joints equal the frame's), the
    nod re-added; else :meth:`RobotRetarget.solve` warm-started from the previous step.

    Args:
        retarget: the solver. clips_h, clips_r: per clip the humanoid frames (T_i, n_act) and
            their robot frames (T_i, n) (:func:`retarget_library`), or None (no cache).
    """

    def __init__(self, retarget: RobotRetarget, clips_h: list[np.ndarray] | None = None,
                 clips_r: list[np.ndarray] | None = None) -> None:
        self.retarget = retarget
        self.clips_h, self.clips_r = clips_h, clips_r
        self._cols = np.array([hm.ACTUATED_JOINTS.index(j) for j in RETARGET_JOINTS])
        self.stand = retarget.stand
        retarget.restart_every = 15
        #: control steps served from the cache / tracked (:meth:`RobotRetarget.track`, one
        #: iteration from the previous step) / solved in full (:meth:`RobotRetarget.solve`)
        self.cached_steps = self.tracked_steps = self.solved_steps = 0
        #: whether a step off the cache is tracked (else always solved in full)
        self.track = True
        #: steps that repeated the previous, converged step's pose (its target held)
        self.held_steps = 0
        self._key_cols = np.concatenate([self._cols, retarget._h_nod])
        self._settled, self._last_key = False, None

    @property
    def q_prev(self) -> np.ndarray | None:
        """The previous step's robot target (None: none yet)."""
        return self.retarget.q_prev

    @q_prev.setter
    def q_prev(self, q: np.ndarray | None) -> None:
        self.retarget.q_prev = q
        self._settled, self._last_key = False, None

    def solve(self, q_h: np.ndarray, q_prev: np.ndarray | None = None, iterations: int = 4,
              dt: float | None = None) -> np.ndarray:
        """:meth:`RobotRetarget.solve` (no cache)."""
        return self.retarget.solve(q_h, q_prev=q_prev, iterations=iterations, dt=dt)

    def target(self, q_h: np.ndarray, playing: tuple[int, int] | None, dt: float
               ) -> np.ndarray:
        """The robot target (n,) of the step whose humanoid target is ``q_h`` (n_act,) while
        (clip, clip frame) ``playing`` plays (None: nothing); ``dt``: the control step (s)."""
        rt = self.retarget
        if playing is not None and self.clips_r is not None and self.clips_h is not None:
            c, f = playing
            if 0 <= c < len(self.clips_r) and 0 <= f < len(self.clips_r[c]):
                h = self.clips_h[c][f]
                if np.array_equal(np.asarray(q_h[self._cols], dtype=np.float32),
                                  h[self._cols]):
                    q = self.clips_r[c][f].astype(float)
                    if rt.nod_col >= 0:
                        k = rt.nod_col
                        q[k] = np.clip(q[k] + rt.robot.nod_gain * float(
                            q_h[rt._h_nod].sum() - h[rt._h_nod].astype(float).sum()),
                            rt._lo[k], rt._hi[k])
                    prev = rt.q_prev
                    if prev is not None:
                        step = np.minimum(0.9 * rt.v_max, MAX_SPEED) * dt
                        q = np.clip(q, prev - step, prev + step)
                    self._settled, self._last_key = False, None
                    rt.q_prev = q
                    rt._nod_prev = (rt.robot.nod_gain * float(q_h[rt._h_nod].sum())
                                    if rt.nod_col >= 0 else 0.0)
                    self.cached_steps += 1
                    return q
        if rt.q_prev is not None and self.track:
            prev = rt.q_prev
            key = np.asarray(q_h, dtype=float)[self._key_cols]
            if self._settled and self._last_key is not None and np.array_equal(
                    key, self._last_key):
                self.held_steps += 1          # the same pose again, already converged
                return prev.copy()
            q, miss = rt.track(q_h, prev, dt=dt)
            if miss <= RESTART_ERROR:
                self._settled = float(np.abs(q - prev).max()) < 1e-5
                self._last_key = key
                self.tracked_steps += 1
                return q
            rt.q_prev = prev                    # caught in a fold: the full solve
        self._settled, self._last_key = False, None
        self.solved_steps += 1
        return rt.solve(q_h, iterations=4, dt=dt)


def _library_fingerprint(qpos: list[np.ndarray]) -> str:
    import hashlib

    h = hashlib.sha256()
    for a in qpos:
        h.update(np.ascontiguousarray(a, dtype=np.float32).tobytes())
    return h.hexdigest()[:16]


def cache_file(robot: RobotMap, fingerprint: str) -> str:
    """The file name of a robot library: robot name, its fingerprint, the library's, version."""
    return f"{robot.name}-{robot.fingerprint}-{fingerprint}-v{RETARGET_VERSION}.npz"


def shipped_dir() -> Path:
    """Where prebuilt robot libraries of the shipped library are (``<library>/robots``)."""
    from gesture_sim import DATA_DIR

    return DATA_DIR / "motion_library" / "default" / "robots"


def find_library_on_robot(robot: RobotMap, library) -> tuple[list, list] | None:
    """(humanoid frames, robot frames) per clip of ``library`` (a MotionLibrary) when a built
    robot library for this robot and library exists (shipped, then the cache), else None."""
    name = cache_file(robot, library.fingerprint)
    for folder in (shipped_dir(), cache_dir()):
        if (folder / name).is_file():
            frames, _ = retarget_library(robot, [c.qpos for c in library.clips], library.fps,
                                         fingerprint=library.fingerprint, cache=folder)
            return [np.asarray(c.qpos, dtype=np.float32) for c in library.clips], frames
    return None


def retarget_library(robot: RobotMap, clips_qpos: list[np.ndarray], fps: float,
                     fingerprint: str | None = None, cache: Path | None = None,
                     retarget: RobotRetarget | None = None) -> tuple[list[np.ndarray], dict]:
    """Every clip's frames on the robot, cached on disk.

    Args:
        robot: the robot's map. clips_qpos: per clip, (T_i, n_act) humanoid frames (rad).
        fps: their frame rate (Hz; the velocity clip's dt). fingerprint: the library's (default:
        a hash of the frames). cache: the cache folder (default :func:`cache_dir`).

    Returns:
        (per clip (T_i, n) robot frames in actuator order, info) with info ``built`` (bool),
        ``seconds`` (build time, s), ``path`` (the cache file), ``max_hand_error`` (m).
    """
    fp = fingerprint or _library_fingerprint(clips_qpos)
    folder = cache_dir() if cache is None else Path(cache)
    path = folder / cache_file(robot, fp)
    if path.is_file():
        with np.load(path) as z:
            frames, bounds = z["frames"], z["bounds"]
            info = {"built": False, "seconds": 0.0, "path": str(path),
                    "max_hand_error": float(z["max_hand_error"])}
        return [frames[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)], info
    t0 = time.perf_counter()
    rt = retarget or RobotRetarget(robot)
    out, worst = [], 0.0
    for qs in clips_qpos:
        rt.q_prev = None
        rows = []
        for i, qh in enumerate(np.asarray(qs, dtype=float)):
            rows.append(rt.solve(qh, iterations=12 if i == 0 else 6,
                                 dt=None if i == 0 else 1.0 / fps))
            worst = max(worst, rt.hand_error)
        out.append(np.array(rows, dtype=np.float32).reshape(-1, rt.n))
    seconds = time.perf_counter() - t0
    from gesture_sim.fileio import atomic_path

    folder.mkdir(parents=True, exist_ok=True)
    bounds = np.cumsum([0, *(len(a) for a in out)])
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, frames=np.concatenate(out) if out else np.zeros((0, rt.n)),
                            bounds=bounds, max_hand_error=worst,
                            joint_names=np.array(rt.joint_names))
    return out, {"built": True, "seconds": seconds, "path": str(path), "max_hand_error": worst}
