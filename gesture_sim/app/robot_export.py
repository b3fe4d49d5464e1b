"""The simulated robot's joint trajectory for a real robot (``render --body g1 --robot-export``).

From a robot's :class:`~gesture_sim.sim.trace.SimTrace` (:class:`~gesture_sim.sim.robot.
RobotSim`, rows every 10 ms) the rows at 50 Hz (every ``0.02 / trace.dt``-th row: the
simulated states themselves, not interpolated) are written, in the robot's **motor order**
(the map's ``motor_order``; G1: the low-level command order of ``g1_joint_index_dds.md``,
29-DoF table), as

* ``STEM.npz``: ``t`` (N,) s; ``joint_names`` (D,); ``q`` (N, D) rad; ``dq`` (N, D) rad/s;
  ``tau`` (N, D) N·m, the torque the simulated motor applied (after its limit);
  ``q_target`` (N, D) rad, the PD target; ``root_pos`` (N, 3) m; ``root_rot`` (N, 4) x, y, z,
  w; ``fps``; ``tau_limit`` (D,) N·m;
* ``STEM.csv``: one row per sample, columns ``t``, then ``q_<joint>``, ``dq_<joint>``,
  ``tau_<joint>`` for every joint in motor order;
* ``STEM.pkl``: a pickled dict ``fps`` (50), ``root_pos`` (N, 3), ``root_rot`` (N, 4) xyzw,
  ``dof_pos`` (N, DoF) rad and ``dof_names`` (the motor order without unused slots) — the layout
  motion retargeting / tracking tools for these robots read.

A slot of the motor order whose motor has no torque range (H1's ``not_use_joint``) is written
as zeros in the npz / csv and left out of ``dof_pos``.
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim.bodies import RobotMap
from gesture_sim.sim.trace import SimTrace

#: The export rate (Hz).
EXPORT_FPS = 50.0


def export_paths(stem: str | os.PathLike[str]) -> tuple[Path, Path, Path]:
    """The three files of an export named ``STEM.npz`` (or ``STEM``): .npz, .csv, .pkl."""
    p = Path(stem)
    base = p.with_suffix("") if p.suffix == ".npz" else p
    return base.with_suffix(".npz"), base.with_suffix(".csv"), base.with_suffix(".pkl")


def robot_arrays(robot: RobotMap, trace: SimTrace, fps: float = EXPORT_FPS) -> dict:
    """The export's arrays (module docstring) from a robot trace."""
    step = (1.0 / fps) / trace.dt
    if abs(step - round(step)) > 1e-6 or round(step) < 1:
        raise GestureSimError(f"the trace's rows ({trace.dt * 1000:.1f} ms) do not divide "
                              f"{fps:g} Hz")
    rows = np.arange(0, len(trace), int(round(step)))
    names = list(trace.joint_names)
    try:
        cols = np.array([names.index(j) for j in robot.motor_order])
    except ValueError as exc:
        raise GestureSimError(f"robot {robot.name!r}: motor order names a joint the trace "
                              f"lacks ({exc})") from exc
    used = trace.force_range[cols, 1] > trace.force_range[cols, 0]
    q, dq = trace.q[rows][:, cols], trace.qd[rows][:, cols]
    tau = trace.act_force[rows][:, cols]
    q[:, ~used] = dq[:, ~used] = tau[:, ~used] = 0.0
    qp = trace.qpos[rows]
    root_rot = qp[:, [4, 5, 6, 3]]                         # MuJoCo wxyz -> xyzw
    return {"t": trace.time[rows] - trace.time[0], "joint_names": np.array(robot.motor_order),
            "q": q, "dq": dq, "tau": tau, "q_target": trace.q_target[rows][:, cols],
            "root_pos": qp[:, :3].copy(), "root_rot": root_rot, "fps": float(fps),
            "tau_limit": trace.force_range[cols, 1].copy(), "used": used}


def write_robot_export(npz_path: Path, csv_path: Path, pkl_path: Path, arrays: dict) -> None:
    """Write the three files (to the paths given: the caller makes them atomic)."""
    names = [str(n) for n in arrays["joint_names"]]
    with open(npz_path, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    head = ["t", *(f"q_{n}" for n in names), *(f"dq_{n}" for n in names),
            *(f"tau_{n}" for n in names)]
    table = np.column_stack([arrays["t"], arrays["q"], arrays["dq"], arrays["tau"]])
    with open(csv_path, "w", encoding="utf-8") as fh:
        fh.write(",".join(head) + "\n")
        np.savetxt(fh, table, delimiter=",", fmt="%.6g")
    used = np.asarray(arrays["used"], dtype=bool)
    doc = {"fps": float(arrays["fps"]), "root_pos": arrays["root_pos"].astype(np.float64),
           "root_rot": arrays["root_rot"].astype(np.float64),
           "dof_pos": arrays["q"][:, used].astype(np.float64),
           "dof_names": [n for n, u in zip(names, used, strict=True) if u]}
    with open(pkl_path, "wb") as fh:
        pickle.dump(doc, fh, protocol=4)
