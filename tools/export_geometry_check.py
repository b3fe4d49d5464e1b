#!/usr/bin/env python3
"""Measure the BVH exports' geometry on the shipped library's clips (issue 49's figures).

Three measurements, each over the clips chosen (``--clips``, default all 70 of
``motion_library/default``):

* ``euler``: the largest frame-to-frame step (deg) of any rotation channel of every BVH path:
  ``render --bvh`` (the humanoid's skeleton), ``--mixamo`` and ``--to-skeleton`` onto the
  test skeletons (CMU, Bandai, MocapBank, PyMO's 23 joints), with the joint, the channel and
  the clip where it is largest, and how many clips step over 90 degrees.
* ``fingers``: per finger segment, the largest angle (deg) between the exported segment (read
  back by the project's BVH reader) and the humanoid's, with every finger joint swept through
  10-90 % of its range (``tests/export/test_finger_segments.py``'s motion), on ``--mixamo`` and
  on ``--to-skeleton`` onto the Mixamo rig.
* ``upright``: for each test skeleton, its detected up axis and the median pelvis and head
  heights (m) of the source file and of the export along it.

Example (from the repository root; ``--json`` for machine-readable output)::

    .venv/bin/python tools/export_geometry_check.py euler fingers upright
    .venv/bin/python tools/export_geometry_check.py euler --clips 0 31 33
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import mujoco
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gesture_sim.export import FINGER_SEGMENTS  # noqa: E402
from gesture_sim.export import mixamo as mixamo_export  # noqa: E402
from gesture_sim.export.skeleton import read_skeleton, skeleton_bvh_text  # noqa: E402
from gesture_sim.motion import bvh_export  # noqa: E402
from gesture_sim.motion.bvh import read_bvh  # noqa: E402
from gesture_sim.sim import humanoid as hm  # noqa: E402

DATA = REPO / "tests" / "data" / "motion"
LIBRARY = REPO / "motion_library" / "default"
SKELETONS = {"cmu": "neutral_16_000.bvh", "bandai": "dataset-1_bye_active_001.bvh",
             "mocapbank": "test_mocapbank.bvh",
             "pymo23": "AV_8Walk_Meredith_HVHA_Rep1_first240.bvh"}
C = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])   # MuJoCo -> BVH axes


def clip_qpos(model, clip: int, start: int = 0, n: int | None = None) -> np.ndarray:
    """Frames of a shipped library clip as full qpos rows (30 fps)."""
    z = np.load(LIBRARY / "library.npz")
    names = json.loads((LIBRARY / "manifest.json").read_text())["joint_names"]
    a, b = int(z["clip_offsets"][clip]), int(z["clip_offsets"][clip + 1])
    a += start
    b = b if n is None else min(b, a + n)
    q = np.zeros((b - a, model.nq))
    q[:, 0:3], q[:, 3:7] = z["root_pos"][a:b], z["root_quat"][a:b]
    q[:, hm.qpos_addresses(model, names)] = z["qpos"][a:b]
    return q


def rotation_steps(text: str) -> tuple[float, str]:
    """The largest frame-to-frame step (deg) of any rotation channel of a BVH text, and where."""
    lines = text.splitlines()
    start = lines.index("MOTION") + 3
    values = np.array([[float(x) for x in ln.split()] for ln in lines[start:]])
    names, joint = [], ""
    for ln in lines[:start - 3]:
        tok = ln.split()
        if tok and tok[0] in ("ROOT", "JOINT"):
            joint = tok[1]
        elif tok and tok[0] == "CHANNELS":
            names += [f"{joint} {c}" for c in tok[2:]]
    rot = [k for k, n in enumerate(names) if n.endswith("rotation")]
    if len(values) < 2:
        return 0.0, ""
    steps = np.abs(np.diff(values[:, rot], axis=0)).max(axis=0)
    k = int(np.argmax(steps))
    return float(steps[k]), names[rot[k]]


def euler(model, clips: list[int]) -> dict:
    skeletons = {k: read_skeleton(DATA / v) for k, v in SKELETONS.items()}
    out: dict[str, dict] = {}
    for c in clips:
        q = clip_qpos(model, c)
        texts = {"bvh": bvh_export.bvh_text(model, q), "mixamo": mixamo_export.bvh_text(model, q)}
        texts |= {f"to-skeleton {k}": skeleton_bvh_text(s, model, q)
                  for k, s in skeletons.items()}
        for path, text in texts.items():
            step, where = rotation_steps(text)
            row = out.setdefault(path, {"max_step_deg": 0.0, "where": "", "clip": -1,
                                        "clips_over_90": 0, "frames": 0})
            row["frames"] += len(q)
            row["clips_over_90"] += int(step > 90.0)
            if step > row["max_step_deg"]:
                row.update(max_step_deg=round(step, 2), where=where, clip=c)
        print(f"euler: clip {c} done", file=sys.stderr, flush=True)
    return out


def finger_qpos(model) -> np.ndarray:
    """2 s of clip 30 with every finger joint swept through 10-90 % of its range."""
    q = clip_qpos(model, 30, 0, 60)
    names = list(hm.JOINT_GROUPS["fingers"])
    adr = hm.qpos_addresses(model, names)
    ranges = np.array([model.jnt_range[model.joint(n).id] for n in names])
    t = np.arange(len(q))[:, None] / 30.0
    u = 0.5 + 0.4 * np.sin(2 * np.pi * 0.6 * t + np.arange(len(names))[None] * 0.7)
    q[:, adr] = ranges[:, 0] + u * (ranges[:, 1] - ranges[:, 0])
    return q


def fingers(model) -> dict:
    q = finger_qpos(model)
    data = mujoco.MjData(model)
    hum: dict[tuple[str, str], list] = {}
    for row in q:
        data.qpos[:] = row
        mujoco.mj_kinematics(model, data)
        for side in ("left", "right"):
            for finger, segs in FINGER_SEGMENTS.items():
                pts = [data.body(f"{side}_{finger}_{s}").xpos for s in segs]
                pts.append(data.site(f"{side}_{finger}_tip").xpos)
                hum.setdefault((side, finger), []).append(C @ np.diff(pts, axis=0).T)
    rig_name = {"little": "Pinky"}
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        mix = Path(tmp) / "mixamo.bvh"
        mixamo_export.write_mixamo(mix, model, q)
        skeleton = read_skeleton(mix)
        mine = Path(tmp) / "mine.bvh"
        mine.write_text(skeleton_bvh_text(skeleton, model, q), encoding="utf-8")
        for label, path, axes in (("mixamo", mix, np.eye(3)),
                                  (f"to-skeleton mixamo rig ({skeleton.family} map)", mine,
                                   skeleton.axes)):
            motion = read_bvh(path)
            table = {}
            for (side, finger), want in hum.items():
                want = np.swapaxes(np.array(want), 1, 2)
                names = [f"mixamorig:{side.capitalize()}Hand"
                         f"{rig_name.get(finger, finger.capitalize())}{k}" for k in (1, 2, 3)]
                idx = [motion.names.index(n) for n in names]
                idx.append(motion.names.index(names[2] + "_End"))
                for k in range(3):
                    got = motion.positions[:, idx[k + 1]] - motion.positions[:, idx[k]]
                    w = want[:, k] @ axes.T
                    cos = np.sum(got * w, 1) / np.linalg.norm(got, axis=1) / np.linalg.norm(
                        w, axis=1)
                    deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
                    table[f"{side} {finger} {k + 1}"] = {
                        "median_deg": round(float(np.median(deg)), 3),
                        "max_deg": round(float(deg.max()), 3)}
            out[label] = table
    return out


def upright(model) -> dict:
    from gesture_sim.export.skeleton import write_skeleton

    q = clip_qpos(model, 30, 0, 60)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, file in SKELETONS.items():
            skeleton = read_skeleton(DATA / file)
            up = int(np.argmax(np.abs(skeleton.axes[:, 1])))
            src = read_bvh(DATA / file)
            exported = read_bvh(write_skeleton(Path(tmp) / "o.bvh", skeleton, model, q))
            row = {"up_axis": "XYZ"[up]}
            for key in ("pelvis", "head"):
                j = skeleton.points[key]
                row[f"{key}_source_m"] = round(float(np.median(src.positions[:, j, up])), 3)
                row[f"{key}_export_m"] = round(float(np.median(exported.positions[:, j, up])),
                                               3)
            out[name] = row
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", nargs="+", choices=("euler", "fingers", "upright"))
    parser.add_argument("--clips", type=int, nargs="*", default=None,
                        help="library clips for `euler` (default: all)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    model = hm.load_model(scene=False)
    n_clips = len(np.load(LIBRARY / "library.npz")["clip_offsets"]) - 1
    result = {}
    if "euler" in args.what:
        result["euler"] = euler(model, args.clips if args.clips else list(range(n_clips)))
    if "fingers" in args.what:
        result["fingers"] = fingers(model)
    if "upright" in args.what:
        result["upright"] = upright(model)
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    for section, table in result.items():
        print(f"== {section}")
        for key, row in table.items():
            if section == "fingers":
                worst = max(row.items(), key=lambda kv: kv[1]["max_deg"])
                print(f"  {key}: worst segment {worst[0]} {worst[1]}; every segment max "
                      f"{max(v['max_deg'] for v in row.values()):.3f} deg")
            else:
                print(f"  {key}: {row}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
