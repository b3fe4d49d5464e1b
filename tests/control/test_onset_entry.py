"""Leaving rest at a voice onset (``SyncSettings.onset_entry_s``, ``onset_blend_s``,
``onset_rate_at_once``; issue 55): known hand-speed curves, known answers. Off by default: the
defaults leave the onset as it was."""

from __future__ import annotations

import dataclasses

import numpy as np

from gesture_sim.control.mimic import MimicChooser, build_graph
from gesture_sim.control.synchrony import SpeechCue, SyncPlayer, SyncSettings

ONSET = 1.0     # s: silence before, speech from here on


def _lib(small_lib):
    fps = small_lib.fps

    def two_per_second(i: int) -> np.ndarray:
        t = np.arange(int(small_lib.lengths[i])) / fps
        return 0.6 - 0.5 * np.cos(2 * np.pi * 2.0 * t)        # peaks at 0.5, 1.0, ... s

    return dataclasses.replace(small_lib, hand_speed=two_per_second)


def _run(lib, small_model, **kw) -> SyncPlayer:
    """2.5 s: silence to ONSET, then speech without accents (the onset's stroke alone)."""
    chooser = MimicChooser(build_graph(lib, alpha=0.5), lib, seed=0, model=small_model)
    player = SyncPlayer(lib, chooser, SyncSettings(**kw))
    belief = np.full(small_model.n_states, 1.0 / small_model.n_states)
    for step in range(int(2.5 * lib.fps)):
        t = step / lib.fps
        speaking = t >= ONSET - 1e-9
        player.step(t, belief, SpeechCue(speaking, 0.0 if speaking else t, [], 0.0))
        if step == int(round(ONSET * lib.fps)):
            player.entered_at = player.p          # where the segment was entered
            player.ramp_steps = player._ramp._n
    return player


def test_the_onset_stroke_comes_sooner_when_entered_near_it(small_lib, small_model) -> None:
    lib = _lib(small_lib)
    fps = lib.fps
    before = _run(lib, small_model)
    after = _run(lib, small_model, onset_entry_s=0.05, onset_rate_at_once=True,
                 onset_blend_s=0.1)
    first = [min(t for t in p.log.strokes if t >= ONSET) - ONSET for p in (before, after)]
    # entered at most 0.05 s at 1.5x before the first peak (2.25 frames): the stroke within
    # two steps of the onset; from the segment's start (7.5 and more frames away) it takes
    # longer
    peak = after._next_peak(after.segment, after.entered_at - 1e-6)
    assert peak is not None and peak - after.entered_at <= 0.05 * 1.5 * fps + 1e-9
    assert first[1] <= 2.0 / fps + 1e-9, first
    assert first[1] < first[0], first
    # the ramp from rest is the asked 0.1 s (3 steps), the default one 15
    assert after.ramp_steps == 3 and before.ramp_steps == 15


def test_the_defaults_leave_the_onset_as_it_was(small_lib, small_model) -> None:
    lib = _lib(small_lib)
    a = _run(lib, small_model)
    b = _run(lib, small_model, onset_entry_s=None, onset_blend_s=None, onset_rate_at_once=False)
    assert a.log.strokes == b.log.strokes and a.entered_at == b.entered_at
    assert SyncSettings().onset_entry_s is None and not SyncSettings().onset_rate_at_once
