"""The two-person scene: one MuJoCo model, two free-standing PD + balance humanoids."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.metrics.physics import physics_metrics
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.scene import SceneSim, conversation_model, scene_qpos
from gesture_sim.testing.procedural import gesture_stream


@pytest.fixture(scope="module")
def scene_run():
    sc = SceneSim(conversation_model(1.6))
    sc.reset()
    sc.begin_trace()
    streams = [gesture_stream(duration=6.0, seed=s)[0] for s in (1, 2)]
    sc.advance_to(6.0, [s.sample for s in streams])
    return sc, sc.traces()


def test_two_bodies_face_each_other_at_the_distance(scene_run) -> None:
    sc, traces = scene_run
    m = sc.model
    assert m.nu == 2 * len(hm.ACTUATED_JOINTS)
    a, b = (tr.qpos[0] for tr in traces)
    assert b[0] - a[0] == pytest.approx(1.6, abs=0.02)
    # person 1 is turned by 180 degrees about z: its quaternion is (0, 0, 0, +-1)
    assert abs(b[3]) < 0.05 and abs(abs(b[6]) - 1.0) < 0.05
    assert abs(a[3]) > 0.99
    for name in ("both", "person_0", "person_1", "face_0", "face_1"):
        assert m.camera(name).id >= 0


def test_each_trace_has_the_single_person_layout(scene_run) -> None:
    sc, traces = scene_run
    n = len(hm.ACTUATED_JOINTS)
    for tr in traces:
        assert tr.qpos.shape[1] == 7 + n and tr.q.shape[1] == n
        np.testing.assert_allclose(tr.q, tr.qpos[:, 7:])
    q = scene_qpos(sc.model, traces)
    assert q.shape == (min(len(t.qpos) for t in traces), sc.model.nq)
    np.testing.assert_allclose(q[:, 7 + n: 14 + 2 * n], traces[1].qpos[: len(q)])


def test_both_bodies_gesture_and_stand_on_their_own(scene_run) -> None:
    _sc, traces = scene_run
    for tr in traces:
        m = physics_metrics(tr)
        assert not m.fell
        assert m.assist_impulse_per_s == 0.0
        assert m.foot_skate_mm_s < 2.0
        # each body's own contacts only: the other body's feet are not its ground contacts
        assert tr.foot_contact.all(axis=1).mean() > 0.95
        hands = tr.sim_sites[:, :2]
        assert np.ptp(hands[:, :, 2], axis=0).max() > 0.1       # the arms really moved


def test_bad_distance_is_one_clear_error() -> None:
    for d in (0.2, float("nan"), 9.0):
        with pytest.raises(GestureSimError, match="distance"):
            conversation_model(d)
