"""The importer reads the project's own BVH export, and says what a skeleton lacks (issue 49).

* ``render --bvh`` writes the humanoid's own skeleton (Mixamo-style trunk and limb names,
  MuJoCo names for the fingers and face: ``Jaw``, ``left_eye``, ``left_middle_proximal`` ...);
  ``library build`` refused it ("unknown skeleton"). Now its own joint map (``gesture_sim``)
  fits, and a clip read back lands where the humanoid was: elbows within 10 mm RMS (measured
  3 mm), head 15 (9), hands 30 (19: the importer aims the hand site where the file's hand
  points at the middle knuckle, and its palm task).
* A CMU skeleton without arms was refused as "the closest map, bandai" (the first map whose
  trunk names it has); the closest map is now the one that finds most of its joints, and the
  line says what is missing: no arm joints.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.bvh import read_bvh
from gesture_sim.motion.bvh_export import write_bvh
from gesture_sim.motion.retarget import _KEYPOINT_SITES, KEYPOINTS, Retargeter, detect_family
from gesture_sim.sim import humanoid as hm

LIBRARY = Path(__file__).resolve().parents[2] / "motion_library" / "default" / "library.npz"
CMU = Path(__file__).resolve().parents[2] / "tests" / "data" / "motion" / "neutral_16_000.bvh"


def _clip(model, n: int = 90) -> np.ndarray:
    """``n`` frames of the shipped library's clip 30 as qpos rows."""
    import json

    z = np.load(LIBRARY)
    names = json.loads((LIBRARY.parent / "manifest.json").read_text())["joint_names"]
    a = int(z["clip_offsets"][30])
    q = np.zeros((n, model.nq))
    q[:, 0:3], q[:, 3:7] = z["root_pos"][a:a + n], z["root_quat"][a:a + n]
    q[:, hm.qpos_addresses(model, names)] = z["qpos"][a:a + n]
    return q


def _heading(root_pos, root_quat, points):
    from scipy.spatial.transform import Rotation

    fwd = Rotation.from_quat(np.roll(root_quat, -1, axis=1)).as_matrix()[:, :, 0].copy()
    fwd[:, 2] = 0.0
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    left = np.stack([-fwd[:, 1], fwd[:, 0], np.zeros(len(fwd))], axis=1)
    frames = np.stack([fwd, left, np.tile([0.0, 0.0, 1.0], (len(fwd), 1))], axis=1)
    return np.einsum("tab,tkb->tka", frames, points - root_pos[:, None])


def test_the_projects_own_bvh_is_retargeted_back_onto_the_humanoid(tmp_path) -> None:
    model = hm.load_model(scene=False)
    q = _clip(model)
    motion = read_bvh(write_bvh(tmp_path / "own.bvh", model, q))
    assert {"Jaw", "left_eye", "left_middle_proximal"} <= set(motion.names)
    assert detect_family(motion.names) == "gesture_sim"
    result = Retargeter().retarget(motion)
    data = mujoco.MjData(model)
    want = []
    for row in q:
        data.qpos[:] = row
        mujoco.mj_kinematics(model, data)
        want.append([data.site(s).xpos.copy() for s in _KEYPOINT_SITES])
    a = _heading(q[:, :3], q[:, 3:7], np.array(want))
    b = _heading(result.root_pos, result.root_quat, result.keypoints)
    rms = {k: float(np.sqrt(np.mean(np.sum((a[:, i] - b[:, i]) ** 2, axis=-1))))
           for i, k in enumerate(KEYPOINTS)}
    assert max(rms["left_elbow"], rms["right_elbow"]) < 0.010, rms
    assert rms["head"] < 0.015, rms
    assert max(rms["left_hand"], rms["right_hand"]) < 0.030, rms


def test_library_build_reads_the_projects_own_bvh(tmp_path, capsys) -> None:
    from gesture_sim import cli

    model = hm.load_model(scene=False)
    bvh = write_bvh(tmp_path / "own.bvh", model, _clip(model, 150))
    assert cli.main(["library", "build", str(bvh), "-o", str(tmp_path / "lib")]) == 0, \
        capsys.readouterr().err
    assert (tmp_path / "lib" / "library.npz").is_file()


def _armless_cmu(tmp_path: Path) -> Path:
    """The CMU test skeleton with its LeftShoulder and RightShoulder subtrees cut out (one
    frame of zeros)."""
    lines = CMU.read_text(encoding="utf-8").splitlines()
    lines = lines[:lines.index("MOTION")]
    for joint in ("LeftShoulder", "RightShoulder"):
        start = next(i for i, ln in enumerate(lines) if ln.split() == ["JOINT", joint])
        depth = len(lines[start]) - len(lines[start].lstrip())
        end = next(i for i in range(start + 1, len(lines))
                   if lines[i].strip() == "}" and len(lines[i]) - len(lines[i].lstrip()) == depth)
        lines = lines[:start] + lines[end + 1:]
    n = sum(int(ln.split()[1]) for ln in lines if ln.strip().startswith("CHANNELS"))
    path = tmp_path / "armless.bvh"
    path.write_text("\n".join([*lines, "MOTION", "Frames: 1", "Frame Time: 0.0333333",
                               " ".join(["0"] * n)]) + "\n", encoding="utf-8")
    return path


def test_a_skeleton_without_arms_is_told_it_has_no_arm_joints(tmp_path) -> None:
    from gesture_sim.export.skeleton import read_skeleton

    path = _armless_cmu(tmp_path)
    motion = read_bvh(path)
    assert "LeftArm" not in motion.names and "Spine1" in motion.names
    with pytest.raises(GestureSimError) as err:
        detect_family(motion.names)                          # library build, render's import
    msg = str(err.value)
    assert "\n" not in msg and "no arm joints" in msg and "closest map, cmu" in msg, msg
    assert "LeftArm" in msg and "map, bandai" not in msg, msg
    with pytest.raises(GestureSimError) as err:
        read_skeleton(path)                                  # render --to-skeleton
    msg = str(err.value)
    assert "\n" not in msg and "no arm joints" in msg and "closest map, cmu" in msg, msg
    assert str(path) in msg and "the left arm and the right arm" in msg, msg
