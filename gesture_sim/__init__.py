"""gesture_sim: body language from speech on a physics-simulated MuJoCo humanoid.

Pipeline (see DESIGN.md): audio -> prosody -> inference (CRF belief) -> control (MDP policy)
-> joint targets -> MuJoCo physics -> viewer / video / metrics.
"""

import os
from pathlib import Path

# Headless by default: without a display, MuJoCo renders offscreen through EGL (Mesa or a GPU).
# Must happen before mujoco is imported; an explicit MUJOCO_GL from the user always wins.
if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

__version__ = "0.1.0"

#: Repository root when running from a checkout (assets and the default library live there).
PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent
ASSETS_DIR = REPO_DIR / "assets"
MJCF_DIR = ASSETS_DIR / "mjcf"
LIBRARY_DIR = REPO_DIR / "motion_library"
DEFAULT_LIBRARY_DIR = LIBRARY_DIR / "default"
