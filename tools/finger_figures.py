#!/usr/bin/env python3
"""Figures of the humanoid's fingers: a contact sheet of hand shapes, finger tracking on the
BEAT2 take, and the physics speed cost of the fingers.

* ``sheet``: renders the right hand (human look, raised in front of the chest) in the shapes of
  :data:`gesture_sim.signals.hands.SHAPES` (fist, point, open spread hand, relaxed hand) from
  the back and the thumb side, into one PNG (default ``docs/figures/hands.png``).
* ``track``: the take's SMPL-X finger pose (``poses``, 30 finger joints) mapped to the finger
  joints (:func:`gesture_sim.motion.finger_tracks.smplx_finger_targets`), played as targets through
  the physics (:class:`~gesture_sim.sim.tracking.HumanoidSim`, standing, every other joint at
  the standing pose, so the hands hang at rest); reports the tracking error (deg RMS of the
  simulated finger joints against the targets, per finger and overall, after a settling
  second), the share of target samples the joint ranges clamp, and the take's own finger
  motion (SD over time per joint, deg, of the mapped, unclamped angles).
* ``speed``: ``mj_step`` rate (steps/s) of the standing humanoid, 2000 steps, for this model
  and, with ``--before``, an older humanoid.xml (e.g. ``git show HEAD:assets/mjcf/humanoid.xml
  > /tmp/old.xml``), interleaved in the same run.

Usage (repository root; ``MUJOCO_GL=egl`` for ``sheet``)::

    .venv/bin/python tools/finger_figures.py sheet [-o docs/figures/hands.png]
    .venv/bin/python tools/finger_figures.py track [--npz TAKE.npz]
    .venv/bin/python tools/finger_figures.py speed --before /tmp/old.xml
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import mujoco  # noqa: E402

from gesture_sim.motion import finger_tracks  # noqa: E402
from gesture_sim.signals import hands  # noqa: E402
from gesture_sim.sim import humanoid as hm  # noqa: E402

#: The arm pose of the sheet (deg): the right hand raised in front of the chest, the palm
#: turned towards the viewer's side.
SHEET_ARM_DEG = {"right_shoulder_flex": 45.0, "right_elbow_flex": 70.0,
                 "right_forearm_twist": -60.0, "right_shoulder_twist": 0.0}


def pose_q(shape: dict[str, float], arm: dict[str, float] | None = None) -> np.ndarray:
    """Actuated joint values (n_act,) (rad): both hands in ``shape`` (deg from straight), the
    arm joints of ``arm`` (deg), the rest of the body standing (0)."""
    q = np.zeros(len(hm.ACTUATED_JOINTS))
    q[hm.actuated_index(hm.FINGER_JOINTS)] = hands.both_hands_q(shape)
    for j, v in (arm or {}).items():
        q[hm.actuated_index([j])] = np.radians(v)
    return q


def sheet(out: Path, size: int = 260) -> None:
    """Render the hand shapes (columns) from the back and the thumb side (rows) into ``out``."""
    from PIL import Image

    model = hm.load_model(look="human")
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, size, size)
    names = ("fist", "point", "spread", "relaxed")
    rows = []
    for azimuth in (90.0, 270.0):
        tiles = []
        for name in names:
            data.qpos[:] = hm.qpos_from_targets(model, pose_q(hands.SHAPES[name], SHEET_ARM_DEG))
            mujoco.mj_forward(model, data)
            hand = data.xpos[model.body("right_hand").id]
            tip = data.site_xpos[model.site("right_middle_tip").id]
            cam = mujoco.MjvCamera()
            cam.lookat[:] = 0.5 * (hand + tip)
            cam.distance, cam.azimuth, cam.elevation = 0.3, azimuth, -15.0
            renderer.update_scene(data, cam)
            tiles.append(renderer.render())
        rows.append(np.concatenate(tiles, axis=1))
    img = np.concatenate(rows, axis=0)
    out.parent.mkdir(parents=True, exist_ok=True)
    small = Image.fromarray(img).quantize(colors=192, method=Image.Quantize.MEDIANCUT)
    small.save(out, optimize=True)
    print(f"{out}: columns {', '.join(names)}; rows the back, the thumb side")


def track(npz: Path, settle_s: float = 1.0) -> dict:
    """Finger tracking of the take's SMPL-X finger motion through the physics (see the module
    docstring); returns the figures (deg)."""
    from gesture_sim.sim.tracking import HumanoidSim

    take = np.load(npz)
    fps = float(take["mocap_frame_rate"])
    model = hm.load_model(look="mannequin")
    targets, raw = finger_tracks.smplx_finger_targets(take["poses"], model)
    cols = hm.actuated_index(hm.FINGER_JOINTS)
    sim = HumanoidSim(model, seed=0)
    sim.reset(settle=0.6)
    n_sub = sim.control_every
    rate = 1.0 / (model.opt.timestep * n_sub)             # control updates per second
    times = np.arange(int(len(targets) / fps * rate)) / rate
    q_ref = np.stack([np.interp(times, np.arange(len(targets)) / fps, targets[:, k])
                      for k in range(targets.shape[1])], axis=1)
    qd_ref = np.gradient(q_ref, 1.0 / rate, axis=0)
    sim_q = np.zeros_like(q_ref)
    q = sim.standing_pose()
    qd = np.zeros_like(q)
    t0 = time.perf_counter()
    for i in range(len(times)):
        q[cols], qd[cols] = q_ref[i], qd_ref[i]
        sim.step(q, qd, n_substeps=n_sub)
        sim_q[i] = sim.q[cols]
    wall = time.perf_counter() - t0
    keep = times >= settle_s
    err = np.degrees(sim_q[keep] - q_ref[keep])
    finite = bool(np.isfinite(sim_q).all())
    by_finger = hands.per_finger(err)
    sd = np.degrees(raw.std(axis=0))
    out = {
        "take": npz.name, "seconds": float(times[-1]), "finite": finite,
        "sim_wall_s": round(wall, 1),
        "rms_deg": round(float(np.sqrt(np.mean(err ** 2))), 2),
        "rms_deg_per_finger": {f: round(float(np.sqrt(np.mean(e ** 2))), 2)
                               for f, e in by_finger.items()},
        "p95_abs_deg": round(float(np.percentile(np.abs(err), 95)), 2),
        "max_abs_deg": round(float(np.abs(err).max()), 1),
        "clamped_share": round(float((np.abs(targets - raw) > 1e-9).mean()), 3),
        "take_sd_deg_mean": round(float(sd.mean()), 2),
        "take_sd_deg_per_joint": {j: round(float(s), 1) for j, s in zip(hm.FINGER_JOINTS, sd,
                                                                       strict=True)},
        "target_sd_deg_mean": round(float(np.degrees(targets.std(axis=0)).mean()), 2),
    }
    return out


#: MuJoCo's timers reported by ``speed`` (seconds per step, from ``data.timer``).
_TIMERS = ("mjTIMER_POS_KINEMATICS", "mjTIMER_POS_INERTIA", "mjTIMER_POS_COLLISION",
           "mjTIMER_POS_MAKE", "mjTIMER_POS_PROJECT", "mjTIMER_VELOCITY", "mjTIMER_ACTUATION",
           "mjTIMER_CONSTRAINT")


def _scene(humanoid_xml: Path) -> mujoco.MjModel:
    """The scene (floor, lights) around ``humanoid_xml``, compiled (the mannequin look)."""
    import shutil
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        shutil.copy(humanoid_xml, Path(tmp) / "humanoid.xml")
        shutil.copy(hm.SCENE_XML, Path(tmp) / "scene.xml")
        return mujoco.MjModel.from_xml_path(str(Path(tmp) / "scene.xml"))


def _rate(model: mujoco.MjModel, steps: int) -> tuple[float, dict[str, float]]:
    """Steps per second of ``model`` standing (root at ROOT_HEIGHT, soles on the floor, every
    position target 0: the standing pose) over ``steps`` steps after 200 to settle; and the
    mean time per step of MuJoCo's stages (us)."""
    data = mujoco.MjData(model)
    data.qpos[:7] = hm.root_qpos()
    data.ctrl[:] = 0.0
    mujoco.mj_forward(model, data)
    for _ in range(200):
        mujoco.mj_step(model, data)
    mujoco.mj_resetData(model, data)
    data.qpos[:7] = hm.root_qpos()
    for _ in range(200):
        mujoco.mj_step(model, data)
    for k in range(len(data.timer)):
        data.timer[k].duration, data.timer[k].number = 0.0, 0
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    rate = steps / (time.perf_counter() - t0)
    stages = {name[8:].lower(): 1e6 * data.timer[int(getattr(mujoco.mjtTimer, name))].duration
              / steps for name in _TIMERS}
    if not np.isfinite(data.qpos).all() or data.qpos[2] < 0.8:
        raise SystemExit("the body fell in the speed run")
    return rate, stages


