"""The listening posture (gesture_sim.signals.listener, *Posture*): while the partner speaks the
listener holds its head about level and looks at the partner with eyes near the middle of the
orbit, instead of hanging its head forward and looking up from under its lids.

The human range: a person looking at someone at eye level holds the head in its natural
position, the visual axis about horizontal (Broca; Moorrees & Kean 1958), whose flexion varies
by a few degrees (SD about 2-4 deg between and within people; Solow & Tallgren 1971), and a
listener leans forward a little when attentive. So the listener's mean head pitch (its spine,
neck and head flexion together: the head against the standing body's facing, + down) over the
partner's speech must lie within -5..+8 deg (about two SDs down, plus the lean; a little up),
the eyes' mean pitch in the orbit within +-10 deg (sustained gaze keeps the eyes near the centre
and turns the head for the rest), and the gaze (head + eyes) within 3 deg of the partner's eyes
(the two stand at the same height). Before the posture the listener's head was 17-18 deg down
and its eyes 12-13 deg up."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.signals.listener import (
    LISTENER_JOINTS,
    ListenerConfig,
    ListenerSignals,
)
from gesture_sim.signals.listeners import make_listener
from gesture_sim.testing import dialogue

PITCH = ("lower_spine_flex", "upper_spine_flex", "neck_flex", "head_flex")
HEAD_DOWN_MAX_DEG = 8.0
HEAD_UP_MAX_DEG = 5.0
EYES_MAX_DEG = 10.0
GAZE_MAX_DEG = 3.0
J = {n: i for i, n in enumerate(LISTENER_JOINTS)}


@pytest.fixture(scope="module")
def conversation():
    """The scripted espeak dialogue through two people (targets, no physics)."""
    from gesture_sim.conversation import Conversation, conversation_channels, run_conversation
    from gesture_sim.loading import load_stack

    try:
        d = dialogue.make_dialogue(0)
    except GestureSimError as exc:
        pytest.skip(str(exc))
    stack = load_stack(None, None, policy=True)
    voices, turns = conversation_channels(channels=d.channels)
    conv = Conversation(stack.library, stack.model, stack.policy, seeds=(0, 1), physics=False,
                        control_library=stack.control_library, interests=(1.0, 1.0))
    run_conversation(conv, voices, turns)
    return conv, d


def _listening(conv, d, p: int) -> tuple[float, float]:
    """Person ``p``'s mean head pitch and eye pitch (deg, + down) over the partner's speech."""
    from gesture_sim.sim.humanoid import ACTUATED_JOINTS

    person = conv.people[p]
    t = np.asarray(person.log.step_times)
    q = np.degrees(np.asarray(person.log.targets, dtype=float))
    partner = np.zeros(len(t), bool)
    for u in d.turns:
        if u.person != p:
            partner |= (t >= u.t_start) & (t < u.t_end)
    assert partner.sum() > 60
    col = [ACTUATED_JOINTS.index(n) for n in PITCH]
    eye = ACTUATED_JOINTS.index("left_eye_pitch")
    return float(q[partner][:, col].sum(axis=1).mean()), float(q[partner, eye].mean())


@pytest.mark.parametrize("p", [0, 1])
def test_the_listeners_head_is_about_level_and_looks_at_the_partner(conversation, p) -> None:
    conv, d = conversation
    assert conv.people[p]._layer("listener").listener.posture
    head, eyes = _listening(conv, d, p)
    assert -HEAD_UP_MAX_DEG <= head <= HEAD_DOWN_MAX_DEG, head
    assert abs(eyes) <= EYES_MAX_DEG, eyes
    assert abs(head + eyes) <= GAZE_MAX_DEG, (head, eyes)


def _partner_frames(dur: float, speech: tuple[float, float]):
    """A partner speaking (flat 60 dB, 120 Hz) within ``speech`` (s), silent otherwise."""
    times = np.arange(0.005, dur, 0.01)
    on = (times >= speech[0]) & (times < speech[1])
    db = np.where(on, 60.0, -120.0)
    f0 = np.where(on, 120.0, np.nan)
    return times, db, ~on, times + 0.02, f0


def test_posture_lifts_the_head_and_the_eyes_counter_rotate_it() -> None:
    cfg = ListenerConfig(p_invited=0.0, p_other=0.0, shift_min_s=1e3, shift_max_s=1e3)
    frames = _partner_frames(8.0, (1.0, 7.0))
    out = {}
    for posture in (False, True):
        lis = ListenerSignals(cfg, seed=1, posture=posture)
        lis.push_frames(*frames)
        out[posture] = np.array([lis.step(k / 30, own_speaking=False)[0]
                                 for k in range(int(8.0 * 30))])
    off, on = out[False], out[True]
    eyes = [J["left_eye_pitch"], J["right_eye_pitch"]]
    assert np.all(off[:, eyes] == 0.0)                    # the backchannels alone: no eyes
    k = int(5.0 * 30)                                     # attention fully in
    lift = (on[k, J["neck_flex"]] + on[k, J["head_flex"]]) - (
        off[k, J["neck_flex"]] + off[k, J["head_flex"]])
    assert lift == pytest.approx(-cfg.attend_lift_rad)
    assert on[k, J["head_flex"]] < on[k, J["neck_flex"]]  # split like the nods (40 / 60)
    own = on[:, [J["lower_spine_flex"], J["neck_flex"], J["head_flex"]]].sum(axis=1)
    assert np.allclose(on[:, eyes[0]], -cfg.vor_gain * own)
    assert np.allclose(on[:, eyes[0]], on[:, eyes[1]])
    assert on[0, J["head_flex"]] == 0.0                   # ramped in with the attention
    step = np.abs(np.diff(on, axis=0))
    assert step[:, [J["neck_flex"], J["head_flex"]]].max() <= math.radians(1.0)


def test_make_listener_holds_the_posture_and_the_vor_gain_matches_the_face() -> None:
    from gesture_sim.stages import VOR_GAIN

    assert make_listener("rule").posture
    assert not make_listener("rule", posture=False).posture
    assert ListenerConfig().vor_gain == VOR_GAIN
