"""Praat pitch with each frame analysed once equals one Praat call per batch, bit for bit.

Issue 35 item 3: with the audio known ahead (a file), :class:`PitchAhead` lets Praat analyse
many frames in one call and runs Praat's path finder itself over each batch's frames. Every
batch it answers must equal the tracker's own per-batch Praat call to the last bit, on real
speech and on the signals that reach the path finder's corners (digital silence, a frame louder
than its segment's peak, clipping, noise); what it cannot decide it must hand back (None).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio import praat_pitch as pp
from gesture_sim.audio.prosody import ProsodyTracker
from gesture_sim.audio.sources import iter_blocks, load_audio
from gesture_sim.contracts import SAMPLE_RATE

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
JFK, BEAT2 = DATA / "jfk.wav", DATA / "beat2_scott_0_2_2_excerpt.wav"
B, C = 5, 6
S = pp.PitchSettings()


def _every_batch(audio: np.ndarray, origin: int) -> tuple[int, int]:
    """Each batch of ``audio`` through :class:`PitchAhead` against its own Praat call; returns
    (batches answered, batches handed back)."""
    ahead = pp.PitchAhead(audio, origin, B, C, S)
    answered = handed_back = 0
    for j in range(ahead.j_lo, ahead.j_hi):
        k0 = j * B - C
        seg = ahead.segment(k0, k0 + B + C - 1)
        got = ahead.f0(j, seg)
        if got is None:
            handed_back += 1
            continue
        np.testing.assert_array_equal(got, pp.batch_f0(seg, k0, S)[C:], err_msg=f"batch {j}")
        answered += 1
    return answered, handed_back


def _padded(x: np.ndarray) -> tuple[np.ndarray, int]:
    origin = 2000
    return np.concatenate([np.zeros(origin), np.asarray(x, np.float64), np.zeros(3000)]), origin


@pytest.mark.parametrize("path", [JFK, BEAT2])
def test_real_speech_every_batch_equals_its_own_praat_call(path) -> None:
    x, _ = load_audio(path)
    answered, handed_back = _every_batch(*_padded(x))
    assert answered > 0.97 * (answered + handed_back)


def test_the_path_finders_corners() -> None:
    rng = np.random.default_rng(7)
    sr = SAMPLE_RATE
    t = np.arange(sr) / sr
    speech, _ = load_audio(JFK)
    parts = [
        np.zeros(sr // 2),                                    # digital silence: no candidates
        0.4 * np.sin(2 * np.pi * 140 * t) * (1 + 0.3 * np.sin(2 * np.pi * 3 * t)),
        np.clip(8.0 * speech[: sr], -1, 1),                   # clipped speech
        np.full(sr // 4, 0.6),                                # a DC step: the local peak
        np.zeros(sr // 4),                                    # exceeds the segment's
        1e-4 * rng.normal(size=sr // 2),                      # faint noise
        0.3 * rng.normal(size=sr // 4),                       # a loud noise burst
        0.2 * np.sign(np.sin(2 * np.pi * 90 * t[: sr // 2])),  # a square wave
    ]
    answered, handed_back = _every_batch(*_padded(np.concatenate(parts)))
    assert answered > 0.9 * (answered + handed_back)


def test_a_wrong_local_peak_hands_the_chunk_back(monkeypatch) -> None:
    """The check against the intensities Praat reports: a window that is off in the last bit
    makes every batch of the chunk take its own Praat call."""
    x, _ = load_audio(JFK)
    audio, origin = _padded(x[: 2 * SAMPLE_RATE])
    real = pp._FrameGeometry.__init__

    def off(self, s):
        real(self, s)
        self.peak_window = self.peak_window * (1 + 2 ** -52)

    monkeypatch.setattr(pp._FrameGeometry, "__init__", off)
    answered, handed_back = _every_batch(audio, origin)
    assert answered == 0 and handed_back > 0


def test_global_peak_certainty() -> None:
    rng = np.random.default_rng(3)
    rows = rng.normal(scale=0.1, size=(200, 2256))
    peak, certain = pp.global_peaks(rows)
    assert certain.mean() > 0.8
    exact = np.array([max(r.max() - np.float64(np.mean(r, dtype=np.longdouble)),
                          np.float64(np.mean(r, dtype=np.longdouble)) - r.min()) for r in rows])
    np.testing.assert_array_equal(peak[certain], exact[certain])
    zero, sure = pp.global_peaks(np.zeros((1, 100)))
    assert zero[0] == 0.0 and sure[0]


def _track(x: np.ndarray, expect: np.ndarray | None, block: int | None = 160):
    tracker = ProsodyTracker()
    if expect is not None:
        tracker.expect(expect)
    syllables = []
    for blk in iter_blocks(x, block):
        syllables.extend(tracker.push(blk))
    syllables.extend(tracker.flush())
    frames, ahead = tracker.frames(), tracker._ahead
    tracker.release()
    return frames, syllables, ahead


def _same(a, b) -> None:
    fa, sa, _ = a
    fb, sb, _ = b
    for name in ("times", "f0_hz", "intensity_db", "silent", "voice"):
        np.testing.assert_array_equal(getattr(fa, name), getattr(fb, name), err_msg=name)
    assert sa == sb


@pytest.mark.parametrize("block", [160, 512, None])
def test_the_tracker_with_audio_known_ahead_is_the_same_tracker(block) -> None:
    x, _ = load_audio(JFK)
    ahead = _track(x, x, block)
    _same(_track(x, None, block), ahead)
    assert ahead[2].stats["batches"] > 0 and ahead[2].stats["praat_calls"] >= 1


def test_audio_ahead_that_differs_from_the_stream_changes_nothing() -> None:
    """Other audio, or too little of it, is never used where the pushed samples differ."""
    x, _ = load_audio(JFK)
    x = x[: 3 * SAMPLE_RATE]
    plain = _track(x, None)
    other = x.copy()
    other[SAMPLE_RATE:] *= 0.5
    _same(plain, _track(x, other))
    _same(plain, _track(x, x[: SAMPLE_RATE]))
    short = x[: 2 * SAMPLE_RATE + 77]           # a stream that ends before the audio ahead:
    _same(_track(short, None), _track(short, x))  # the flush's zeros are not that audio


def test_chunks_start_short_and_grow() -> None:
    """The first chunk is short (the first control steps wait for it), then each is as long as
    what came before it, up to the most."""
    ends, i = [], 0
    while i < 1240:
        i = pp.chunk_end(i, 1240, 400, 40)
        ends.append(i)
    assert ends == [40, 80, 160, 320, 640, 1040, 1240]
    assert pp.chunk_end(5, 7, 400, 40) == 7
