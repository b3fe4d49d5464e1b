"""Retargeting onto the humanoid: error bound, joint limits, feet on the floor, a wave is a wave."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.build import read_motion
from gesture_sim.motion.retarget import KEYPOINTS, detect_family, heading_frame
from gesture_sim.motion.skeleton import resample

DATA = Path(__file__).resolve().parents[1] / "data" / "motion"
FILES = ["dataset-2_wave-right-hand_normal_001.bvh", "dataset-1_bye_active_001.bvh",
         "neutral_16_000.bvh", "test_mocapbank.bvh", "AV_8Walk_Meredith_HVHA_Rep1_first240.bvh",
         "2_scott_0_1_1_first10s.npz"]
GESTURE_FILES = FILES[:2] + FILES[-1:]


@pytest.fixture(scope="module")
def results(retargeter):
    out = {}
    for name in FILES:
        motion = resample(read_motion(DATA / name, retargeter.model), 30.0)
        out[name] = (motion, retargeter.retarget(motion))
    return out


def _replay(rt, res):
    """Kinematic replay: (T, n_sites) z of the foot sites and the qpos of the limited joints."""
    m, d = rt.model, mujoco.MjData(rt.model)
    sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{s}_{p}_site")
             for s in ("left", "right") for p in ("heel", "toe", "foot")]
    feet = []
    for t in range(len(res.qpos)):
        d.qpos[:3] = res.root_pos[t]
        d.qpos[3:7] = res.root_quat[t]
        d.qpos[rt.qadr] = res.qpos[t]
        mujoco.mj_kinematics(m, d)
        feet.append(d.site_xpos[sites, 2].copy())
    return np.array(feet)


@pytest.mark.parametrize("name", FILES)
def test_retarget_error_below_ten_percent_of_arm_length(results, name):
    _, res = results[name]
    assert res.error < 0.10
    if name in GESTURE_FILES:
        assert res.error_p95 < 0.10


@pytest.mark.parametrize("name", FILES)
def test_replay_respects_joint_limits_and_keeps_feet_on_the_floor(retargeter, results, name):
    rt = retargeter
    _, res = results[name]
    lo, hi = rt.range[:, 0], rt.range[:, 1]
    q = res.qpos.astype(float)
    tol = 1e-4  # float32 storage
    assert np.all(q[:, rt.limited] >= lo[rt.limited] - tol)
    assert np.all(q[:, rt.limited] <= hi[rt.limited] + tol)
    lowest = _replay(rt, res).min(axis=1)
    assert abs(lowest.mean()) < 0.01
    assert lowest.min() > -0.03
    # Facing +x at the start: the pelvis's forward axis projects onto +x.
    fwd = Rotation.from_quat(np.roll(res.root_quat[0], -1)).as_matrix()[:2, 0]
    assert fwd[0] / np.linalg.norm(fwd) > 0.999


def test_a_wave_is_a_wave(results):
    motion, res = results["dataset-2_wave-right-hand_normal_001.bvh"]
    kp = heading_frame(res.root_pos, res.root_quat, res.keypoints)
    rh, lh, head = (kp[:, KEYPOINTS.index(k)] for k in ("right_hand", "left_hand", "head"))
    raised = rh[:, 2] > head[:, 2] - 0.05
    assert raised.mean() > 0.4                          # the right hand is up, near the head
    assert np.all(lh[:, 2] < head[:, 2] - 0.4)          # the left hand stays down
    assert np.all(rh[raised, 1] < 0.1)                  # on the body's right side (y < 0 is right)
    # While raised, the hand swings side to side several times.
    y = rh[raised, 1]
    swings = np.sum(np.diff(np.sign(np.diff(y[::3]))) != 0)
    assert swings >= 4


def test_unknown_skeleton_is_refused():
    with pytest.raises(GestureSimError, match="unknown skeleton"):
        detect_family(("root", "a", "b"))


def test_mixamo_prefix_is_ignored():
    names = ["mixamorig:" + n for n in (
        "Hips", "Neck", "Head", "Spine2", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandMiddle1",
        "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightArm", "RightForeArm",
        "RightHand", "RightHandMiddle1", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase")]
    assert detect_family(names) == "mixamo"
