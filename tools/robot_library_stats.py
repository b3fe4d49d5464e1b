"""How well the default library sits on a robot: hand errors, limits, speeds of the built frames.

For every 5th frame of every clip the hand's distance from its scaled target is measured at the
built robot frame (no solver step), and over all built frames the joint-limit violations and the
joint speeds (frame to frame). Usage::

    python tools/robot_library_stats.py g1 h1
"""

from __future__ import annotations

import sys

import numpy as np

from gesture_sim import DATA_DIR
from gesture_sim.motion.library import MotionLibrary
from gesture_sim.sim.bodies import resolve_body
from gesture_sim.sim.robot_ik import RobotRetarget, find_library_on_robot


def main() -> None:
    lib = MotionLibrary.load(DATA_DIR / "motion_library" / "default")
    for name in sys.argv[1:]:
        robot = resolve_body(name).robot
        rt = RobotRetarget(robot)
        built = find_library_on_robot(robot, lib)
        if built is None:
            print(f"{name}: not built (python tools/build_robot_library.py {name})")
            continue
        clips_h, clips_r = built
        errs = []
        for qh, qr in zip(clips_h, clips_r, strict=True):
            for f in range(0, len(qh), 5):
                rt.solve(qh[f].astype(float), q_prev=qr[f].astype(float), iterations=0)
                errs.append(rt.hand_error)
        e = np.array(errs)
        frames = np.concatenate(clips_r)
        lo, hi = rt.joint_range.T
        outside = int(((frames < lo - 1e-6) | (frames > hi + 1e-6)).sum())
        speed = np.concatenate([np.abs(np.diff(r, axis=0)) * lib.fps for r in clips_r
                                if len(r) > 1])
        print(f"{name}: {len(frames)} frames ({len(e)} sampled); hand error median "
              f"{1000 * np.median(e):.1f} mm, p90 {1000 * np.percentile(e, 90):.1f}, p99 "
              f"{1000 * np.percentile(e, 99):.1f}, max {1000 * e.max():.0f} mm; > 4 cm "
              f"{100 * (e > 0.04).mean():.2f} %; outside the joint limits {outside}; joint speed "
              f"max {speed.max():.2f} rad/s")


if __name__ == "__main__":
    main()
