"""The MJCF humanoid honours the shared contract: names, order, frame, signs, mass, physics."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from gesture_sim.sim import humanoid as hm
from gesture_sim.testing.procedural import _FACE_POSE, gesture_stream


@pytest.fixture(scope="module")
def model():
    return hm.load_model()


def _sites(model, q_act):
    data = mujoco.MjData(model)
    data.qpos[:] = hm.qpos_from_targets(model, q_act)
    mujoco.mj_forward(model, data)
    return data


def _with(**values):
    q = np.zeros(len(hm.ACTUATED_JOINTS))
    for name, v in values.items():
        q[hm.actuated_index([name])[0]] = v
    return q


def test_joint_and_actuator_order_is_the_xml_order(model):
    one_dof = [model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] in (2, 3)]
    assert tuple(one_dof) == hm.ACTUATED_JOINTS
    # 49 body joints, the face rig's 16 (lips, mouth corners, inner brows, eyes) and 2 x 20
    # finger joints
    assert len(hm.ACTUATED_JOINTS) == model.nu == 49 + 16 + 40
    assert [model.actuator(a).name for a in range(model.nu)] == list(hm.ACTUATED_JOINTS)
    assert model.joint(0).name == "root" and model.body(model.jnt_bodyid[0]).name == "pelvis"
    for s in ("left", "right"):
        for site in ("hand_site", "wrist_site", "elbow_site", "shoulder_site", "foot_site",
                     "heel_site", "toe_site"):
            assert model.site(f"{s}_{site}").id >= 0
    assert model.site("head_site").id >= 0


def test_addresses_point_at_the_named_joints(model):
    qadr = hm.qpos_addresses(model)
    assert qadr[0] == 7 and len(set(qadr)) == len(qadr)
    data = mujoco.MjData(model)
    data.qpos[hm.qpos_addresses(model, ["left_elbow_flex"])] = 1.0
    assert data.joint("left_elbow_flex").qpos[0] == 1.0


def test_physics_options_and_mass(model):
    assert model.opt.timestep <= 0.002
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert mujoco.mj_getTotalmass(model) == pytest.approx(70.0, abs=1.0)


def test_standing_pose_height_frame_and_contacts(model):
    data = _sites(model, np.zeros(len(hm.ACTUATED_JOINTS)))
    top = max(data.geom_xpos[model.geom(g).id][2] + model.geom(g).size[2]
              for g in ("cranium", "hair"))
    assert top == pytest.approx(1.75, abs=0.03)
    assert data.site("head_site").xpos[0] > 0.05                # faces +x
    assert data.site("left_hand_site").xpos[1] > 0.1 > -0.1 > data.site("right_hand_site").xpos[1]
    for s in ("left", "right"):
        assert data.site(f"{s}_foot_site").xpos[2] == pytest.approx(0.0, abs=1e-6)
        hand, shoulder = data.site(f"{s}_hand_site").xpos, data.site(f"{s}_shoulder_site").xpos
        assert abs(hand[0] - shoulder[0]) < 0.02                 # arms hang straight down
    floor = model.geom("floor").id
    for c in data.contact[: data.ncon]:
        assert floor in (c.geom1, c.geom2), "only the soles may touch anything at rest"


@pytest.mark.parametrize(("joint", "site", "axis", "sign"), [
    ("left_shoulder_flex", "left_hand_site", 0, +1),
    ("right_shoulder_flex", "right_hand_site", 0, +1),
    ("left_shoulder_abduct", "left_hand_site", 1, +1),
    ("right_shoulder_abduct", "right_hand_site", 1, -1),
    ("left_elbow_flex", "left_hand_site", 0, +1),
    ("upper_spine_flex", "head_site", 0, +1),
    ("neck_flex", "head_site", 0, +1),
    ("head_twist", "head_site", 1, +1),
    ("lower_spine_bend", "head_site", 1, +1),
    ("left_hip_flex", "left_foot_site", 0, +1),
    ("right_hip_abduct", "right_foot_site", 1, -1),
    ("left_knee_flex", "left_foot_site", 0, -1),
])
def test_sign_conventions(model, joint, site, axis, sign):
    rest = _sites(model, _with()).site(site).xpos.copy()
    moved = _sites(model, _with(**{joint: 0.5})).site(site).xpos
    assert sign * (moved[axis] - rest[axis]) > 0.02


def test_external_rotation_and_supination_are_mirrored(model):
    bent = {"left_elbow_flex": 1.57, "right_elbow_flex": 1.57}
    rest = _sites(model, _with(**bent))
    turned = _sites(model, _with(**bent, left_shoulder_twist=0.5, right_shoulder_twist=0.5))
    assert turned.site("left_hand_site").xpos[1] > rest.site("left_hand_site").xpos[1] + 0.05
    assert turned.site("right_hand_site").xpos[1] < rest.site("right_hand_site").xpos[1] - 0.05


def test_face_joints_move_face_parts(model):
    rest = _sites(model, _with())
    face = _sites(model, _with(jaw_open=0.3, left_brow_raise=0.01, left_eyelid_close=0.01))
    assert face.body("jaw").xquat @ rest.body("jaw").xquat < 0.999
    assert face.body("left_brow").xpos[2] == pytest.approx(rest.body("left_brow").xpos[2] + 0.01)
    assert face.body("left_eyelid").xpos[2] == pytest.approx(
        rest.body("left_eyelid").xpos[2] - 0.01)


def test_arm_collides_with_torso_but_neighbours_do_not(model):
    pairs = {(model.geom_contype[g], model.geom_conaffinity[g]) for g in
             (model.geom("left_forearm").id, model.geom("chest").id)}
    arm = model.geom("left_forearm").id
    chest = model.geom("abdomen").id
    collide = (model.geom_contype[arm] & model.geom_conaffinity[chest]) or (
        model.geom_contype[chest] & model.geom_conaffinity[arm])
    assert collide and len(pairs) == 2
    thigh, pelvis = model.geom("left_thigh").id, model.geom("abdomen").id
    assert not ((model.geom_contype[thigh] & model.geom_conaffinity[pelvis])
                or (model.geom_contype[pelvis] & model.geom_conaffinity[thigh]))


def test_hand_to_face_pose_reaches_the_chin_without_touching(model):
    q = _with(**{f"left_{k}": v for k, v in _FACE_POSE.items()})
    data = _sites(model, q)
    gap = np.linalg.norm(data.site("left_hand_site").xpos - data.site("head_site").xpos)
    assert gap < 0.2
    hand = model.geom("left_hand").id
    head_geoms = {model.geom(n).id for n in ("cranium", "jaw")}
    for c in data.contact[: data.ncon]:
        assert not ({c.geom1, c.geom2} >= {hand} and {c.geom1, c.geom2} & head_geoms)


def test_procedural_stream_is_seeded_in_range_and_switches():
    a, segs = gesture_stream(10.0, seed=3)
    b, _ = gesture_stream(10.0, seed=3)
    c, _ = gesture_stream(10.0, seed=4)
    np.testing.assert_array_equal(a.q, b.q)
    assert not np.array_equal(a.q, c.q)
    rng = hm.joint_ranges(hm.load_model(scene=False))
    assert np.all(a.q >= rng[:, 0]) and np.all(a.q <= rng[:, 1])
    lengths = [s.length for s in segs]
    assert min(lengths) >= 0.3 and max(lengths) <= 2.0
    assert np.all(a.q[:, hm.actuated_index(hm.LEG_JOINTS)] == 0.0)
    assert np.abs(np.diff(a.q, axis=0)).max() > 0.1         # sudden switches exist
