"""The timing layer's defaults on the shipped library and real speech: no skipped preparations,
and an amplitude that keeps every joint within the range of the library's co-speech frames
(``SyncSettings.skip_after_s``, ``SyncSettings.amplitude_in_range``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.control.synchrony import SyncSettings

ROOT = Path(__file__).resolve().parents[2]
SPEECH = ROOT / "tests/data/audio/jfk.wav"


def _run(**kw):
    """The default pipeline (controller, targets) on real speech with these timing settings:
    (player, [(segment, playhead, mode, player target)] per control step)."""
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(physics=False, sync=SyncSettings(**kw))
    player = pipe.player
    steps = []
    step = player.step

    def logged(t, belief, cue):
        s = step(t, belief, cue)
        steps.append((s.segment, player.p, s.mode, s.target))
        return s

    player.step = logged
    run_file(pipe, SPEECH)
    return player, steps


def _jumps(player, steps) -> int:
    """Steps whose playhead moved on within the same segment by more than playback can."""
    most = player.cfg.rate_max * 1.5 + 1e-6       # rate_max × the voice's largest rate factor
    return sum(1 for (a0, p0, _, _), (a1, p1, _, _) in zip(steps, steps[1:], strict=False)
               if a0 == a1 >= 0 and p1 - p0 > most)


def _played(player, steps) -> np.ndarray:
    cospeech = player.library.cospeech
    return np.array([q for a, _, mode, q in steps
                     if a >= 0 and cospeech[a] and mode not in ("rest", "to_rest")])


@pytest.fixture(scope="module")
def default_run():
    return _run()


def test_no_skips_by_default(default_run):
    assert SyncSettings().skip_after_s is None
    player, steps = default_run
    assert player.log.strokes and player.log.served
    assert _jumps(player, steps) == 0
    skipping, steps_s = _run(skip_after_s=0.12)
    assert _jumps(skipping, steps_s) > 0                # the option still skips


def test_the_amplitude_keeps_the_joints_in_the_co_speech_range(default_run):
    """No joint target leaves the co-speech frames' range, whatever the voice's gain; without
    the bound some do (the gain reaches 1.5 × the extent factor)."""
    player, steps = default_run
    lib = player.library
    pool = np.nonzero(lib.cospeech)[0]
    q_all = np.concatenate([np.asarray(lib.segment_qpos(int(i))) for i in pool])
    assert np.array_equal(player.q_lo, q_all.min(axis=0))
    assert np.array_equal(player.q_hi, q_all.max(axis=0))
    played = _played(player, steps)
    assert len(played) > 100
    assert (played >= player.q_lo - 1e-9).all() and (played <= player.q_hi + 1e-9).all()
    free, steps_f = _run(amplitude_in_range=False)
    loose = _played(free, steps_f)
    assert ((loose < free.q_lo - 1e-3) | (loose > free.q_hi + 1e-3)).any()


@pytest.mark.parametrize("gain", [1.0, 0.7])
def test_a_gain_of_one_or_less_leaves_the_clip_as_it_is(default_run, gain):
    player, _ = default_run
    a = int(np.nonzero(player.library.cospeech)[0][0])
    q = player.qpos(a)
    for p in (0.0, 1.5, len(q) - 1.0):
        i = int(np.floor(p))
        j = min(i + 1, len(q) - 1)
        clip = q[i] + (q[j] - q[i]) * (p - i)
        assert np.allclose(player._pose(a, p, gain), player.rest + gain * (clip - player.rest))
