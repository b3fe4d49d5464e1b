"""Praat intensity from two long calls equals one Praat call per batch, bit for bit.

Issue 35 (the prosody stage's cost): with the audio known ahead, :class:`IntensityAhead`
replays Praat's frame-time arithmetic to pick each batch frame from the long call with the same
middle sample. Every batch it answers must equal the tracker's own per-batch call to the last
bit; what it cannot place it must hand back (None).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import parselmouth
import pytest

from gesture_sim.audio import praat_intensity as pi
from gesture_sim.audio import praat_pitch as pp
from gesture_sim.audio.prosody import ProsodyConfig, ProsodyTracker
from gesture_sim.audio.sources import iter_blocks, load_audio
from gesture_sim.contracts import PROSODY_FRAME_STEP, SAMPLE_RATE

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
JFK, BEAT2 = DATA / "jfk.wav", DATA / "beat2_scott_0_2_2_excerpt.wav"
B, C = 5, 6
CFG = ProsodyConfig()
HALF = CFG.intensity_window // 2 + pp.PAD
MIN_PITCH = CFG.intensity_min_pitch_hz


def _padded(x: np.ndarray) -> tuple[np.ndarray, int]:
    origin = 2000
    return np.concatenate([np.zeros(origin), np.asarray(x, np.float64), np.zeros(3000)]), origin


def _every_batch(audio: np.ndarray, origin: int) -> tuple[int, int]:
    """Each batch through :class:`IntensityAhead` against its own Praat call; returns
    (batches answered, batches handed back)."""
    ahead = pi.IntensityAhead(audio, origin, B, C, HALF, MIN_PITCH)
    answered = handed_back = 0
    for j in range(ahead.j_lo, ahead.j_hi):
        a, b = (j * B - C) * pp.HOP - HALF, (j * B + B - 1) * pp.HOP + HALF
        seg = audio[a + origin: b + origin]
        got = ahead.values(j, seg)
        if got is None:
            handed_back += 1
            continue
        np.testing.assert_array_equal(got, pi.praat_intensity(seg, a, MIN_PITCH),
                                      err_msg=f"batch {j}")
        answered += 1
    return answered, handed_back


@pytest.mark.parametrize("path", [JFK, BEAT2])
def test_real_speech_every_batch_equals_its_own_praat_call(path) -> None:
    x, _ = load_audio(path)
    answered, handed_back = _every_batch(*_padded(x))
    assert answered > 0 and handed_back == 0


def test_silence_noise_clipping_and_steps() -> None:
    rng = np.random.default_rng(5)
    sr = SAMPLE_RATE
    speech, _ = load_audio(JFK)
    parts = [np.zeros(sr // 2), np.clip(8.0 * speech[:sr], -1, 1), np.full(sr // 4, 0.6),
             1e-6 * rng.normal(size=sr // 2), 0.3 * rng.normal(size=sr // 4)]
    answered, handed_back = _every_batch(*_padded(np.concatenate(parts)))
    assert answered > 0 and handed_back == 0


@pytest.mark.parametrize("start", [-1288, -1, 0, 7, 123_457, 9_600_001])
def test_the_replayed_frame_times_are_praats(start) -> None:
    """The first frame's time and the middle samples from the replayed arithmetic: Praat's own
    frame times (``Intensity.x1``), and the middle sample its nearest-index rounding gives."""
    for n in (2256, 2257, 3000, 40_001):
        snd = parselmouth.Sound(np.zeros(n), SAMPLE_RATE, start_time=start / SAMPLE_RATE)
        it = snd.to_intensity(minimum_pitch=MIN_PITCH, time_step=PROSODY_FRAME_STEP)
        mids, t1 = pi.middle_samples(np.array([start]), n, MIN_PITCH)
        assert it.x1 == t1[0] and mids.shape == (1, it.nx)
        for i in (0, it.nx - 1):
            t = it.x1 + i * it.dx
            nearest = math.floor((t - snd.x1) / snd.dx + 1.0 + 0.5)     # 1-based
            assert mids[0, i] == start + nearest - 1


def test_a_wrong_replay_hands_the_chunk_back(monkeypatch) -> None:
    """The per-chunk check against a batch's own Praat call: middle samples one off make the
    batches of each chunk take their own calls."""
    x, _ = load_audio(JFK)
    audio, origin = _padded(x[: 2 * SAMPLE_RATE])
    real = pi.middle_samples

    def off(starts, n, min_pitch):
        mids, t1 = real(starts, n, min_pitch)
        own = n == (B + C - 1) * pp.HOP + 2 * HALF             # a batch's own call: one late
        return mids + own, t1

    monkeypatch.setattr(pi, "middle_samples", off)
    answered, handed_back = _every_batch(audio, origin)    # what is answered is still right:
    assert handed_back > 0.9 * (answered + handed_back)    # in digital silence A and B agree


def test_the_tracker_takes_every_batch_from_the_long_calls() -> None:
    x, _ = load_audio(JFK)
    tracker = ProsodyTracker()
    tracker.expect(x)
    for blk in iter_blocks(x, 160):
        tracker.push(blk)
    tracker.flush()
    stats = tracker._intensity_ahead.stats
    tracker.release()
    assert stats["batches"] > 0 and stats["fallbacks"] == 0


def test_log2_is_the_c_librarys() -> None:
    """Praat's ``NUMlog2`` through the C library's ``log`` (as :func:`math.log`), not numpy's
    SIMD one, on the path finder's ratios of frequencies."""
    rng = np.random.default_rng(11)
    x = np.exp(rng.uniform(math.log(75 / 500), math.log(500 / 75), 200_000))
    want = np.array([math.log(v) for v in x.tolist()]) * pp._LOG2E
    np.testing.assert_array_equal(pp._log2(x), want)
