"""Build the shipped library's frames on a robot once (``motion_library/default/robots/``).

The result is what :func:`gesture_sim.sim.robot_ik.find_library_on_robot` finds, keyed by the
robot's and the library's fingerprints; a changed robot map, model or library needs a rebuild
(or is built into the user cache by ``render --body`` on first use). Usage::

    python tools/build_robot_library.py g1 h1
"""

from __future__ import annotations

import sys

from gesture_sim.motion.library import MotionLibrary
from gesture_sim.sim.bodies import resolve_body
from gesture_sim.sim.robot_ik import retarget_library, shipped_dir


def main() -> None:
    from gesture_sim import DATA_DIR

    lib = MotionLibrary.load(DATA_DIR / "motion_library" / "default")
    for name in sys.argv[1:]:
        robot = resolve_body(name).robot
        _, info = retarget_library(robot, [c.qpos for c in lib.clips], lib.fps,
                                   fingerprint=lib.fingerprint, cache=shipped_dir())
        print(name, info)


if __name__ == "__main__":
    main()
