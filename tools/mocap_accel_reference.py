#!/usr/bin/env python3
"""Peak joint angular accelerations of real motion capture, per joint group (test reference).

For every BVH file given, each joint's rotation relative to its parent is differentiated:
angular velocity ω_t = log(R_tᵀ R_{t+1}) · fps (rad/s, parent frame), smoothed by a centred
moving average of ``--smooth`` seconds (light smoothing against marker noise), then the angular
acceleration |ω̇| (rad/s²) by central differences. Joints are mapped to the humanoid's joint
groups by name (BVH naming of the Bandai Namco and CMU skeletons). Per group the tool reports
the 99th percentile and the maximum over all frames of all files, and writes a small JSON with
the source files named inside.

Usage:
    python tools/mocap_accel_reference.py -o tests/data/physics/mocap_accel_reference.json \
        /path/to/bandai_namco_motion/dataset-1/dataset-1_bye_normal_001.bvh ...
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.fileio import atomic_write_text
from gesture_sim.motion.bvh import read_bvh

#: (group, substrings of BVH joint names, case-insensitive); first match wins.
GROUP_PATTERNS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("clavicle", ("shoulder_", "leftshoulder", "rightshoulder", "lshoulder", "rshoulder",
                  "clavicle", "collar")),
    ("shoulder", ("upperarm", "leftarm", "rightarm", "lhumerus", "rhumerus")),
    ("elbow_forearm", ("lowerarm", "forearm", "radius")),
    ("wrist", ("hand",)),
    ("neck_head", ("neck", "head")),
    ("spine", ("spine", "chest", "lowerback", "upperback", "thorax")),
)


def group_of(name: str) -> str | None:
    """The humanoid joint group a BVH joint name belongs to, or None."""
    low = name.lower()
    if "end" in low or "thumb" in low or "finger" in low or "index" in low:
        return None
    for group, patterns in GROUP_PATTERNS:
        if any(p in low for p in patterns):
            return group
    return None


def joint_accelerations(local_rotations: np.ndarray, fps: float, smooth_s: float
                        ) -> np.ndarray:
    """|angular acceleration| (rad/s²) of one joint, shape (T - 2,) from (T, 3, 3) rotations."""
    rel = Rotation.from_matrix(local_rotations[:-1]).inv() * Rotation.from_matrix(
        local_rotations[1:])
    omega = rel.as_rotvec() * fps
    win = max(int(round(smooth_s * fps)), 1)
    if win > 1:
        kernel = np.ones(win) / win
        omega = np.stack([np.convolve(omega[:, k], kernel, mode="same") for k in range(3)], 1)
        omega = omega[win // 2: len(omega) - win // 2] if len(omega) > win else omega
    acc = np.gradient(omega, 1.0 / fps, axis=0)
    return np.linalg.norm(acc, axis=1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bvh", nargs="+", help="BVH files")
    parser.add_argument("-o", "--output", required=True, help="JSON file to write")
    parser.add_argument("--smooth", type=float, default=0.05,
                        help="moving-average window on angular velocity (s), default 0.05")
    args = parser.parse_args(argv)
    per_group: dict[str, list[np.ndarray]] = {}
    sources = []
    for path in args.bvh:
        motion = read_bvh(path)
        sources.append({"file": Path(path).name, "folder": Path(path).parent.name,
                        "fps": motion.fps, "frames": motion.n_frames})
        for j, name in enumerate(motion.names):
            group = group_of(name)
            if group is None or motion.parents[j] < 0:
                continue
            acc = joint_accelerations(motion.local_rotations[:, j], motion.fps, args.smooth)
            per_group.setdefault(group, []).append(acc)
    result = {
        "description": "peak joint angular accelerations of real motion capture (rad/s^2): "
                       "|d omega/dt| of each joint's rotation relative to its parent, angular "
                       f"velocity smoothed by a {args.smooth:.3f} s moving average",
        "command": "python tools/mocap_accel_reference.py -o <json> " + " ".join(
            Path(p).name for p in args.bvh),
        "smooth_s": args.smooth,
        "groups": {
            g: {"p99": float(np.percentile(np.concatenate(v), 99)),
                "p999": float(np.percentile(np.concatenate(v), 99.9)),
                "max": float(np.concatenate(v).max()), "n_samples": int(sum(map(len, v)))}
            for g, v in sorted(per_group.items())},
        "sources": sources,
    }
    atomic_write_text(args.output, json.dumps(result, indent=1) + "\n")
    for g, r in result["groups"].items():
        print(f"{g:14s} p99 {r['p99']:8.1f}  p99.9 {r['p999']:8.1f}  max {r['max']:8.1f} rad/s^2")
    return 0


if __name__ == "__main__":
    sys.exit(main())
