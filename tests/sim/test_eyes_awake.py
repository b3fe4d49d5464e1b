"""The human look's upper lids rest open (issue 54 item 5: eyes awake), blinks still close
fully and gaze is unchanged. Measured geometrically from the front, as the face camera sees
the eyes: rays along -x onto a 0.5 mm grid over each eye, each labelled by the first skin it
hits (face skin, eye white or iris); no GL."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from gesture_sim.signals import face_rig as fr
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim import looks

SIDES = ("left", "right")
_SKIN, _WHITE, _IRIS = 1, 2, 3
_STEP = 0.0005                                   # ray grid (m)


def _compile(person: int, opened: bool) -> mujoco.MjModel:
    """The human look of ``person`` (0: body a, 1: body b), with the lids opened as shipped
    or (``opened`` False) MakeHuman's."""
    old = dict(looks.LID_REST_OPEN_RAD)
    if not opened:
        looks.LID_REST_OPEN_RAD.clear()
    try:
        spec = mujoco.MjSpec.from_file(str(hm.SCENE_XML))
        return looks.apply_look(spec, "human", person).compile()
    finally:
        looks.LID_REST_OPEN_RAD.update(old)


@pytest.fixture(scope="module", params=[0, 1], ids=["body_a", "body_b"])
def models(request) -> dict[str, mujoco.MjModel]:
    """``old``: MakeHuman's lids (no rest opening); ``new``: the look as shipped."""
    return {"old": _compile(request.param, False), "new": _compile(request.param, True)}


def _posed(model: mujoco.MjModel, pose: dict[str, float]) -> tuple[mujoco.MjData, np.ndarray]:
    """Data at ``pose`` (joint offsets) and the skin vertices (nskinvert, 3) m there."""
    data = mujoco.MjData(model)
    q = np.zeros(len(hm.ACTUATED_JOINTS))
    for j, v in pose.items():
        q[hm.ACTUATED_JOINTS.index(j)] = v
    data.qpos[:] = hm.qpos_from_targets(model, q)
    mujoco.mj_kinematics(model, data)
    scn = mujoco.MjvScene(model, maxgeom=2000)
    mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), None, mujoco.MjvCamera(),
                           int(mujoco.mjtCatBit.mjCAT_ALL), scn)
    return data, scn.skinvert.reshape(-1, 3)[: model.nskinvert].astype(float).copy()


def _verts(model: mujoco.MjModel, verts: np.ndarray, skin: str) -> np.ndarray:
    k = model.skin(skin).id
    return verts[model.skin_vertadr[k]: model.skin_vertadr[k] + model.skin_vertnum[k]]


def _front_view(model: mujoco.MjModel, pose: dict[str, float], side: str,
                half: float = 0.02) -> dict[str, float]:
    """The eye of ``side`` seen from the front at ``pose``: ``aperture_mm`` (the height of eye,
    white or iris, visible in the column through the iris's centre), ``cover_mm`` (the iris's
    top minus the top of its visible part: how much the upper lid covers), ``eye_rays``
    (rays that reach the eye, of the grid)."""
    data, v = _posed(model, pose)
    c = data.body(f"{side}_eye").xpos.copy()
    tris, labels = [], []
    for name, label in (("human_skin", _SKIN), ("human_eyes", _WHITE), ("human_irises", _IRIS),
                        ("human_brows", _SKIN)):
        k = model.skin(name).id
        f0, nf = model.skin_faceadr[k], model.skin_facenum[k]
        t = _verts(model, v, name)[model.skin_face[f0: f0 + nf]]
        near = ((np.abs(t[:, :, 1] - c[1]).min(1) < half + 0.005)
                & (np.abs(t[:, :, 2] - c[2]).min(1) < half + 0.005) & (t[:, :, 0].max(1) > c[0]))
        tris.append(t[near])
        labels.append(np.full(int(near.sum()), label))
    t, lab = np.concatenate(tris), np.concatenate(labels)
    ys = c[1] + np.arange(-half, half + 1e-9, _STEP)
    zs = c[2] + np.arange(-half, half + 1e-9, _STEP)
    gy, gz = np.meshgrid(ys, zs, indexing="ij")
    origin = np.stack([np.full(gy.size, c[0] + 0.1), gy.ravel(), gz.ravel()], 1)
    # Moller-Trumbore, every ray (direction -x) against every triangle
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    p = np.stack([np.zeros(len(t)), e2[:, 2], -e2[:, 1]], 1)        # cross(-x, e2)
    det = (e1 * p).sum(1)
    ok = np.abs(det) > 1e-12
    t, lab, e1, e2, p, det = t[ok], lab[ok], e1[ok], e2[ok], p[ok], det[ok]
    s = origin[:, None, :] - t[None, :, 0]
    u = (s * p[None]).sum(2) / det
    qv = np.cross(s, e1[None])
    w = -qv[:, :, 0] / det
    dist = (qv * e2[None]).sum(2) / det
    dist = np.where((u >= 0) & (w >= 0) & (u + w <= 1) & (dist > 0), dist, np.inf)
    first = np.where(np.isfinite(dist.min(1)), lab[dist.argmin(1)], 0).reshape(gy.shape)
    iris = _verts(model, v, "human_irises")
    iris = iris[np.sign(iris[:, 1]) == np.sign(c[1])]
    column = first[np.argmin(np.abs(ys - iris[:, 1].mean()))]
    seen = first == _IRIS
    top = zs[seen.any(0)].max() if seen.any() else -np.inf
    return {"aperture_mm": 1e3 * _STEP * float((column >= _WHITE).sum()),
            "cover_mm": 1e3 * float(iris[:, 2].max() - top),
            "eye_rays": int((first >= _WHITE).sum())}


