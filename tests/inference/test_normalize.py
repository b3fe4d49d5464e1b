"""Per-speaker normalisation (Gesture Controllers x = (F0, I, L)) and Levine 2009 features."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gesture_sim.audio.prosody import ProsodyFrames
from gesture_sim.contracts import Syllable
from gesture_sim.inference.normalize import (
    SpeakerNormalizer,
    levine09_features,
    levine09_stats,
)


def _syllables(f0_median: float, n: int, seed: int, t0: float = 0.0,
               intensity: float = 65.0) -> list[Syllable]:
    """n contiguous syllables: log-F0 ~ N(log median, 0.1), I ~ N(intensity, 4), 0.2 s each."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        f0 = float(f0_median * math.exp(rng.normal(0, 0.1)))
        t = t0 + 0.2 * k
        out.append(Syllable(t, t + 0.2, t + 0.25, f0, float(rng.normal(intensity, 4.0)), True))
    return out


def test_running_statistics_converge_to_the_speaker() -> None:
    norm = SpeakerNormalizer()
    feats = norm.features_batch(_syllables(200.0, 600, seed=1))
    assert norm.logf0.mean == pytest.approx(math.log(200.0), abs=0.03)
    assert norm.logf0.sd == pytest.approx(0.1, rel=0.2)
    assert norm.intensity.mean == pytest.approx(65.0, abs=1.0)
    late = feats[300:]
    assert abs(late[:, 0].mean()) < 0.2 and late[:, 0].std() == pytest.approx(1.0, rel=0.2)
    assert abs(late[:, 1].mean()) < 0.2 and late[:, 1].std() == pytest.approx(1.0, rel=0.2)
    np.testing.assert_allclose(feats[:, 2], math.log(0.2))


def test_adapts_to_a_new_speaker() -> None:
    norm = SpeakerNormalizer(memory=100)
    norm.features_batch(_syllables(110.0, 400, seed=2))
    probe = Syllable(0, 0.2, 0.25, 220.0, 65.0, True)
    assert norm.features(probe, update=False)[0] > 3  # an octave above a low voice
    norm.features_batch(_syllables(220.0, 400, seed=3))
    assert abs(norm.features(probe, update=False)[0]) < 0.5


def test_unvoiced_gives_nan_pitch_and_is_not_absorbed() -> None:
    norm = SpeakerNormalizer()
    before = norm.logf0.mean
    f = norm.features(Syllable(0, 0.15, 0.2, None, 60.0, False))
    assert math.isnan(f[0]) and np.isfinite(f[1:]).all()
    assert norm.logf0.mean == before
    assert f[2] == pytest.approx(math.log(0.15))


def test_seeding_and_round_trip() -> None:
    train = _syllables(150.0, 300, seed=4)
    norm = SpeakerNormalizer.from_syllables(train)
    logs = np.log([s.f0_hz for s in train])
    assert norm.logf0.mean == pytest.approx(logs.mean())
    assert norm.logf0.var == pytest.approx(logs.var())
    copy = SpeakerNormalizer.from_dict(json.loads(json.dumps(norm.to_dict())))
    test = _syllables(150.0, 20, seed=5)
    np.testing.assert_allclose(copy.features_batch(test), norm.features_batch(test))
    # a seeded normaliser hardly moves on a few syllables of the same speaker
    assert abs(copy.logf0.mean - math.log(150.0)) < 0.03


def test_levine09_classes_and_silences() -> None:
    syl = _syllables(150.0, 30, seed=6)
    loud_long = Syllable(7.0, 7.8, 7.85, 150.0, 90.0, True)  # after a 1 s pause
    obs = levine09_features(syl + [loud_long])
    assert all(0 <= o.code < 36 for o in obs)
    silent = [o for o in obs if o.intensity == 0]
    assert len(silent) >= 2  # the 1 s pause is cut into medium chunks
    assert all(o.up == 0 and o.down == 0 and o.length in (0, 1) for o in silent)
    assert silent[0].t_start == pytest.approx(6.0) and silent[-1].t_end == pytest.approx(7.0)
    last = obs[-1]
    assert (last.intensity, last.length) == (2, 2)


def test_levine09_pitch_inflection_from_frames() -> None:
    # 20 flat syllables, then one with a 6-semitone rise and one with a 6-semitone fall
    times = np.arange(0, 4.4, 0.01)
    f0 = np.full(len(times), 150.0)
    rise = (times >= 4.0) & (times < 4.2)
    fall = (times >= 4.2) & (times < 4.4)
    f0[rise] = 150.0 * 2 ** (np.linspace(0, 6, rise.sum()) / 12)
    f0[fall] = 150.0 * 2 ** (np.linspace(6, 0, fall.sum()) / 12)
    frames = ProsodyFrames(times, f0, np.full(len(times), 65.0), np.zeros(len(times), bool))
    syl = [Syllable(0.2 * k, 0.2 * k + 0.2, 0.2 * k + 0.25, 150.0, 65.0, True)
           for k in range(22)]
    obs = levine09_features(syl, frames, stats=levine09_stats(syl[:20], frames))
    assert (obs[-2].up, obs[-2].down) == (1, 0)
    assert (obs[-1].up, obs[-1].down) == (0, 1)
    assert all((o.up, o.down) == (0, 0) for o in obs[:20])
