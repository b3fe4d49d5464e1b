"""A lower body that lives (issue 29 item 3): the legs follow the clip's weight shifts over
planted feet (``legs="clip"``), the balance controller carries them out, and nothing else gets
worse: no fall, no assist, feet that do not slide."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.tracking import BalanceGains, HumanoidSim, StanceLegs

BEAT2_62S = Path(__file__).resolve().parents[1] / "data" / "pipeline" / "beat2_scott_0_2_2.wav"


def test_stance_legs_keep_the_soles_flat_where_they_stand() -> None:
    ik = StanceLegs()
    for dx, dy, dz in ((0.0, 0.0, 0.0), (0.01, 0.04, 0.0), (-0.02, -0.05, 0.03)):
        legs = ik.solve(dx, dy, dz, iterations=20)
        m = ik.model
        d = mujoco.MjData(m)
        d.qpos[:3] = (dx, dy, hm.ROOT_HEIGHT - max(dz, ik.least_drop(dx, dy)))
        d.qpos[3] = 1.0
        d.qpos[hm.qpos_addresses(m, list(hm.LEG_JOINTS))] = legs
        mujoco.mj_kinematics(m, d)
        sites = [m.site(s).id for s in hm.FOOT_SITES]
        np.testing.assert_allclose(d.site_xpos[sites], ik.feet, atol=1e-5)       # in place
        np.testing.assert_allclose(d.site_xmat[sites][:, 8], 1.0, atol=1e-8)     # flat
        knees = legs[[hm.LEG_JOINTS.index(f"{s}_knee_flex") for s in ("left", "right")]]
        assert np.all(np.rad2deg(knees) >= 4.5)                                  # soft knees


def test_the_com_target_follows_the_reference_only_when_asked() -> None:
    """With ``follow_target`` the support centre moves with the reference pose's COM (bounded);
    the standing pose gives no shift at all."""
    sim = HumanoidSim(balance=BalanceGains(follow_target=True))
    pose_com = sim._target_com
    assert pose_com is not None and HumanoidSim()._target_com is None
    assert pose_com.offset(np.zeros(sim.n)) == pytest.approx((0.0, 0.0), abs=1e-12)
    q = np.zeros(sim.n)
    legs = hm.actuated_index(hm.LEG_JOINTS)
    q[legs] = StanceLegs().solve(0.0, 0.04, 0.0, iterations=20)
    dx, dy = pose_com.offset(q)
    assert 0.025 < dy < 0.045 and abs(dx) < 0.01          # the pelvis moved 4 cm to the left


def test_leg_modes_and_the_old_name() -> None:
    from gesture_sim.pipeline import DEFAULT_LEGS, GesturePipeline

    assert GesturePipeline.create(physics=False).legs == DEFAULT_LEGS
    assert GesturePipeline.create(physics=False, stand=True).legs == "stand"
    assert GesturePipeline.create(physics=False, stand=False).legs == "free"
    assert GesturePipeline.create(physics=False, stand=True, legs="clip").legs == "clip"
    with pytest.raises(GestureSimError, match="legs must be one of"):
        GesturePipeline.create(physics=False, legs="walk")


def _run(legs: str):
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    y, _ = load_audio(BEAT2_62S)
    pipe = GesturePipeline.create(seed=0, legs=legs)
    run_file(pipe, y=y[30 * 16000: 50 * 16000], sr=16000)
    return pipe.trace()


def _lateral(trace) -> np.ndarray:
    """COM left of the sole mid-point (m), in the pelvis heading frame, per row."""
    w, x, y, z = trace.qpos[:, 3:7].T
    fx, fy = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z)
    n = np.hypot(fx, fy)
    rel = trace.com[:, :2] - trace.foot_pos[:, :, :2].mean(axis=1)
    return (-rel[:, 0] * fy + rel[:, 1] * fx) / n


@pytest.mark.slow
def test_the_weight_shifts_over_planted_feet_on_real_speech() -> None:
    """20 s of a real take: with the clip's lower body the COM moves sideways over the feet
    several times (measured 25 mm SD, 3 swings of 20 mm, the band's 9.6-28.8 a minute;
    standing legs: 2 mm, none), with no fall, no assist, feet planted (skating 0.7 mm/s) and
    no self-penetration."""
    from gesture_sim.metrics.physics import physics_metrics

    stand, clip = _run("stand"), _run("clip")
    m = physics_metrics(clip)
    assert not m.fell
    assert m.assist_impulse_per_s == 0.0
    assert m.foot_skate_mm_s < 1.0
    assert m.ground_penetration_max_mm < 5.0
    assert m.self_penetration_max_mm <= 10.0
    assert m.saturation_share_any < 0.01
    y_stand, y_clip = _lateral(stand), _lateral(clip)
    assert y_clip.std() > 0.008 and y_clip.std() > 3 * y_stand.std()
    assert np.abs(y_clip).max() < 0.08                    # well inside the soles (±0.135 m)
    # swings of at least 20 mm from one extreme to the next (a weight shift from foot to foot)
    turns, ext, direction = 0, y_clip[0], 0
    for v in y_clip[::10]:
        if direction >= 0 and v < ext - 0.02 or direction <= 0 and v > ext + 0.02:
            turns, direction, ext = turns + 1, (1 if v > ext else -1), v
        elif direction > 0 and v > ext or direction < 0 and v < ext:
            ext = v
    assert turns >= 3
    knees = clip.q[:, [hm.ACTUATED_JOINTS.index(f"{s}_knee_flex") for s in ("left", "right")]]
    assert np.rad2deg(knees).mean() > 3.0                 # soft knees, never locked
