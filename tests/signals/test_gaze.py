"""The eyes: a speaker looks away at a phrase's start and back at its end, a listener mostly
at the partner; and the eyes counter-rotate the head (the face layer), so the gaze stays on
the partner while the head nods or turns."""

from __future__ import annotations

import math

import numpy as np

from gesture_sim.audio.speech import Heard
from gesture_sim.signals.gaze import Gaze, GazeConfig
from gesture_sim.signals.ruth import RuthSignals
from gesture_sim.sim import humanoid as hm
from gesture_sim.stages import VOR_GAIN, FaceLayer


def _heard(t: float, speaking: bool) -> Heard:
    return Heard(t=t, syllables=(), accents=(), boundaries=(), frames=None, speaking=speaking,
                 silence_s=0.0 if speaking else 2.0, energy=0.0)


def test_a_speaker_looks_away_at_phrase_starts_and_back_at_their_ends() -> None:
    gaze = Gaze(GazeConfig(p_avert_phrase=1.0, saccade_rad=0.0), seed=0)
    yaw0, _ = gaze.step(0.0, speaking=False)
    assert abs(yaw0) < 1e-12
    yaw, pitch = gaze.step(0.1, speaking=True, phrase_start=True)
    assert abs(yaw) >= 0.7 * GazeConfig().avert_yaw_rad      # away, to one side
    yaw, pitch = gaze.step(0.5, speaking=True, phrase_end=True)
    assert yaw == 0.0 and pitch == 0.0 and gaze.looking_at_partner()
    assert [e for _, e in gaze.events] == ["gaze away phrase", "gaze back"]


def test_a_listener_looks_at_the_speaker_most_of_the_time() -> None:
    gaze = Gaze(seed=1)
    away = []
    for t in np.arange(0, 120, 1 / 30):
        gaze.step(float(t), speaking=False)
        away.append(not gaze.looking_at_partner())
    assert 0.0 < np.mean(away) < 0.25                         # Argyle & Cook: ~75 % at the speaker
    saccades = {round(e, 6) for e in np.array(
        [gaze.step(120 + k / 30, speaking=False)[0] for k in range(300)])}
    assert len(saccades) > 5                                  # the eyes never freeze


def test_the_eyes_counter_rotate_the_head() -> None:
    base = np.zeros(len(hm.ACTUATED_JOINTS))
    base[hm.ACTUATED_JOINTS.index("head_flex")] = 0.15        # the clip's head looks down
    base[hm.ACTUATED_JOINTS.index("neck_twist")] = 0.20       # and turns left
    layer = FaceLayer(RuthSignals(seed=0), gaze=Gaze(GazeConfig(saccade_rad=0.0,
                                                                listener_avert_per_min=0.0)),
                      base=lambda: base)
    off, _ = layer.step(0.5, _heard(0.5, False))
    j = {n: i for i, n in enumerate(layer.joints)}
    for side in ("left", "right"):
        assert math.isclose(off[j[f"{side}_eye_pitch"]], -VOR_GAIN * 0.15, abs_tol=1e-9)
        assert math.isclose(off[j[f"{side}_eye_yaw"]], -VOR_GAIN * 0.20, abs_tol=1e-9)
        assert off[j[f"{side}_eyelid_close"]] == 0.0          # looking up: the lids stay open
    plain = FaceLayer(RuthSignals(seed=0), gaze=Gaze(GazeConfig(saccade_rad=0.0,
                                                                listener_avert_per_min=0.0)))
    off0, _ = plain.step(0.5, _heard(0.5, False))
    assert off0[j["left_eye_pitch"]] == 0.0                   # without a base: straight ahead
