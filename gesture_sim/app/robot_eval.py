"""Figures of speech-driven motion on a robot (``gesture-sim bench robot``).

Per run (a method, an audio file, a seed; the causal pipeline with physics, fed the file as
``render`` feeds it), from the robot's :class:`~gesture_sim.sim.trace.SimTrace` (rows every
10 ms = every control update):

* ``fell``: the pelvis below 0.6 of its standing height in any row; ``assist``: the assist
  impulse (N·s/s; zero by construction);
* ``joint_limit_excess_deg``: the largest excess of a motor's joint past its range (deg; a
  slot without a motor, H1's ``not_use_joint``, is left out here and below);
* ``saturation_share``: per joint, the share of rows with the motor at its torque limit
  (|τ| ≥ 0.999 ``ctrlrange``); ``saturation_share_max`` the largest;
* ``velocity_excess``: per joint the largest excess of |q̇| over the map's speed limit
  (rad/s); ``velocity_excess_max``;
* ``self_contacts``: contacts with penetration between an arm and the trunk (pelvis, waist,
  torso) or between the two arms (every row's state replayed through ``mj_collision``),
  summed over rows, ``arm_torso`` and ``arm_arm``;
* ``foot_skate_mm_s``: mean horizontal speed of the soles while both touch the floor
  (:func:`~gesture_sim.metrics.physics.physics_metrics`);
* speech synchrony of the **hands** (the two hand points, in the pelvis heading frame, at
  30 fps; the first 2 s left out): ``bc``, its chance level ``bc_chance`` and ``bc_excess``
  (:func:`gesture_sim.metrics.motion.beat_consistency`, :func:`~gesture_sim.metrics.inputs.
  bc_chance`), ``accent_hit_excess`` (:func:`~gesture_sim.metrics.motion.prosody_coupling`).
  The same definition is applied to the humanoid (its hand sites), so that the robot's
  synchrony reads against the humanoid's on the same audio and seeds. This is not
  ``eval motion``'s BC, which averages more points (head, elbows, wrists, hands).

Controls: ``random`` (the random-clip baseline method) and ``mismatched`` (the controller's
motion scored against another file's audio, cyclically; one file: its audio rotated by half).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import mujoco
import numpy as np

from gesture_sim.metrics import motion as mm
from gesture_sim.metrics.inputs import AudioInput, bc_chance, load_input, rotated
from gesture_sim.metrics.physics import physics_metrics
from gesture_sim.metrics.points import EVAL_FPS

#: Seconds left out at the start of every scored run (the body settles into the speech).
WARMUP_S = 2.0


def hand_positions(trace, fps: float = EVAL_FPS) -> np.ndarray:
    """(N, 2, 3) the left and right hand sites in the pelvis heading frame (m) at ``fps``."""
    t = trace.time - trace.time[0]
    n = int(math.floor(t[-1] * fps)) + 1
    tt = np.arange(n) / fps
    root = trace.qpos[:, :7]
    w, x, y, z = root[:, 3], root[:, 4], root[:, 5], root[:, 6]
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    hands = trace.sim_sites[:, :2] - np.stack([root[:, 0], root[:, 1], 0 * root[:, 2]],
                                              axis=1)[:, None, :]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    local = np.stack([c * hands[..., 0] + s * hands[..., 1], -s * hands[..., 0] + c * hands[..., 1],
                      hands[..., 2]], axis=-1)
    out = np.empty((n, 2, 3))
    for k in range(2):
        for d in range(3):
            out[:, k, d] = np.interp(tt, t, local[:, k, d])
    return out


def sync_scores(pos: np.ndarray, inp: AudioInput, warmup_s: float = WARMUP_S) -> dict:
    """BC, its chance level and excess, and accent hits − chance of hand points ``pos``
    (N, 2, 3) at 30 fps against ``inp`` (both cut to the shorter)."""
    k0 = int(round(warmup_s * EVAL_FPS))
    n = min(len(pos), int(math.floor(inp.duration * EVAL_FPS)) + 1)
    p = pos[k0:n]
    t0 = k0 / EVAL_FPS
    dur = (len(p) - 1) / EVAL_FPS
    onsets = inp.onsets[(inp.onsets >= t0) & (inp.onsets <= t0 + dur)] - t0
    beats = mm.beat_consistency(onsets, EVAL_FPS, positions=p, joints=[0, 1])
    chance = bc_chance(onsets, p, [0, 1], dur)
    speed = mm.joint_speeds(p, EVAL_FPS).mean(axis=1)
    f0 = inp.f0_hz[int(round(t0 / mm.FRAME_STEP_S)):]
    inten = inp.intensity_db[int(round(t0 / mm.FRAME_STEP_S)):]
    m = min(len(inten), int(math.floor(dur / mm.FRAME_STEP_S)) + 1)
    c = mm.prosody_coupling(speed, EVAL_FPS, inten[:m], f0[:m])
    return {"bc": float(beats.bc), "bc_chance": float(chance),
            "bc_excess": float(beats.bc - chance), "accent_hit_excess": float(c.accent_hit_excess),
            "hand_speed_mean_m_s": float(speed.mean())}


def _arm_torso_groups(model: mujoco.MjModel, robot) -> np.ndarray:
    """Per body: 0 left arm, 1 right arm, 2 trunk (pelvis, waist, torso), -1 other."""
    group = np.full(model.nbody, -1)
    for k, side in enumerate(("left", "right")):
        first = model.joint(robot.arms[side].joints[0]).id
        root = model.jnt_bodyid[first]
        for b in range(model.nbody):
            a = b
            while a > 0 and a != root:
                a = model.body_parentid[a]
            if a == root:
                group[b] = k
    for b in range(model.nbody):
        if group[b] < 0 and model.body_rootid[b] == model.body(robot.pelvis_body).id:
            name = model.body(b).name
            if not any(k in name for k in ("hip", "knee", "ankle", "thigh", "foot")):
                group[b] = 2
    return group


def self_contacts(model: mujoco.MjModel, robot, trace, every: int = 1) -> dict:
    """Arm–trunk and arm–arm contacts with penetration, summed over the trace's rows
    (every ``every``-th row replayed through ``mj_collision``)."""
    d = mujoco.MjData(model)
    group = _arm_torso_groups(model, robot)
    arm_torso = arm_arm = 0
    for qpos in trace.qpos[::every]:
        d.qpos[:] = qpos
        mujoco.mj_kinematics(model, d)
        mujoco.mj_collision(model, d)
        for i in range(d.ncon):
            con = d.contact[i]
            if con.dist >= 0:
                continue
            g = sorted((group[model.geom_bodyid[con.geom1]], group[model.geom_bodyid[con.geom2]]))
            if g == [0, 1]:
                arm_arm += 1
            elif g[1] == 2 and g[0] in (0, 1):
                arm_torso += 1
    return {"arm_torso": arm_torso, "arm_arm": arm_arm}


def robot_physics(pipe, trace) -> dict:
    """The physics figures of one robot run (module docstring)."""
    robot = pipe.body.robot
    sim = pipe.sim
    lo, hi = trace.joint_range[:, 0], trace.joint_range[:, 1]
    used = trace.force_range[:, 1] > trace.force_range[:, 0]      # H1's slot 9 drives nothing
    excess = np.maximum(np.maximum(trace.q - hi, lo - trace.q), 0.0)[:, used]
    sat = (np.abs(trace.act_force) >= 0.999 * trace.force_range[:, 1]) & used
    v_ex = np.where(used, np.maximum(np.abs(trace.qd) - sim.v_max, 0.0).max(axis=0), 0.0)
    phys = physics_metrics(trace).to_dict()
    names = list(trace.joint_names)
    return {
        "fell": bool(phys.get("fell")),
        "assist_impulse_per_s": float(phys.get("assist_impulse_per_s", 0.0)),
        "joint_limit_excess_deg": float(np.degrees(excess.max())),
        "saturation_share": {n: float(s) for n, s, u in zip(names, sat.mean(axis=0), used,
                                                             strict=True) if u},
        "saturation_share_max": float(sat.mean(axis=0).max()),
        "velocity_excess": {n: float(v) for n, v in zip(names, v_ex, strict=True)},
        "velocity_excess_max": float(v_ex.max()),
        "self_contacts": self_contacts(sim.model, robot, trace),
        "foot_skate_mm_s": float(phys.get("foot_skate_mm_s", float("nan"))),
        "torque_peak_share": {n: float(x) for n, x, u in zip(
            names, (np.abs(trace.act_force) / np.maximum(trace.force_range[:, 1], 1e-9)).max(
                axis=0), used, strict=True) if u},
    }


def run_one(body: str, method: str, inp: AudioInput, seed: int, pipe_kwargs: dict | None = None
            ) -> tuple[dict, np.ndarray]:
    """One pipeline run with physics: (figures, hand positions (N, 2, 3) at 30 fps)."""
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method=method, seed=seed, body=body, **(pipe_kwargs or {}))
    result = run_file(pipe, y=inp.samples, sr=16000, name=str(inp.path))
    trace = pipe.trace()
    pos = hand_positions(trace)
    out = {"body": body, "method": method, "audio": inp.name, "seed": seed,
           "duration_s": inp.duration, "wall_s": float(result.wall),
           "realtime_factor": float(inp.duration / max(result.wall, 1e-9))}
    if pipe.body.is_robot:
        out["physics"] = robot_physics(pipe, trace)
        out["cached_steps"] = pipe.to_body.cached_steps
        out["solved_steps"] = pipe.to_body.solved_steps
        out["tracked_steps"] = pipe.to_body.tracked_steps
        out["held_steps"] = pipe.to_body.held_steps
    else:
        phys = physics_metrics(trace).to_dict()
        out["physics"] = {"fell": bool(phys.get("fell")),
                          "foot_skate_mm_s": float(phys.get("foot_skate_mm_s", float("nan")))}
    out.update(sync_scores(pos, inp))
    return out, pos


def bench_robot(bodies: Sequence[str], audio: Sequence[str], seeds: Sequence[int],
                seconds: float | None = None, controls: bool = True,
                on_run: Callable[[dict], None] | None = None) -> dict:
    """Every run of ``bodies`` (the humanoid first if listed) x ``audio`` x ``seeds`` (the
    controller; with ``controls`` also ``random`` and ``mismatched`` on every body), and the
    summaries: per body and method the mean and spread (std over runs) of each figure.
    ``on_run`` is called with each run's row as it is done."""
    inputs = []
    for path in audio:
        inp = load_input(path)
        if seconds is not None and inp.duration > seconds:
            inp = _cut(inp, seconds)
        inputs.append(inp)
    runs = []
    for body in bodies:
        for k, inp in enumerate(inputs):
            for seed in seeds:
                row, pos = run_one(body, "controller", inp, seed)
                runs.append(row)
                if on_run is not None:
                    on_run(row)
                if not controls:
                    continue
                other = inputs[(k + 1) % len(inputs)] if len(inputs) > 1 else rotated(
                    inp, inp.name + "_rotated")
                mis = dict(row, method="mismatched", **sync_scores(pos, other))
                mis["audio"] = f"{inp.name} vs {other.name}"
                runs.append(mis)
                rnd, _ = run_one(body, "random", inp, seed)
                runs.append(rnd)
                if on_run is not None:
                    on_run(mis)
                    on_run(rnd)
    return {"runs": runs, "summary": summarise(runs)}


