"""Every finger segment of the exports points where the humanoid's does (issue 49).

The humanoid's fingers move (a library clip with every finger joint swept smoothly through
most of its range); each exported finger's three segments (joint 1 -> 2, 2 -> 3, 3 -> its End
Site, read back by the project's BVH reader) are compared with the humanoid's (the finger
bodies' origins, then the fingertip site), in the file's axes. Paths: ``--mixamo`` and
``--to-skeleton`` onto the Mixamo rig (which the ``cmu`` joint map fits, its hand end the
index finger's base). Before: the Mixamo middle finger's first segment 8-19 degrees off (rigid
with the hand), the to-skeleton index finger's 21 (the same), every last segment off by the
humanoid's distal flexion (kept at rest). Tolerance 3 degrees: the aimed first two segments
are exact (measured < 1e-3); the last turns with the humanoid's distal joint from the rig's own
rest shape, which differs from the humanoid's by up to 1.5 degrees.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from gesture_sim.export import FINGER_SEGMENTS
from gesture_sim.export.mixamo import write_mixamo
from gesture_sim.export.skeleton import read_skeleton, write_skeleton
from gesture_sim.motion.bvh import read_bvh
from gesture_sim.sim import humanoid as hm

from .poses import library_qpos

C = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])   # MuJoCo -> BVH axes
_RIG = {"little": "Pinky"}


@pytest.fixture(scope="module")
def model():
    return hm.load_model(scene=False)


@pytest.fixture(scope="module")
def qpos(model):
    """2 s of a library clip, every finger joint swept through 10-90 % of its range."""
    q = library_qpos(model, 30, 60)
    names = list(hm.JOINT_GROUPS["fingers"])
    adr = hm.qpos_addresses(model, names)
    ranges = np.array([model.jnt_range[model.joint(n).id] for n in names])
    t = np.arange(len(q))[:, None] / 30.0
    phase = np.arange(len(names))[None] * 0.7
    u = 0.5 + 0.4 * np.sin(2 * np.pi * 0.6 * t + phase)
    q[:, adr] = ranges[:, 0] + u * (ranges[:, 1] - ranges[:, 0])
    return q


def _humanoid_segments(model, qpos) -> dict[tuple[str, str], np.ndarray]:
    """(side, finger) -> (F, 3, 3) the humanoid's three segment vectors, BVH axes."""
    data = mujoco.MjData(model)
    out: dict[tuple[str, str], list] = {}
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for side in ("left", "right"):
            for finger, segs in FINGER_SEGMENTS.items():
                pts = [data.body(f"{side}_{finger}_{s}").xpos for s in segs]
                pts.append(data.site(f"{side}_{finger}_tip").xpos)
                out.setdefault((side, finger), []).append(C @ np.diff(pts, axis=0).T)
    return {k: np.swapaxes(np.array(v), 1, 2) for k, v in out.items()}


def _worst(path: Path, axes: np.ndarray, hum) -> dict[str, float]:
    """'side finger k' -> the largest angle (deg) over the frames, file vs humanoid."""
    motion = read_bvh(path)
    worst = {}
    for (side, finger), want in hum.items():
        names = [f"mixamorig:{side.capitalize()}Hand{_RIG.get(finger, finger.capitalize())}{k}"
                 for k in (1, 2, 3)]
        idx = [motion.names.index(n) for n in names] + [motion.names.index(names[2] + "_End")]
        for k in range(3):
            got = motion.positions[:, idx[k + 1]] - motion.positions[:, idx[k]]
            w = want[:, k] @ axes.T
            cos = np.sum(got * w, axis=1) / np.linalg.norm(got, axis=1) / np.linalg.norm(w,
                                                                                    axis=1)
            worst[f"{side} {finger} {k + 1}"] = float(np.degrees(np.arccos(np.clip(
                cos, -1.0, 1.0))).max())
    return worst


@pytest.mark.parametrize("path", ["mixamo", "to_skeleton"])
def test_every_finger_segment_follows_the_humanoid(model, qpos, path, tmp_path) -> None:
    mixamo = write_mixamo(tmp_path / "mixamo.bvh", model, qpos)
    axes = np.eye(3)
    if path == "to_skeleton":
        skeleton = read_skeleton(mixamo)
        assert skeleton.family == "cmu"                  # its hand end: the index's base
        mixamo = write_skeleton(tmp_path / "mine.bvh", skeleton, model, qpos)
        axes = skeleton.axes
    worst = _worst(mixamo, axes, _humanoid_segments(model, qpos))
    bad = {k: round(v, 1) for k, v in worst.items() if v >= 3.0}
    assert not bad, bad
    aimed = [v for k, v in worst.items() if not k.endswith("3")]
    assert max(aimed) < 1e-2, max(aimed)
