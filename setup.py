"""Build hook: ship the humanoid, the example speech and the default library inside the wheel.

Everything else about the package is declared in ``pyproject.toml``. The data live at the top of
the source tree (``assets/``, ``motion_library/default/``) so that tools, tests and a checkout
use them in place; a regular (non-editable) build copies them into ``gesture_sim/_data/``, where
:mod:`gesture_sim` finds them once installed (see ``gesture_sim.DATA_DIR``). An editable
install copies nothing: the package then finds the tree beside it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
#: Source-tree folders copied under ``gesture_sim/_data/`` (same relative paths).
DATA_TREES = ("assets/mjcf", "assets/audio", "assets/robots", "motion_library/default")


class BuildPyWithData(build_py):
    """``build_py`` that also copies :data:`DATA_TREES` into the built package."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        dest_root = Path(self.build_lib) / "gesture_sim" / "_data"
        for rel in DATA_TREES:
            src = ROOT / rel
            if not src.is_dir():
                raise FileNotFoundError(f"package data folder missing: {src}")
            dest = dest_root / rel
            if dest.exists():
                shutil.rmtree(dest)
            shutil.copytree(src, dest, ignore=shutil.ignore_patterns("__pycache__", ".*"))


setup(cmdclass={"build_py": BuildPyWithData})
