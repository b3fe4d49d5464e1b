"""No Euler channel of any BVH export steps over 90 degrees between frames (issue 49).

The humanoid's motion is smooth (a shipped library clip at 30 fps moves a joint at most ~20
degrees a frame), so a bigger step in a channel is a jump between the two Euler triples of one
rotation (SciPy's principal triple flips by 180 degrees when a middle angle passes 90: the CMU
rig's forearms in the first clip did, at frames 21-217). Paths: ``render --bvh`` (the
humanoid's own skeleton), ``--mixamo`` and ``--to-skeleton`` onto every test skeleton.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.export import mixamo
from gesture_sim.export.skeleton import read_skeleton, skeleton_bvh_text
from gesture_sim.motion import bvh_export
from gesture_sim.motion.bvh import read_bvh
from gesture_sim.sim import humanoid as hm

from .poses import library_qpos

DATA = Path(__file__).resolve().parents[2] / "tests" / "data" / "motion"
SKELETONS = {"cmu": "neutral_16_000.bvh", "pymo23": "AV_8Walk_Meredith_HVHA_Rep1_first240.bvh",
             "mocapbank": "test_mocapbank.bvh", "bandai": "dataset-1_bye_active_001.bvh"}
#: Windows of the shipped library's clip 0 where today's principal triples flip (frames).
WINDOWS = ((0, 240), (500, 560))


@pytest.fixture(scope="module")
def model():
    return hm.load_model(scene=False)


@pytest.fixture(scope="module")
def clips(model):
    q = library_qpos(model, 0, WINDOWS[-1][1])
    return [q[a:b] for a, b in WINDOWS]


def _rotation_steps(text: str, tmp_path: Path) -> tuple[float, str]:
    """The largest frame-to-frame step (deg) of any rotation channel, and where."""
    path = tmp_path / "x.bvh"
    path.write_text(text, encoding="utf-8")
    read_bvh(path)                               # a valid file
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
    steps = np.abs(np.diff(values[:, rot], axis=0)).max(axis=0)
    k = int(np.argmax(steps))
    return float(steps[k]), names[rot[k]]


@pytest.mark.parametrize("path", ["bvh", "mixamo", *SKELETONS])
def test_no_euler_channel_steps_over_90_degrees(model, clips, path, tmp_path) -> None:
    worst = (0.0, "")
    for q in clips:
        if path == "bvh":
            text = bvh_export.bvh_text(model, q)
        elif path == "mixamo":
            text = mixamo.bvh_text(model, q)
        else:
            text = skeleton_bvh_text(read_skeleton(DATA / SKELETONS[path]), model, q)
        worst = max(worst, _rotation_steps(text, tmp_path))
    assert worst[0] < 90.0, worst
