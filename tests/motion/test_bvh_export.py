"""BVH export of the simulated humanoid: read back, it gives the simulated joint angles."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gesture_sim.app.motion_export import motion_arrays, write_npz
from gesture_sim.app.video import resample_qpos
from gesture_sim.errors import GestureSimError
from gesture_sim.motion.bvh import read_bvh
from gesture_sim.motion.bvh_export import MJ_TO_BVH, bvh_skeleton, bvh_text, write_bvh
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.tracking import HumanoidSim

#: Targets moved during the short simulation (joint, amplitude in rad).
WAVES = (("left_shoulder_flex", 1.4), ("right_shoulder_abduct", 0.9), ("left_elbow_flex", 1.1),
         ("right_forearm_twist", 0.6), ("upper_spine_twist", 0.3), ("neck_bend", 0.3),
         ("head_flex", 0.3), ("right_wrist_flex", 0.7), ("left_wrist_deviate", 0.3),
         ("left_clavicle_elevate", 0.3), ("jaw_open", 0.3), ("right_hip_flex", 0.2))


@pytest.fixture(scope="module")
def simulated():
    """(model, trace, qpos (F, nq) at 30 fps) of 1.2 s of simulated gesturing."""
    sim = HumanoidSim(seed=0)
    sim.reset(settle=0.2)
    t = np.arange(37) / 30.0
    q = np.repeat(sim.standing_pose()[None], len(t), axis=0)
    for name, amp in WAVES:
        q[:, hm.ACTUATED_JOINTS.index(name)] += amp * np.sin(np.pi * t / t[-1]) ** 2
    trace = sim.run(q, rate=30.0)
    qpos = resample_qpos(sim.model, trace.time, trace.qpos, 30.0)
    return sim.model, trace, qpos


@pytest.fixture(scope="module")
def exported(simulated, tmp_path_factory):
    model, _, qpos = simulated
    path = tmp_path_factory.mktemp("bvh") / "motion.bvh"
    write_bvh(path, model, qpos, fps=30.0)
    return path, read_bvh(path)


def _hinge_rotation(model: mujoco.MjModel, body: int, qpos: np.ndarray) -> np.ndarray:
    """The body's hinges composed in XML order, in BVH axes: (3, 3)."""
    r = np.eye(3)
    for j in range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]):
        axis = MJ_TO_BVH @ model.jnt_axis[j]
        r = r @ Rotation.from_rotvec(axis * qpos[model.jnt_qposadr[j]]).as_matrix()
    return r


def test_layout_names_rate_and_units(simulated, exported) -> None:
    model, _, qpos = simulated
    path, motion = exported
    text = path.read_text()
    lines = text.splitlines()
    assert lines[0] == "HIERARCHY" and lines[1] == "ROOT Hips"
    assert f"Frames: {len(qpos)}" in lines and "Frame Time: 0.0333333" in lines
    for name in ("Hips", "Spine", "Spine1", "Neck", "Head", "Jaw", "LeftShoulder", "LeftArm",
                 "LeftForeArm", "LeftHand", "RightUpLeg", "RightLeg", "RightFoot",
                 "RightToeBase"):
        assert name in motion.names
    assert not [n for n in motion.names if "brow" in n.lower() or "eyelid" in n.lower()]
    channel_lines = [ln.split() for ln in lines if ln.strip().startswith("CHANNELS")]
    assert channel_lines[0][1:] == ["6", "Xposition", "Yposition", "Zposition", "Zrotation",
                                    "Xrotation", "Yrotation"]
    for ch in channel_lines[1:]:
        assert ch[1] == "3" and sorted(ch[2:]) == ["Xrotation", "Yrotation", "Zrotation"]
    assert motion.fps == 30.0 and motion.unit_scale == 0.01          # centimetres detected
    assert motion.positions.shape == (len(qpos), len(motion.names), 3)


def test_joint_angles_read_back_within_a_tenth_of_a_degree(simulated, exported) -> None:
    model, _, qpos = simulated
    _, motion = exported
    moved = 0.0
    for joint in bvh_skeleton(model):
        if joint.parent < 0:
            continue
        k = motion.names.index(joint.name)
        local = motion.local_rotations[:, k]
        # composed hinge rotations == the rotation read back
        for f in range(len(qpos)):
            expected = _hinge_rotation(model, joint.body_id, qpos[f])
            err = np.degrees(Rotation.from_matrix(expected.T @ local[f]).magnitude())
            assert err < 0.1, (joint.name, f, err)
        # and per joint: the Euler angles read back are the simulated hinge angles
        order = "".join(c[0] for c in joint.channels)
        angles = Rotation.from_matrix(local).as_euler(order, degrees=True)
        for col, (adr, sign) in enumerate(joint.hinges):
            want = np.degrees(sign * qpos[:, adr]) if adr >= 0 else np.zeros(len(qpos))
            np.testing.assert_allclose(angles[:, col], want, atol=0.1, err_msg=joint.name)
            if adr >= 0:
                moved = max(moved, float(np.ptp(want)))
    assert moved > 45.0   # the test moved joints by a lot, not only around zero


