"""Joint positions of the simulated body for the motion metrics: forward kinematics of recorded
``qpos`` rows to the evaluated points (:data:`EVAL_POINTS`, 12 points, metres) in the pelvis
heading frame (origin: the pelvis projected onto the floor, x forward, z up; see
:func:`gesture_sim.motion.retarget.heading_frame`), linearly interpolated to :data:`EVAL_FPS`.
"""

from __future__ import annotations

import math

import numpy as np

from gesture_sim.errors import GestureSimError

#: Frame rate of the evaluated joint positions (Hz).
EVAL_FPS = 30.0
#: (name, MuJoCo object kind, MuJoCo name) of the evaluated points, in column order.
EVAL_POINTS: tuple[tuple[str, str, str], ...] = (
    ("pelvis", "body", "pelvis"), ("chest", "body", "chest"), ("neck", "body", "neck"),
    ("head", "site", "head_site"),
    ("left_shoulder", "site", "left_shoulder_site"),
    ("right_shoulder", "site", "right_shoulder_site"),
    ("left_elbow", "site", "left_elbow_site"), ("right_elbow", "site", "right_elbow_site"),
    ("left_wrist", "site", "left_wrist_site"), ("right_wrist", "site", "right_wrist_site"),
    ("left_hand", "site", "left_hand_site"), ("right_hand", "site", "right_hand_site"),
)
POINT_NAMES = tuple(p[0] for p in EVAL_POINTS)
#: Points averaged in beat consistency.
BEAT_POINTS = ("head", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand",
               "right_hand")
#: Points whose mean speed is the hand envelope of the prosody coupling.
HAND_POINTS = ("left_hand", "right_hand")


class PointFK:
    """Forward kinematics of the humanoid to :data:`EVAL_POINTS`.

    Args:
        model: a compiled humanoid scene (default :func:`gesture_sim.sim.humanoid.load_model`).
    """

    def __init__(self, model=None) -> None:
        import mujoco

        from gesture_sim.sim import humanoid as hm

        self.model = hm.load_model() if model is None else model
        self.data = mujoco.MjData(self.model)
        self._mj = mujoco
        m = self.model
        self.body_ids = [(i, m.body(n).id) for i, (_, kind, n) in enumerate(EVAL_POINTS)
                         if kind == "body"]
        self.site_ids = [(i, m.site(n).id) for i, (_, kind, n) in enumerate(EVAL_POINTS)
                         if kind == "site"]

    def world(self, qpos: np.ndarray) -> np.ndarray:
        """World positions ``(T, 12, 3)`` (m) of the points for full ``qpos`` rows ``(T, nq)``."""
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        m, d = self.model, self.data
        if qpos.shape[1] != m.nq:
            raise GestureSimError(f"qpos rows have {qpos.shape[1]} values, the model needs {m.nq}")
        out = np.empty((len(qpos), len(EVAL_POINTS), 3))
        bi = np.array([i for i, _ in self.body_ids])
        bid = np.array([b for _, b in self.body_ids])
        si = np.array([i for i, _ in self.site_ids])
        sid = np.array([s for _, s in self.site_ids])
        for t, row in enumerate(qpos):
            d.qpos[:] = row
            self._mj.mj_kinematics(m, d)
            out[t, bi] = d.xpos[bid]
            out[t, si] = d.site_xpos[sid]
        return out

    def heading(self, qpos: np.ndarray) -> np.ndarray:
        """Points ``(T, 12, 3)`` in the pelvis heading frame (m) for ``qpos`` rows ``(T, nq)``."""
        from gesture_sim.motion.retarget import heading_frame

        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        return heading_frame(qpos[:, :3], qpos[:, 3:7], self.world(qpos))

    def standing(self, q_act: np.ndarray) -> np.ndarray:
        """Points ``(T, 12, 3)`` (m) of actuated joint values ``(T, n_act)`` on the standing body
        (root upright at the origin, so already in the heading frame)."""
        from gesture_sim.sim import humanoid as hm

        q_act = np.atleast_2d(np.asarray(q_act, dtype=float))
        qpos = np.zeros((len(q_act), self.model.nq))
        qpos[:, :7] = hm.root_qpos()
        qpos[:, hm.qpos_addresses(self.model)] = q_act
        return self.world(qpos)


def resample_positions(times: np.ndarray, positions: np.ndarray, fps: float = EVAL_FPS,
                       duration: float | None = None) -> np.ndarray:
    """Linear interpolation of positions ``(T, J, 3)`` at ``times`` (s) onto ``k / fps`` for
    ``k = 0 .. floor(duration * fps)`` (duration default: the last time). Returns ``(K, J, 3)``."""
    times = np.asarray(times, dtype=float)
    p = np.asarray(positions, dtype=float)
    end = float(times[-1]) if duration is None else float(duration)
    grid = np.arange(int(math.floor(end * fps + 1e-9)) + 1) / fps
    flat = p.reshape(len(p), -1)
    out = np.empty((len(grid), flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(grid, times, flat[:, c])
    return out.reshape(len(grid), *p.shape[1:])


def trace_positions(trace, fk: PointFK, fps: float = EVAL_FPS) -> np.ndarray:
    """Joint positions ``(K, 12, 3)`` (m, pelvis heading frame) of a ``SimTrace`` at ``fps``,
    frame ``k`` at ``k / fps`` s on the trace's clock (which starts at 0)."""
    if len(trace.time) < 2:
        raise GestureSimError("the simulation trace has fewer than 2 rows")
    return resample_positions(trace.time - trace.time[0], fk.heading(trace.qpos), fps)
