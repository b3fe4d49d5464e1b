"""The reference voice onsets of ``gesture-sim bench onset`` (:func:`gesture_sim.metrics.onset.
voice_onsets`): tone bursts at known times, known answers."""

from __future__ import annotations

import numpy as np

from gesture_sim.metrics.onset import first_at_or_after, voice_onsets

SR = 16_000


def _burst(seconds: float, db: float = -20.0) -> np.ndarray:
    t = np.arange(int(seconds * SR)) / SR
    return (10 ** (db / 20) * np.sqrt(2) * np.sin(2 * np.pi * 180.0 * t)).astype(np.float32)


def _quiet(seconds: float) -> np.ndarray:
    rng = np.random.default_rng(0)
    return (1e-4 * rng.standard_normal(int(seconds * SR))).astype(np.float32)   # -80 dBFS


def test_onsets_after_pauses_only() -> None:
    # 1.2 s pause | voice 0.5 | 30 ms closure | voice 0.4 | 0.3 s gap | voice 0.5 |
    # 1.5 s pause | voice 0.6, 10 dB quieter (within 30 dB of the loud level: voice)
    parts = [_quiet(1.2), _burst(0.5), _quiet(0.03), _burst(0.4), _quiet(0.3), _burst(0.5),
             _quiet(1.5), _burst(0.6, db=-30.0)]
    x = np.concatenate(parts)
    starts = np.cumsum([0] + [len(p) for p in parts]) / SR
    on = voice_onsets(x, SR, min_pause_s=1.0)
    # the first burst (after 1.2 s) and the last (after 1.5 s): the closure is bridged, the
    # 0.3 s gap is no pause
    assert np.allclose(on, [starts[1], starts[7]], atol=0.011), (on, starts)
    # a 1.6 s pause asked: none of the pauses is that long
    assert len(voice_onsets(x, SR, min_pause_s=1.6)) == 0
    # a short blip (50 ms) is no voice
    y = np.concatenate([_quiet(1.5), _burst(0.05), _quiet(1.5), _burst(0.5)])
    assert np.allclose(voice_onsets(y, SR), [3.05], atol=0.011)
    # nor is a breath 25 dB under the voice, 0.2 s before it: the onset is the voice's
    z = np.concatenate([_quiet(1.5), _burst(0.3, db=-45.0), _quiet(0.2), _burst(0.5)])
    assert np.allclose(voice_onsets(z, SR), [2.0], atol=0.011)


def test_first_at_or_after() -> None:
    assert first_at_or_after(np.array([0.1, 0.5, 0.9]), 0.4) == 0.5
    assert np.isnan(first_at_or_after(np.array([0.1, 0.5]), 0.6))
    assert np.isnan(first_at_or_after(np.array([0.1, 1.5]), 0.2, within_s=1.0))