def speed(before: Path | None, steps: int = 2000, repeats: int = 5) -> dict:
    """mj_step rate (steps/s, median of ``repeats`` runs of ``steps``) of the standing humanoid
    in the scene, this model and ``before`` (an older humanoid.xml), interleaved; with the
    models' sizes and MuJoCo's per-stage times (us per step, of the last run)."""
    paths = {"after": hm.HUMANOID_XML}
    if before is not None:
        paths = {"before": before, **paths}
    models = {k: _scene(p) for k, p in paths.items()}
    rates: dict[str, list[float]] = {k: [] for k in paths}
    stages: dict[str, dict[str, float]] = {}
    for _ in range(repeats):
        for k, m in models.items():
            r, stages[k] = _rate(m, steps)
            rates[k].append(r)
    out = {}
    for k, m in models.items():
        out[k] = {"steps_per_s_median": round(float(np.median(rates[k]))),
                  "runs": [round(x) for x in rates[k]],
                  "nq": int(m.nq), "nv": int(m.nv), "nu": int(m.nu), "nbody": int(m.nbody),
                  "us_per_step": {s: round(v, 1) for s, v in stages[k].items()}}
    if before is not None:
        out["slowdown"] = round(out["before"]["steps_per_s_median"]
                                / out["after"]["steps_per_s_median"], 2)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("sheet")
    p.add_argument("-o", "--output", type=Path, default=ROOT / "docs/figures/hands.png")
    p.add_argument("--size", type=int, default=260, help="tile size (px)")
    p = sub.add_parser("track")
    p.add_argument("--npz", type=Path, required=True,
                   help="an SMPL-X take with hand pose (e.g. BEAT2's 2_scott_0_1_1.npz)")
    p = sub.add_parser("speed")
    p.add_argument("--before", type=Path, default=None)
    p.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args(argv)
    if args.cmd == "sheet":
        sheet(args.output, args.size)
    elif args.cmd == "track":
        print(json.dumps(track(args.npz), indent=1))
    else:
        print(json.dumps(speed(args.before, args.steps), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
