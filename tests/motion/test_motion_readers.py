"""BVH and SMPL-X readers: every family imports, FK is right, malformed files fail in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.bvh import read_bvh
from gesture_sim.motion.retarget import detect_family
from gesture_sim.motion.skeleton import resample
from gesture_sim.motion.smplx import SMPLX_JOINTS, SMPLX_PARENTS, read_smplx

DATA = Path(__file__).resolve().parents[1] / "data" / "motion"
BVH_FILES = [  # (file, family, joints including End Sites, fps)
    ("dataset-2_wave-right-hand_normal_001.bvh", "bandai", 27, 30.0),
    ("neutral_16_000.bvh", "cmu", 38, 120.0),
    ("test_mocapbank.bvh", "mocapbank", 24, 30.0),
    ("AV_8Walk_Meredith_HVHA_Rep1_first240.bvh", "pymo23", 30, 120.0),
]


@pytest.mark.parametrize(("name", "family", "n_joints", "fps"), BVH_FILES)
def test_every_bvh_family_imports(name, family, n_joints, fps):
    m = read_bvh(DATA / name)
    assert len(m.names) == n_joints
    assert m.fps == fps
    assert detect_family(m.names) == family
    # Units detected: a standing adult is 1.2-2.1 m tall (whatever the file's unit).
    up = np.argmax(np.ptp(m.positions[0], axis=0))
    height = np.ptp(m.positions[:, :, up], axis=1).max()
    assert 1.2 < height < 2.1
    # Rigid bones: a joint without position channels stays at |offset| from its parent.
    for j in range(1, len(m.names)):
        p = m.parents[j]
        d = np.linalg.norm(m.positions[:, j] - m.positions[:, p], axis=1)
        if family != "bandai":  # bandai has position channels on every joint
            np.testing.assert_allclose(d, np.linalg.norm(m.offsets[j]), atol=1e-6)


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "x.bvh"
    path.write_text(text)
    return path


HEADER = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Arm
  {
    OFFSET 0 1 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
"""


def test_forward_kinematics_follows_the_channel_order(tmp_path):
    frame = [1, 2, 3, 30, 20, 10, 15, 25, 35]
    path = _write(tmp_path, HEADER + "MOTION\nFrames: 1\nFrame Time: 0.008333\n"
                  + " ".join(map(str, frame)) + "\n")
    m = read_bvh(path, unit_scale=1.0)
    assert m.fps == 120.0
    assert m.names == ("Hips", "Arm", "Arm_End")
    r_root = Rotation.from_euler("ZXY", [30, 20, 10], degrees=True).as_matrix()
    r_arm = Rotation.from_euler("XYZ", [15, 25, 35], degrees=True).as_matrix()
    np.testing.assert_allclose(m.positions[0, 0], [1, 2, 3])
    arm = np.array([1, 2, 3]) + r_root @ [0, 1, 0]
    np.testing.assert_allclose(m.positions[0, 1], arm, atol=1e-12)
    np.testing.assert_allclose(m.positions[0, 2], arm + r_root @ r_arm @ [1, 0, 0], atol=1e-12)


