"""FBX / GLB export through Blender (``gesture_sim.export.blender``).

The round-trip tests need Blender's ``bpy`` (the optional ``blender`` extra) and skip without
it; ``test_require_bpy_without_bpy`` runs everywhere.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError

FPS = 30.0
N_FRAMES = 7
MID = N_FRAMES // 2
#: Bones whose world heads are compared with the MuJoCo bodies.
CHECK_BONES = ("pelvis", "head", "right_upper_arm", "right_forearm", "right_hand", "left_hand",
               "right_foot", "left_toes")


def test_require_bpy_without_bpy(monkeypatch):
    from gesture_sim.export import blender

    monkeypatch.setitem(sys.modules, "bpy", None)      # `import bpy` now raises ImportError
    with pytest.raises(GestureSimError) as info:
        blender.require_bpy()
    assert str(info.value) == blender.BLENDER_EXTRA_HINT
    assert "gesture-sim[blender]" in str(info.value)
    with pytest.raises(GestureSimError, match="gesture-sim\\[blender\\]"):
        blender.write_scene("unused.fbx", None, np.zeros((1, 1)), FPS, "fbx")


def test_unknown_format_is_one_line_error():
    from gesture_sim.export import blender

    with pytest.raises(GestureSimError, match="unknown scene format"):
        blender.write_scene("unused.obj", None, np.zeros((1, 1)), FPS, "obj")


@pytest.fixture(scope="module")
def model():
    from gesture_sim.sim.humanoid import load_model

    return load_model(scene=False, look="human")


@pytest.fixture(scope="module")
def motion(model):
    """(N_FRAMES, nq): the right arm rising forward with the elbow bending, the left arm out to
    the side, the body walking forward and turning 30 degrees about the vertical."""
    from gesture_sim.sim.humanoid import qpos_addresses

    s = np.linspace(0.0, 1.0, N_FRAMES)
    qpos = np.tile(model.qpos0, (N_FRAMES, 1))
    adr = qpos_addresses(model, ["right_shoulder_flex", "right_elbow_flex",
                                 "left_shoulder_abduct", "neck_twist"])
    qpos[:, adr[0]] = 1.4 * s
    qpos[:, adr[1]] = 0.9 * s
    qpos[:, adr[2]] = 0.8 * s
    qpos[:, adr[3]] = 0.3 * s
    qpos[:, 0] = 0.2 * s
    yaw = np.radians(30.0) * s
    qpos[:, 3] = np.cos(yaw / 2)
    qpos[:, 6] = np.sin(yaw / 2)
    return qpos


@pytest.fixture(scope="module")
def exported(model, motion, tmp_path_factory):
    pytest.importorskip("bpy")
    from gesture_sim.export.blender import write_scene

    out = tmp_path_factory.mktemp("blender")
    paths = {}
    for fmt in ("fbx", "glb"):
        path = out / f"human.{fmt}.tmp"              # not the format's suffix: written exactly
        assert write_scene(path, model, motion, FPS, fmt) == N_FRAMES
        paths[fmt] = path
    return paths


@pytest.mark.parametrize("fmt", ["fbx", "glb"])
def test_round_trip_through_blender(fmt, exported, model, motion):
    from gesture_sim.export.blender import body_positions, bone_heads, read_back, rig_from_model

    path = exported[fmt]
    assert path.is_file() and path.stat().st_size > 10_000
    assert not list(path.parent.glob(path.name + ".*"))     # no suffix appended, no leftovers
    arm = read_back(path, fmt, FPS)
    rig = rig_from_model(model)
    # (a) the bones: every skinned body and its ancestors, the world body excluded
    skinned = set(model.skin_bonebodyid.tolist())
    expected = set()
    for b in skinned:
        while b > 0:
            expected.add(model.body(b).name)
            b = int(model.body_parentid[b])
    assert set(arm.data.bones.keys()) == set(rig.names) == expected
    assert {"pelvis", "head", "right_hand", "left_toes"} <= expected
    assert arm.data.bones["right_hand"].parent.name == "right_forearm"
    assert arm.data.bones["pelvis"].parent is None
    # (b) one mesh per skin, as many vertices as the skins
    import bpy

    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(meshes) == model.nskin
    assert sum(len(o.data.vertices) for o in meshes) == int(model.skin_vertnum.sum())
    assert all(any(m.type == "ARMATURE" for m in o.modifiers) or o.parent_type == "ARMATURE"
               or o.parent == arm for o in meshes)
    # (d) the frame range
    action = arm.animation_data.action
    assert tuple(round(x) for x in action.frame_range) == (0, N_FRAMES - 1)
    # (c) bone heads follow the MuJoCo bodies (Blender axes) at the first, mid and last frame
    frames = [0, MID, N_FRAMES - 1]
    got = bone_heads(arm, CHECK_BONES, frames)
    want = body_positions(model, motion[frames], CHECK_BONES)
    err = np.linalg.norm(got - want, axis=-1)
    assert err.max() < 0.01, f"{fmt}: bone heads off by up to {100 * err.max():.2f} cm"
    # the pose really moved: the raised right hand is far from its rest place
    rest = body_positions(model, motion[:1], ["right_hand"])[0, 0]
    assert np.linalg.norm(got[1, CHECK_BONES.index("right_hand")] - rest) > 0.2


def test_skinned_mesh_matches_mujoco_skinning(model, motion, exported):
    """The Blender-deformed skins (Armature modifier) equal the skins MuJoCo's renderer draws
    for the same frame (``mjv_updateScene``)."""
    pytest.importorskip("bpy")
    import bpy

    from gesture_sim.export.blender import build_scene, mujoco_skin_vertices

    built = build_scene(model, motion, FPS)
    scene = bpy.context.scene
    scene.frame_set(MID)
    want = mujoco_skin_vertices(model, motion[MID])
    dg = bpy.context.evaluated_depsgraph_get()
    for s in range(model.nskin):
        obj = bpy.data.objects[model.skin(s).name]
        ev = obj.evaluated_get(dg).to_mesh()
        co = np.empty(len(ev.vertices) * 3)
        ev.vertices.foreach_get("co", co)
        mw = np.array(obj.matrix_world)
        co = co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
        assert np.abs(co - want[s]).max() < 1e-4, model.skin(s).name
    assert built["frames"] == N_FRAMES
    # a fresh scene: the armature and one mesh per skin, no startup cube, camera or light
    kinds = sorted(o.type for o in scene.objects)
    assert kinds == ["ARMATURE"] + ["MESH"] * model.nskin
    assert scene.render.fps / scene.render.fps_base == pytest.approx(FPS)
    assert (scene.frame_start, scene.frame_end) == (0, N_FRAMES - 1)


def test_glb_material_colours(exported, model):
    """The shirt's glTF base colour is the MuJoCo shirt colour, in linear light."""
    pytest.importorskip("bpy")
    from gesture_sim.export.blender import read_back, srgb_to_linear

    read_back(exported["glb"], "glb", FPS)
    import bpy

    mat = bpy.data.objects["human_shirt"].active_material
    base = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value
    shirt = model.mat_rgba[model.skin_matid[model.skin("human_shirt").id]]
    np.testing.assert_allclose(list(base)[:3], srgb_to_linear(shirt[:3]), atol=2e-3)
