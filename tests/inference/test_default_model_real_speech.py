"""The shipped default model on real speech it was not trained on (BEAT2 take 0_3_3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.inference.model import GestureModel

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "motion_library" / "default" / "model"
WAV = ROOT / "tests" / "data" / "inference" / "beat2_scott_0_3_3_first20s.wav"


@pytest.fixture(scope="module")
def run():
    from gesture_sim.audio.prosody import analyze_file

    if not (MODEL / "model.json").is_file():
        pytest.skip("default model not built (tools/train_default_model.py)")
    model = GestureModel.load(MODEL)
    syllables = sorted(analyze_file(WAV).syllables, key=lambda s: s.t_emitted)
    rate = model.settings.rate_hz
    filt = model.new_filter()
    beliefs, feats, k = [], [], 0
    for i in range(int(20.0 * rate)):
        t = i / rate
        new = []
        while k < len(syllables) and syllables[k].t_emitted <= t:
            new.append(syllables[k])
            k += 1
        beliefs.append(filt.step(t, new))
        feats.append(filt.last_features)
    return model, np.array(beliefs), np.array(feats)


def test_belief_is_a_distribution_that_moves(run) -> None:
    model, beliefs, _ = run
    assert beliefs.shape[1] == model.n_states
    np.testing.assert_allclose(beliefs.sum(axis=1), 1.0, atol=1e-9)
    entropy = -np.sum(beliefs * np.log(np.maximum(beliefs, 1e-300)), axis=1)
    assert entropy.max() - entropy.min() > 0.3
    argmax = beliefs.argmax(axis=1)
    assert len(np.unique(argmax)) >= 3
    assert np.count_nonzero(np.diff(argmax)) >= 5


def test_loud_high_speech_shifts_belief_to_faster_states(run) -> None:
    """Expected velocity parameter under the belief is higher in loud, high-pitched steps than
    in quiet or silent ones, and rises with intensity overall."""
    model, beliefs, feats = run
    v = beliefs @ model.hmm.means[:, 2]
    f0 = np.nan_to_num(feats[:, 0], nan=-np.inf)
    loud_high = (feats[:, 1] > 0.5) & (f0 > 0.0)
    quiet = feats[:, 1] < -0.5
    assert loud_high.sum() > 20 and quiet.sum() > 20
    assert v[loud_high].mean() > v[quiet].mean()
    assert np.corrcoef(feats[:, 1], v)[0, 1] > 0.2
