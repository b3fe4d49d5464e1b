"""The timing layer thins a speaker's accents to the real speaker's stroke rate, most prominent
first (``SyncSettings.stroke_rate``): known accent streams, known answers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gesture_sim.control.mimic import MimicChooser, build_graph
from gesture_sim.control.synchrony import SpeechCue, SyncPlayer, SyncSettings


def _called(player: SyncPlayer, accents_s: np.ndarray, strengths: np.ndarray,
            n_states: int) -> np.ndarray:
    """Feed one accent per control step at the given times; (K,) bool: did it call a stroke."""
    fps = player.library.fps
    belief = np.full(n_states, 1.0 / n_states)
    called = []
    step = 0
    for ta, sa in zip(accents_s, strengths, strict=True):
        while step / fps < ta:                               # speech between the accents
            player.step(step / fps, belief, SpeechCue(True, 0.0, [], 0.0))
            step += 1
        player.pending = player.pending_t = None
        player.step(step / fps, belief, SpeechCue(True, 0.0, [float(ta)], 0.0, [float(sa)]))
        called.append(player.pending_t == float(ta) or player.log.served[-1:] == [
            (float(ta), step / fps)])
        step += 1
    return np.array(called)


@pytest.fixture()
def make_player(small_lib, small_model):
    chooser = MimicChooser(build_graph(small_lib, alpha=0.5), small_lib, seed=0,
                           model=small_model)

    def make(**kw) -> SyncPlayer:
        chooser.reset()
        return SyncPlayer(small_lib, chooser, SyncSettings(**kw))
    return make


def test_fast_accents_keep_the_prominent_ones(make_player, small_model):
    """3 accents/s alternating strong and weak, thinned to 1.5 strokes/s: the strong ones call
    strokes, the weak ones do not (after the first five, which always do)."""
    t = 1.0 + np.arange(90) / 3.0
    strength = np.where(np.arange(90) % 2 == 0, 2.0, -1.0)
    called = _called(make_player(stroke_rate=1.5), t, strength, small_model.n_states)[10:]
    strong = strength[10:] > 0
    assert called[strong].mean() >= 0.9
    assert called[~strong].mean() <= 0.1
    # the rate that passes is about the asked one (half of 3 /s)
    assert 1.2 <= called.mean() * 3.0 <= 1.8


def test_slow_speech_and_no_limit_keep_every_accent(make_player, small_model):
    """1 accent/s is below a 1.5 /s limit: every accent calls a stroke; ``stroke_rate=0``
    keeps every accent of fast speech."""
    rng = np.random.default_rng(0)
    slow = 1.0 + np.arange(40) * 1.0
    assert _called(make_player(stroke_rate=1.5), slow, rng.normal(size=40),
                   small_model.n_states).all()
    fast = 1.0 + np.arange(60) / 3.0
    assert _called(make_player(stroke_rate=0.0), fast, rng.normal(size=60),
                   small_model.n_states).all()


def test_default_rate_is_the_librarys_own(small_lib, small_model):
    """``stroke_rate=None`` (the default): stroke marks per second of the co-speech clips; hands
    whose speed peaks twice a second give about 2 strokes/s, still hands no limit."""
    fps = small_lib.fps

    def two_per_second(i: int) -> np.ndarray:
        t = np.arange(int(small_lib.lengths[i])) / fps
        return 0.6 - 0.5 * np.cos(2 * np.pi * 2.0 * t)        # peaks at 0.25, 0.75, ... s

    chooser = MimicChooser(build_graph(small_lib, alpha=0.5), small_lib, seed=0,
                           model=small_model)
    lib = dataclasses.replace(small_lib, hand_speed=two_per_second)
    rate = SyncPlayer(lib, chooser).stroke_rate
    assert 1.5 < rate <= 2.0                  # a peak cut by a clip's end is not a stroke mark
    assert SyncPlayer(small_lib, chooser).stroke_rate == 0.0     # no hand speeds: no limit