def _cut(inp: AudioInput, seconds: float) -> AudioInput:
    n = int(seconds * 16000)
    k = int(seconds / mm.FRAME_STEP_S)
    return AudioInput(inp.path, inp.name, inp.samples[:n], inp.f0_hz[:k], inp.intensity_db[:k],
                      inp.onsets[inp.onsets < seconds],
                      accents=None if inp.accents is None else inp.accents[inp.accents < seconds])


def summarise(runs: list[dict]) -> dict:
    """Per ``body/method``: mean and std of the scalar figures and of the physics scalars."""
    out: dict = {}
    keys = ("bc", "bc_chance", "bc_excess", "accent_hit_excess", "hand_speed_mean_m_s",
            "realtime_factor")
    pkeys = ("joint_limit_excess_deg", "saturation_share_max", "velocity_excess_max",
             "foot_skate_mm_s", "assist_impulse_per_s")
    groups: dict[str, list[dict]] = {}
    for r in runs:
        groups.setdefault(f"{r['body']}/{r['method']}", []).append(r)
    for name, rows in groups.items():
        s: dict = {"runs": len(rows)}
        for k in keys:
            v = np.array([r[k] for r in rows if k in r], dtype=float)
            if len(v):
                s[k] = {"mean": float(np.nanmean(v)), "std": float(np.nanstd(v))}
        phys = [r["physics"] for r in rows if "physics" in r]
        s["falls"] = int(sum(bool(p.get("fell")) for p in phys))
        for k in pkeys:
            v = np.array([p[k] for p in phys if k in p], dtype=float)
            if len(v):
                s[k] = {"mean": float(np.nanmean(v)), "max": float(np.nanmax(v))}
        sc = [p["self_contacts"] for p in phys if "self_contacts" in p]
        if sc:
            s["self_contacts"] = {k: int(sum(c[k] for c in sc)) for k in sc[0]}
        sat = [p["saturation_share"] for p in phys if "saturation_share" in p]
        if sat:
            s["saturation_share_per_joint_max"] = {
                j: float(max(x[j] for x in sat)) for j in sat[0]}
        out[name] = s
    return out
