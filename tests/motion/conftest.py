"""Shared fixtures of the motion-library tests (real mocap excerpts in tests/data/motion)."""

from __future__ import annotations

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "data" / "motion"


@pytest.fixture(scope="session")
def retargeter():
    from gesture_sim.motion.retarget import Retargeter

    return Retargeter()


@pytest.fixture(scope="session")
def small_library(retargeter):
    """A library of the BEAT2 excerpt and the Bandai wave, built once per session."""
    from gesture_sim.motion.build import build_library

    return build_library(
        [DATA / "2_scott_0_1_1_first10s.npz", DATA / "dataset-2_wave-right-hand_normal_001.bvh"],
        retargeter=retargeter)