@pytest.mark.parametrize(("text", "words"), [
    (HEADER + "MOTION\nFrames: 3\nFrame Time: 0.0333\n" + "0 0 0 0 0 0 0 0 0\n" * 2,
     "truncated motion"),
    (HEADER + "MOTION\nFrames: 2\nFrame Time: 0.0333\n" + "0 0 0 0 0 0 0 0 0\n" * 3,
     "frame count mismatch"),
    (HEADER + "MOTION\nFrames: 2\nFrame Time: 0.0333\n0 0 0 0 0 0 0 0 0\n0 0 0 0 0 0 0 0\n",
     "wrong channel count"),
    (HEADER + "MOTION\nFrames: 1\nFrame Time: 0.0333\n0 0 0 0 zero 0 0 0 0\n", "not a number"),
    (HEADER.replace("HIERARCHY", "HIERARCH") + "MOTION\nFrames: 1\nFrame Time: 0.0333\n"
     + "0 0 0 0 0 0 0 0 0\n", "no HIERARCHY"),
    (HEADER, "no MOTION"),
    (HEADER.replace("CHANNELS 3 Xrotation", "CHANNELS 3 Wrotation") + "MOTION\nFrames: 1\n"
     "Frame Time: 0.0333\n0 0 0 0 0 0 0 0 0\n", "unknown channel"),
    (HEADER.replace("OFFSET 0 1 0", "OFFSET 0 one 0") + "MOTION\nFrames: 1\n"
     "Frame Time: 0.0333\n0 0 0 0 0 0 0 0 0\n", "expected a number"),
    (HEADER[:-2] + "MOTION\nFrames: 1\nFrame Time: 0.0333\n0 0 0 0 0 0 0 0 0\n",
     "end of HIERARCHY"),
])
def test_malformed_bvh_gives_a_one_line_error(tmp_path, text, words):
    with pytest.raises(GestureSimError) as info:
        read_bvh(_write(tmp_path, text))
    message = str(info.value)
    assert words in message
    assert "\n" not in message


def test_missing_file_is_a_user_error(tmp_path):
    with pytest.raises(GestureSimError, match="cannot read"):
        read_bvh(tmp_path / "nope.bvh")


def test_smplx_tree_and_reader():
    assert len(SMPLX_JOINTS) == 55 and len(SMPLX_PARENTS) == 55
    assert all(SMPLX_PARENTS[j] < j for j in range(1, 55))
    assert SMPLX_JOINTS[SMPLX_PARENTS[SMPLX_JOINTS.index("left_wrist")]] == "left_elbow"
    assert SMPLX_JOINTS[SMPLX_PARENTS[SMPLX_JOINTS.index("right_index1")]] == "right_wrist"
    assert SMPLX_JOINTS[SMPLX_PARENTS[SMPLX_JOINTS.index("head")]] == "neck"
    m = read_smplx(DATA / "2_scott_0_1_1_first10s.npz")
    assert m.n_frames == 300 and m.fps == 30.0
    with np.load(DATA / "2_scott_0_1_1_first10s.npz") as raw:
        trans = raw["trans"]
    np.testing.assert_allclose(m.positions[:, 0], trans + m.offsets[0], atol=1e-9)
    for j in range(1, 55):
        d = np.linalg.norm(m.positions[:, j] - m.positions[:, SMPLX_PARENTS[j]], axis=1)
        np.testing.assert_allclose(d, np.linalg.norm(m.offsets[j]), atol=1e-6)
    # Y up: the head is above the pelvis, which is above the ankles.
    y = m.positions[:, :, 1]
    assert np.all(y[:, SMPLX_JOINTS.index("head")] > y[:, 0])
    assert np.all(y[:, 0] > y[:, SMPLX_JOINTS.index("left_ankle")])


def test_smplx_malformed(tmp_path):
    path = tmp_path / "bad.npz"
    np.savez(path, poses=np.zeros((5, 165)), mocap_frame_rate=30)
    with pytest.raises(GestureSimError, match="'trans'"):
        read_smplx(path)
    np.savez(path, poses=np.zeros((5, 99)), trans=np.zeros((5, 3)), mocap_frame_rate=30)
    with pytest.raises(GestureSimError, match="expected"):
        read_smplx(path)


def test_resample_120_to_30_keeps_time():
    m = read_bvh(DATA / "neutral_16_000.bvh")
    r = resample(m, 30.0)
    assert r.fps == 30.0
    assert r.n_frames == (m.n_frames - 1) // 4 + 1
    np.testing.assert_allclose(r.positions[1], m.positions[4], atol=1e-9)
    np.testing.assert_allclose(r.rotations[2], m.rotations[8], atol=1e-9)