def test_skeleton_matches_mujoco_kinematics(simulated, exported) -> None:
    """Root and every joint: positions within 1 mm, orientations within 0.1 deg of MuJoCo's."""
    model, _, qpos = simulated
    _, motion = exported
    data = mujoco.MjData(model)
    for f in range(len(qpos)):
        data.qpos[:] = qpos[f]
        mujoco.mj_kinematics(model, data)
        for joint in bvh_skeleton(model):
            k = motion.names.index(joint.name)
            np.testing.assert_allclose(motion.positions[f, k],
                                       MJ_TO_BVH @ data.xpos[joint.body_id], atol=1e-3)
            world = MJ_TO_BVH @ data.xmat[joint.body_id].reshape(3, 3) @ MJ_TO_BVH.T
            err = np.degrees(Rotation.from_matrix(world.T @ motion.rotations[f, k]).magnitude())
            assert err < 0.1, (joint.name, f, err)


def test_bodies_off_the_axes_are_decomposed(tmp_path) -> None:
    """A hinge not along a coordinate axis and a ball joint: Euler angles, still exact."""
    model = mujoco.MjModel.from_xml_string("""
    <mujoco><worldbody><body name="pelvis" pos="0 0 1"><freejoint name="root"/>
      <geom size="0.1"/>
      <body name="tilted" pos="0 0.2 0" quat="0.9659 0 0.2588 0">
        <joint name="skew" type="hinge" axis="1 1 0"/><geom size="0.05" pos="0 0 -0.4"/>
        <body name="ball_child" pos="0 0 -0.8"><joint name="ball" type="ball"/>
          <geom size="0.05" pos="0 0 -0.4"/></body></body>
    </body></worldbody></mujoco>""")
    rng = np.random.default_rng(0)
    qpos = np.zeros((5, model.nq))
    qpos[:, 2] = 1.0
    qpos[:, 3:7] = Rotation.random(5, random_state=1).as_quat()[:, [3, 0, 1, 2]]
    qpos[:, 7] = rng.uniform(-1, 1, 5)
    qpos[:, 8:12] = Rotation.random(5, random_state=2).as_quat()[:, [3, 0, 1, 2]]
    skeleton = bvh_skeleton(model)
    assert [j.name for j in skeleton] == ["Hips", "tilted", "ball_child"]
    assert all(not j.hinges for j in skeleton)
    path = write_bvh(tmp_path / "odd.bvh", model, qpos, fps=10.0, unit="m")
    assert "CHANNELS 3 Zrotation Xrotation Yrotation" in path.read_text()
    motion = read_bvh(path, unit_scale=1.0)
    assert motion.fps == 10.0
    data = mujoco.MjData(model)
    for f in range(len(qpos)):
        data.qpos[:] = qpos[f]
        mujoco.mj_kinematics(model, data)
        for j in skeleton:
            k = motion.names.index(j.name)
            world = MJ_TO_BVH @ data.xmat[j.body_id].reshape(3, 3) @ MJ_TO_BVH.T
            err = np.degrees(Rotation.from_matrix(world.T @ motion.rotations[f, k]).magnitude())
            assert err < 0.1
            np.testing.assert_allclose(motion.positions[f, k],
                                       MJ_TO_BVH @ data.xpos[j.body_id], atol=1e-5)


def test_bad_input_is_one_line(simulated, tmp_path) -> None:
    model, _, qpos = simulated
    with pytest.raises(GestureSimError, match="qpos frames"):
        write_bvh(tmp_path / "x.bvh", model, qpos[:, :10])
    with pytest.raises(GestureSimError, match="unit"):
        bvh_text(model, qpos, unit="inch")
    with pytest.raises(GestureSimError, match="frame rate"):
        bvh_text(model, qpos, fps=0.0)
    assert not (tmp_path / "x.bvh").exists()


def test_npz_holds_qpos_times_targets_and_decisions(simulated, tmp_path) -> None:
    model, trace, _ = simulated
    decisions = [{"t": 0.0, "segment_id": 3, "frame": 0, "kind": "start", "clip": "a",
                  "costs": {"fit": 1.5, "smooth": None}},
                 {"t": 0.6, "segment_id": 7, "frame": 12, "kind": "interrupt", "clip": "b",
                  "costs": {}}]
    path = tmp_path / "run.data"          # any name: nothing is appended to it
    write_npz(path, motion_arrays(model, trace, decisions))
    with np.load(path) as d:              # no pickle needed
        assert str(d["format"]) == "gesture_sim.motion_npz"
        np.testing.assert_array_equal(d["qpos"], trace.qpos)
        np.testing.assert_array_equal(d["time"], trace.time)
        assert d["qpos"].shape == (len(trace.time), model.nq)
        assert list(d["qpos_names"][:7]) == ["root_x", "root_y", "root_z", "root_qw", "root_qx",
                                             "root_qy", "root_qz"]
        assert d["qpos_names"][model.jnt_qposadr[model.joint("left_elbow_flex").id]] == \
            "left_elbow_flex"
        assert tuple(d["joint_names"]) == hm.ACTUATED_JOINTS
        np.testing.assert_array_equal(d["q_target"], trace.q_target)
        np.testing.assert_array_equal(d["decision_segment"], [3, 7])
        assert list(d["decision_kind"]) == ["start", "interrupt"]
        assert json.loads(str(d["decisions_json"])) == decisions