_CLOSED = {"left_eyelid_close": 0.014, "right_eyelid_close": 0.014}


@pytest.mark.parametrize("side", SIDES)
def test_the_lids_rest_with_the_iris_top_just_covered(models, side) -> None:
    old = _front_view(models["old"], {}, side)
    new = _front_view(models["new"], {}, side)
    # MakeHuman's lid hangs ~7 mm over the (17 mm) iris; opened, it covers only its top
    assert old["cover_mm"] > 6.5
    assert 1.0 < new["cover_mm"] < 5.5 and new["cover_mm"] < old["cover_mm"] - 2.5
    assert new["aperture_mm"] > old["aperture_mm"] + 2.5 and new["aperture_mm"] < 13.0


@pytest.mark.parametrize("side", SIDES)
def test_a_blink_still_closes_the_eye_fully(models, side) -> None:
    assert _front_view(models["new"], {}, side)["eye_rays"] > 300
    assert _front_view(models["new"], _CLOSED, side)["eye_rays"] == 0
    half = {k: 0.5 * v for k, v in _CLOSED.items()}
    assert 0 < _front_view(models["new"], half, side)["eye_rays"] \
        < _front_view(models["new"], {}, side)["eye_rays"]


def test_gaze_is_unchanged_and_the_lid_still_follows_it(models) -> None:
    down = dict(zip(fr.GAZE_JOINTS, fr.gaze_offsets(-0.3, 0.3), strict=True))
    (d_old, v_old), (d_new, v_new) = _posed(models["old"], down), _posed(models["new"], down)
    for side in SIDES:
        eye = models["new"].body(f"{side}_eye").id
        assert np.array_equal(d_old.xmat[eye], d_new.xmat[eye])
    # the eyeballs (white and iris) are where they were: only lid-bound vertices moved
    assert np.array_equal(_verts(models["old"], v_old, "human_irises"),
                          _verts(models["new"], v_new, "human_irises"))
    # the iris turned with the gaze, and the lid came down with a downward look
    _, v_rest = _posed(models["new"], {})
    moved = np.linalg.norm(_verts(models["new"], v_new, "human_irises")
                           - _verts(models["new"], v_rest, "human_irises"), axis=1)
    assert moved.min() > 0.002
    for side in SIDES:
        assert _front_view(models["new"], down, side)["aperture_mm"] \
            < _front_view(models["new"], {}, side)["aperture_mm"] - 1.0


def test_the_opening_moves_only_lid_bound_vertices() -> None:
    skn = looks.read_skn(looks.HUMAN_DIR / "a" / "skin.skn")
    assert np.array_equal(looks.open_lid_rest(skn, 0.0), skn["vert"])
    opened = looks.open_lid_rest(skn, looks.LID_REST_OPEN_RAD["a"])
    lid = np.zeros(len(skn["vert"]), bool)
    for bone, _, _, ids, w in skn["bones"]:
        if bone in looks.LID_BONES:
            lid[ids[w > 0]] = True
    rise = opened[:, 2] - skn["vert"][:, 2]
    assert np.array_equal(opened[~lid], skn["vert"][~lid])
    assert rise[lid].max() > 0.003 and rise[lid].min() > -1e-9
