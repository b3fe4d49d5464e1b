"""The humanoid's fingers: joints and actuators, flexion signs, the skin, the relaxed hand layer."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from gesture_sim.audio.speech import Heard
from gesture_sim.motion import finger_tracks
from gesture_sim.signals import hands
from gesture_sim.sim import humanoid as hm


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return hm.load_model(look="human")


def _posed(model: mujoco.MjModel, pose: dict[str, float]) -> mujoco.MjData:
    data = mujoco.MjData(model)
    q = np.zeros(len(hm.ACTUATED_JOINTS))
    for j, v in pose.items():
        q[hm.ACTUATED_JOINTS.index(j)] = v
    data.qpos[:] = hm.qpos_from_targets(model, q)
    mujoco.mj_kinematics(model, data)
    return data


def _heard(t: float, speaking: bool, energy: float = 0.0) -> Heard:
    return Heard(t=t, syllables=(), accents=(), boundaries=(), frames=None, speaking=speaking,
                 silence_s=0.0 if speaking else 2.0, energy=energy)


def test_every_finger_joint_is_actuated_in_xml_order(model) -> None:
    assert len(hm.FINGER_JOINTS) == 40 and len(set(hm.FINGER_JOINTS)) == 40
    for side in ("left", "right"):
        for f in hm.FINGERS[1:]:
            for j in ("spread", "mcp_flex", "pip_flex", "dip_flex"):
                assert f"{side}_{f}_{j}" in hm.FINGER_JOINTS
        for j in ("cmc_oppose", "cmc_flex", "mcp_flex", "ip_flex"):
            assert f"{side}_thumb_{j}" in hm.FINGER_JOINTS
    # the model's hinge order is ACTUATED_JOINTS (load_model checks it), and the fingers follow
    # their hand's wrist in it
    idx = hm.actuated_index(hm.FINGER_JOINTS)
    assert (np.diff(idx[:20]) == 1).all() and (np.diff(idx[20:]) == 1).all()
    assert hm.ACTUATED_JOINTS[idx[0] - 1] == "left_wrist_deviate"
    assert hm.ACTUATED_JOINTS[idx[20] - 1] == "right_wrist_deviate"
    act = hm.actuator_ids(model, hm.FINGER_JOINTS)
    assert np.allclose(model.actuator_gainprm[act, 0], 0.4)
    assert set(hm.JOINT_GROUPS["fingers"]) == set(hm.FINGER_JOINTS)
    assert not set(hm.FINGER_JOINTS) & set(hm.LEG_JOINTS)


def test_the_fingers_are_light_and_visual_only(model) -> None:
    for side in ("left", "right"):
        hand = model.body(f"{side}_hand").id
        assert model.body_subtreemass[hand] == pytest.approx(0.427, abs=1e-6)
        fingers = [b for b in range(model.nbody) if model.body_parentid[b] == hand]
        share = sum(model.body_subtreemass[b] for b in fingers) / 0.427
        assert 0.2 < share < 0.3
    for g in range(model.ngeom):
        name = model.geom(g).name
        if any(f"_{f}_" in name for f in hm.FINGERS):
            assert model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0, name


def test_positive_flexion_curls_the_finger_towards_the_palm(model) -> None:
    rest = _posed(model, {})
    for side in ("left", "right"):
        palm = model.site(f"{side}_hand_site").id
        for j in hm.FINGER_JOINTS:
            if not j.startswith(side) or "spread" in j:
                continue
            finger = j.split("_")[1]
            tip = model.site(f"{side}_{finger}_tip").id
            bent = _posed(model, {j: np.radians(30.0)})
            d0 = np.linalg.norm(rest.site_xpos[tip] - rest.site_xpos[palm])
            d1 = np.linalg.norm(bent.site_xpos[tip] - bent.site_xpos[palm])
            assert d1 < d0 - 0.002, j


def test_spread_moves_the_finger_away_from_the_middle_finger(model) -> None:
    rest = _posed(model, {})
    for side in ("left", "right"):
        mid = model.site(f"{side}_middle_tip").id
        for f in ("index", "ring", "little"):
            tip = model.site(f"{side}_{f}_tip").id
            spread = _posed(model, {f"{side}_{f}_spread": np.radians(15.0)})
            d0 = np.linalg.norm(rest.site_xpos[tip] - rest.site_xpos[mid])
            d1 = np.linalg.norm(spread.site_xpos[tip] - spread.site_xpos[mid])
            assert d1 > d0 + 0.005, (side, f)


def test_the_skin_follows_the_finger_bodies(model) -> None:
    """The skin's vertices bound to the index's distal phalanx move rigidly with it."""
    pose = {f"left_index_{j}": np.radians(50.0) for j in ("mcp_flex", "pip_flex", "dip_flex")}
    rest, bent = _posed(model, {}), _posed(model, pose)
    body = model.body("left_index_distal").id
    skin = model.skin("human_skin").id
    vids = []
    for b in range(model.skin_boneadr[skin], model.skin_boneadr[skin] + model.skin_bonenum[skin]):
        if model.skin_bonebodyid[b] == body:
            a = model.skin_bonevertadr[b]
            w = model.skin_bonevertweight[a: a + model.skin_bonevertnum[b]]
            vids = model.skin_bonevertid[a: a + model.skin_bonevertnum[b]][w > 0.99]
    assert len(vids) > 20
    vids = np.asarray(vids) + model.skin_vertadr[skin]

    def scene_skin(data: mujoco.MjData) -> np.ndarray:
        scn = mujoco.MjvScene(model, maxgeom=2000)
        mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), None, mujoco.MjvCamera(),
                               int(mujoco.mjtCatBit.mjCAT_ALL), scn)
        return scn.skinvert.reshape(-1, 3)[: model.nskinvert].astype(float)

    v0, v1 = scene_skin(rest)[vids], scene_skin(bent)[vids]
    local0 = v0 - rest.xpos[body]
    local1 = (v1 - bent.xpos[body]) @ bent.xmat[body].reshape(3, 3)
    assert np.abs(local1 - local0).max() < 1e-4            # rigid with the phalanx ...
    assert np.linalg.norm(v1 - v0, axis=1).min() > 0.02     # ... which went round the palm


def test_the_hand_layer_is_relaxed_and_alive() -> None:
    layer = hands.HandLayer(seed=3)
    assert layer.name == "hands" and layer.joints == hm.FINGER_JOINTS
    ts = np.arange(0.0, 20.0, 1.0 / 30.0)
    quiet = np.array([layer.step(t, _heard(t, False))[0] for t in ts])
    assert quiet.shape == (len(ts), 40) and np.isfinite(quiet).all()
    deg = np.degrees(quiet)
    sd = deg.std(0)
    assert 1.0 < np.median(sd) < 6.0                       # it moves a few degrees ...
    assert np.abs(np.diff(deg, axis=0)).max() < 2.0        # ... slowly
    # the cascade: the little finger more flexed than the index, every flexion curled
    col = {j: i for i, j in enumerate(hm.FINGER_JOINTS)}
    rest = finger_tracks.MESH_REST_DEG
    angle = deg + np.array([rest[j.split("_", 1)[1]] for j in hm.FINGER_JOINTS])
    mean = angle.mean(0)
    for side in ("left", "right"):
        assert mean[col[f"{side}_little_mcp_flex"]] > mean[col[f"{side}_index_mcp_flex"]] + 5
        assert all(mean[col[f"{side}_{f}_mcp_flex"]] > 12 for f in hm.FINGERS[1:])
    # speaking opens the hand; the same seed gives the same offsets
    layer.reset()
    loud = np.array([layer.step(t, _heard(t, True, 0.8))[0] for t in ts])
    flex = [i for i, j in enumerate(hm.FINGER_JOINTS) if "flex" in j and "thumb" not in j]
    assert (quiet[150:, flex].mean() - loud[150:, flex].mean()) > np.radians(5.0)
    again = hands.HandLayer(seed=3)
    assert np.array_equal(again.step(1.0, _heard(1.0, False))[0],
                          hands.HandLayer(seed=3).step(1.0, _heard(1.0, False))[0])


def test_standing_with_the_hand_layer_is_stable() -> None:
    from gesture_sim.sim.layers import TargetLayers
    from gesture_sim.sim.tracking import HumanoidSim

    model = hm.load_model(look="mannequin")
    sim = HumanoidSim(model, seed=0)
    sim.reset()
    layer = hands.HandLayer(seed=1)
    layers = TargetLayers()
    layers.define(layer.name, layer.joints)
    cols = hm.actuated_index(hm.FINGER_JOINTS)
    rng = hm.joint_ranges(model)[cols]
    worst = 0.0
    for k in range(int(3.0 * 30)):
        t = k / 30.0
        off, _ = layer.step(t, _heard(t, speaking=k > 45, energy=0.5))
        layers.set(layer.name, off)
        q = layers.apply(sim.standing_pose())
        sim.step(q, n_substeps=int(round(1.0 / 30.0 / model.opt.timestep)))
        qf = sim.q[cols]
        assert np.isfinite(sim.data.qpos).all()
        worst = max(worst, float(np.max(np.maximum(rng[:, 0] - qf, qf - rng[:, 1]))))
        if k > 15:
            assert np.abs(qf - q[cols]).max() < np.radians(8.0)
    assert worst < np.radians(1.0)
    assert sim.data.qpos[2] > 0.9                               # still standing


def test_smplx_hand_pose_maps_to_the_fingers(model) -> None:
    """A flexed SMPL-X index (about its flexion axis) and a spread little finger land on the
    right joints with the right signs, on both hands."""
    from gesture_sim.motion.smplx import SMPLX_JOINTS

    poses = np.zeros((1, 165))
    r = poses.reshape(1, 55, 3)
    r[0, SMPLX_JOINTS.index("left_index2")] = [0.0, 0.0, -0.5]    # left: flexion about -Z
    r[0, SMPLX_JOINTS.index("right_index2")] = [0.0, 0.0, 0.5]    # right: about +Z
    r[0, SMPLX_JOINTS.index("left_pinky1")] = [0.0, 0.3, 0.0]     # ulnar: about +Y on the left
    angles = finger_tracks.smplx_finger_angles(poses, model)[0]
    col = {j: i for i, j in enumerate(hm.FINGER_JOINTS)}
    assert angles[col["left_index_pip_flex"]] == pytest.approx(0.5, abs=0.03)
    assert angles[col["right_index_pip_flex"]] == pytest.approx(0.5, abs=0.03)
    assert angles[col["left_little_spread"]] == pytest.approx(0.3, abs=0.06)
    others = np.delete(angles, [col["left_index_pip_flex"], col["right_index_pip_flex"],
                                col["left_little_spread"], col["left_little_mcp_flex"]])
    assert np.abs(others).max() < 1e-9


def test_the_hands_play_a_clips_own_finger_motion_while_it_plays() -> None:
    """With a finger track for clip 2, the layer plays the track's rows while clip 2 plays
    (after a short crossfade), and returns to the relaxed hand at rest."""
    track = np.tile(np.linspace(0.0, 0.5, 40), (100, 1))
    track[:, 0] = np.linspace(0.0, 1.0, 100)            # a joint that moves along the clip
    where = {"now": (2, 10)}
    layer = hands.HandLayer(seed=0, tracks={2: track}, playing=lambda: where["now"])
    for k in range(30):                                 # 1 s at 30 Hz: past the crossfade
        where["now"] = (2, 10 + k)
        off, _ = layer.step(k / 30, _heard(k / 30, True, 0.5))
    np.testing.assert_allclose(off, track[39], atol=1e-9)
    relaxed = hands.HandLayer(seed=0)
    where["now"] = None                                 # at rest: back to the relaxed hand
    for k in range(30, 60):
        off, _ = layer.step(k / 30, _heard(k / 30, True, 0.5))
        ref, _ = relaxed.step(k / 30, _heard(k / 30, True, 0.5))
    assert layer.track_weight == 0.0
    assert np.abs(off - ref).max() < np.radians(3.0)   # the same relaxed hand (openness aside)


def test_the_shipped_library_has_its_beat2_clips_finger_motion() -> None:
    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.motion.finger_tracks import load_finger_tracks
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(DEFAULT_LIBRARY_DIR)
    tracks = load_finger_tracks(DEFAULT_LIBRARY_DIR, lib)
    beat2 = [i for i, c in enumerate(lib.clips) if c.name == "2_scott_0_1_1"]
    assert list(tracks) == beat2
    q = tracks[beat2[0]]
    assert q.shape == (lib.clips[beat2[0]].n_frames, 40)
    assert 4.0 < np.degrees(q.std(axis=0)).mean() < 15.0    # the take's fingers move (7.6 deg)


def test_library_build_and_subset_keep_an_smplx_takes_finger_motion(tmp_path) -> None:
    """``library build`` of an SMPL-X take writes its hand pose beside the library as the
    clip's finger track (the take's own frames at the library's rate: the same values the
    mapping gives on the file's poses), a BVH without fingers gets none, and ``library
    subset`` keeps the tracks of the clips it keeps."""
    from pathlib import Path

    from gesture_sim import cli
    from gesture_sim.motion.finger_tracks import load_finger_tracks, smplx_finger_track
    from gesture_sim.motion.library import MotionLibrary

    data = Path(__file__).resolve().parents[1] / "data" / "motion"
    npz, bvh = data / "2_scott_0_1_1_first10s.npz", data / "dataset-1_bow_active_001.bvh"
    out = tmp_path / "lib"
    assert cli.main(["library", "build", str(npz), str(bvh), "-o", str(out), "--json"]) == 0
    lib = MotionLibrary.load(out)
    tracks = load_finger_tracks(out, lib)
    assert list(tracks) == [0]                                  # the SMPL-X take only
    with np.load(npz) as z:
        poses, fps = z["poses"], float(z["mocap_frame_rate"])
    n = lib.clips[0].n_frames
    assert fps == lib.fps                                       # 30 Hz: no resampling here
    ref, _ = finger_tracks.smplx_finger_targets(poses[:n], hm.load_model(scene=False))
    np.testing.assert_allclose(tracks[0], ref, atol=1e-5)
    assert np.degrees(tracks[0].std(axis=0)).mean() > 3.0
    half = smplx_finger_track(npz, hm.load_model(scene=False), 15.0, n // 2)
    np.testing.assert_allclose(half, ref[: 2 * (n // 2): 2], atol=1e-5)   # 15 Hz: every 2nd
    sub = tmp_path / "sub"
    assert cli.main(["library", "subset", str(out), "--clips", "2_scott_*", "-o", str(sub),
                     "--json"]) == 0
    sub_lib = MotionLibrary.load(sub)
    np.testing.assert_allclose(load_finger_tracks(sub, sub_lib)[0], tracks[0])
