"""Audio sources: WAV widths/rates/channels, other formats, errors, ring buffer, resampler,
and the microphone source driven by a fake PortAudio stream."""

from __future__ import annotations

import subprocess
import threading
import time
import wave
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile
from scipy.signal import resample_poly

from gesture_sim.audio.prosody import ProsodyTracker, analyze_file
from gesture_sim.audio.sources import (
    FileSource,
    MicrophoneSource,
    RingBuffer,
    StreamingResampler,
    load_audio,
    resolve_input_device,
)
from gesture_sim.errors import GestureSimError

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
JFK, ARCTIC = DATA / "jfk.wav", DATA / "arctic_a0007.wav"


@pytest.fixture(scope="module")
def arctic() -> np.ndarray:
    rate, data = wavfile.read(ARCTIC)
    assert rate == 16000 and data.dtype == np.int16
    return data.astype(np.float64) / 32768.0


def _write_pcm(path: Path, x: np.ndarray, rate: int, width: int, channels: int = 1) -> None:
    """Write float (n,) or (n, ch) in [-1, 1] as integer PCM of `width` bytes with `wave`."""
    x = np.clip(x, -1, 1 - 2.0 ** -(8 * width - 1))
    if width == 1:
        raw = np.round(x * 128 + 128).astype(np.uint8).tobytes()
    elif width == 3:
        v = np.round(x * 2**23).astype(np.int32).reshape(-1)
        b = np.stack([v & 0xFF, (v >> 8) & 0xFF, (v >> 16) & 0xFF], axis=1).astype(np.uint8)
        raw = b.tobytes()
    else:
        raw = np.round(x * 2.0 ** (8 * width - 1)).astype(f"<i{width}").tobytes()
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(width)
        w.setframerate(rate)
        w.writeframes(raw)


@pytest.mark.parametrize("width, tol", [(1, 1 / 100), (2, 1e-4), (3, 1e-6), (4, 1e-6)])
def test_integer_widths_read_back(tmp_path: Path, arctic: np.ndarray, width: int,
                                  tol: float) -> None:
    path = tmp_path / f"w{width}.wav"
    _write_pcm(path, arctic, 16000, width)
    x, info = load_audio(path)
    assert x.dtype == np.float32 and x.shape == arctic.shape
    assert np.max(np.abs(x - arctic)) < tol
    assert info.source_rate == 16000 and info.channels == 1


def test_float32_wav(tmp_path: Path, arctic: np.ndarray) -> None:
    path = tmp_path / "f.wav"
    wavfile.write(path, 16000, arctic.astype(np.float32))
    x, info = load_audio(path)
    assert info.sample_format == "float32"
    np.testing.assert_allclose(x, arctic, atol=1e-7)


def test_48k_stereo_is_mixed_down_and_resampled(tmp_path: Path, arctic: np.ndarray) -> None:
    up = resample_poly(arctic, 3, 1)
    stereo = np.stack([up, 0.5 * up], axis=1)  # mix-down = 0.75 * signal
    path = tmp_path / "s48.wav"
    _write_pcm(path, stereo, 48000, 2, channels=2)
    x, info = load_audio(path)
    assert info.source_rate == 48000 and info.channels == 2
    assert abs(len(x) - len(arctic)) <= 1
    mid = slice(1000, len(arctic) - 1000)
    err = x[mid] - 0.75 * arctic[mid]
    assert np.sqrt(np.mean(err**2)) < 0.01 * np.sqrt(np.mean(arctic[mid] ** 2)) + 1e-4


def test_8k_input_gives_similar_syllables(tmp_path: Path, arctic: np.ndarray) -> None:
    path = tmp_path / "n8.wav"
    _write_pcm(path, resample_poly(arctic, 1, 2), 8000, 2)
    x, info = load_audio(path)
    assert info.source_rate == 8000 and abs(len(x) - len(arctic)) <= 2
    narrow = analyze_file(path).summary["n_syllables"]
    wide = analyze_file(ARCTIC).summary["n_syllables"]
    assert abs(narrow - wide) <= max(2, 0.2 * wide)


def test_flac_decoded_with_ffmpeg(tmp_path: Path, arctic: np.ndarray) -> None:
    import imageio_ffmpeg

    flac = tmp_path / "a.flac"
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(ARCTIC),
                    str(flac)], check=True)
    x, info = load_audio(flac)
    assert info.format == "flac" and info.source_rate == 16000
    assert len(x) == len(arctic)
    assert np.max(np.abs(x - arctic)) < 1e-4


@pytest.mark.parametrize("content, message", [
    (b"", "empty file"),
    (b"RIFF\x24\x00\x00\x00WAVEfmt \x10\x00\x00\x00garbage", "not a readable WAV"),
    (b"this is a text file, not audio\n" * 20, "not an audio file"),
])
def test_bad_files_are_one_line_errors(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.wav"
    path.write_bytes(content)
    with pytest.raises(GestureSimError, match=message) as exc:
        load_audio(path)
    assert "\n" not in str(exc.value)


def test_missing_file_and_zero_samples(tmp_path: Path) -> None:
    with pytest.raises(GestureSimError, match="no such file"):
        load_audio(tmp_path / "nope.wav")
    empty = tmp_path / "zero.wav"
    wavfile.write(empty, 16000, np.zeros(0, dtype=np.int16))
    with pytest.raises(GestureSimError, match="no samples"):
        load_audio(empty)


def test_file_source_blocks_cover_the_file() -> None:
    src = FileSource(JFK, block_size=999)
    blocks = list(src)
    assert [b.t_start for b in blocks[:3]] == [0.0, 999 / 16000, 1998 / 16000]
    np.testing.assert_array_equal(np.concatenate([b.samples for b in blocks]), src.samples)
    assert len(blocks[-1].samples) == 176000 % 999  # 11.0 s at 16 kHz


@pytest.mark.parametrize("rate", [48000, 44100, 8000])
def test_streaming_resampler_matches_resample_poly(rate: int) -> None:
    x = np.random.default_rng(0).standard_normal(rate // 2)
    r = StreamingResampler(rate)
    rng = np.random.default_rng(1)
    parts, i = [], 0
    while i < len(x):
        n = int(rng.integers(1, 2000))
        parts.append(r.process(x[i : i + n]))
        i += n
    y = np.concatenate(parts)
    ref = resample_poly(x, r.up, r.down)
    assert abs(len(y) - len(ref)) <= 1
    # The causal version lags by half the filter; find the lag, then compare sample by sample.
    lag = int(np.argmax(np.correlate(y[:2000], ref[:1000], mode="valid")))
    assert 0 < lag <= 40
    n = min(len(y) - lag, len(ref)) - 200
    np.testing.assert_allclose(y[lag + 200 : lag + n], ref[200:n], atol=1e-5)


def test_ring_buffer_wraps_and_counts_overflow() -> None:
    ring = RingBuffer(10)
    ring.write(np.arange(6, dtype=np.float32))
    np.testing.assert_array_equal(ring.read(4), [0, 1, 2, 3])
    ring.write(np.arange(6, 14, dtype=np.float32))  # wraps; 2 + 8 = 10 fits exactly
    assert ring.dropped == 0
    ring.write(np.array([99, 98], dtype=np.float32))  # full: both dropped
    assert ring.dropped == 2
    np.testing.assert_array_equal(ring.read(100), [4, 5, 6, 7, 8, 9, 10, 11, 12, 13])


class FakeStream:
    """Plays a WAV through a sounddevice-style callback on its own thread."""

    accept_rates: tuple[int, ...] = (16000,)

    def __init__(self, samples: np.ndarray, samplerate: int, channels: int, dtype: str,
                 blocksize: int, device: object, callback) -> None:
        if samplerate not in self.accept_rates:
            raise ValueError(f"Invalid sample rate {samplerate}")
        assert dtype == "float32" and channels == 1
        self.samples, self.callback, self.rate = samples.astype(np.float32), callback, samplerate
        self.active = False
        self._thread = threading.Thread(target=self._play, daemon=True)

    def _play(self) -> None:
        n = 256
        for i in range(0, len(self.samples), n):
            chunk = self.samples[i : i + n].reshape(-1, 1)
            self.callback(chunk, len(chunk), None, None)
            if i % 4096 == 0:
                time.sleep(0.0005)  # let the consumer run sometimes, like a real device
        self.active = False

    def start(self) -> None:
        self.active = True
        self._thread.start()

    def stop(self) -> None:
        self._thread.join(timeout=10)

    def close(self) -> None:
        pass


def _fake_factory(samples: np.ndarray, rates: tuple[int, ...] = (16000,)):
    def factory(**kw):
        stream = FakeStream.__new__(FakeStream)
        stream.accept_rates = rates
        FakeStream.__init__(stream, samples, **kw)
        return stream
    return factory


def test_microphone_with_fake_device_gives_file_syllables() -> None:
    x, _ = load_audio(JFK)
    mic = MicrophoneSource(block_size=160, stream_factory=_fake_factory(x), buffer_s=20.0)
    tracker = ProsodyTracker()
    got = []
    n = 0
    for block in mic:
        assert block.t_start == pytest.approx(n / 16000)
        n += len(block.samples)
        got.extend(tracker.push(block))
    got.extend(tracker.flush())
    assert n == len(x) and mic.stats()["dropped_samples"] == 0
    ref = analyze_file(JFK).syllables
    assert [(s.t_start, s.t_end, s.f0_hz) for s in got] == \
        [(s.t_start, s.t_end, s.f0_hz) for s in ref]


def test_microphone_falls_back_to_device_rate_and_resamples() -> None:
    x, _ = load_audio(ARCTIC)
    x48 = resample_poly(x.astype(np.float64), 3, 1)
    devices = [{"index": 3, "name": "Fake USB Mic", "channels": 1,
                "default_samplerate": 48000.0, "hostapi": "ALSA", "default": True}]
    mic = MicrophoneSource(stream_factory=_fake_factory(x48, rates=(48000,)), devices=devices,
                           buffer_s=20.0)
    y = np.concatenate([b.samples for b in mic])
    assert mic.rate == 48000
    lag = int(np.argmax(np.correlate(y[:6000], x[:5000], mode="valid")))
    assert lag <= 20
    n = min(len(y) - lag, len(x))
    err = y[lag : lag + n] - x[:n]
    assert np.sqrt(np.mean(err**2)) < 0.02 * np.sqrt(np.mean(x**2))


def test_microphone_overflow_is_counted() -> None:
    x = np.zeros(16000, dtype=np.float32)
    mic = MicrophoneSource(stream_factory=_fake_factory(x), buffer_s=0.05, block_size=160)
    mic.start()
    mic._stream._thread.join()  # the producer runs to the end before anything is consumed
    delivered = sum(len(b.samples) for b in mic)
    assert mic.dropped_samples > 0
    assert delivered + mic.dropped_samples == 16000


def test_no_device_and_busy_device_are_clear_errors() -> None:
    with pytest.raises(GestureSimError, match="no audio input device"):
        MicrophoneSource(stream_factory=_fake_factory(np.zeros(10)), devices=[])

    def busy(**kw):
        raise OSError("Device unavailable [PaErrorCode -9985]")

    mic = MicrophoneSource(stream_factory=busy,
                           devices=[{"index": 0, "name": "hw:0", "default_samplerate": 16000.0,
                                     "default": True}])
    with pytest.raises(GestureSimError, match="cannot open input device 'hw:0'"):
        mic.start()


def test_device_choice_by_index_and_name() -> None:
    devs = [{"index": 1, "name": "Built-in Microphone", "default": False},
            {"index": 4, "name": "USB Headset", "default": True}]
    assert resolve_input_device(None, devs)["index"] == 4
    assert resolve_input_device(1, devs)["index"] == 1
    assert resolve_input_device("headset", devs)["index"] == 4
    with pytest.raises(GestureSimError, match="no input device matches 'webcam'"):
        resolve_input_device("webcam", devs)
    with pytest.raises(GestureSimError, match="no input device with index 7"):
        resolve_input_device(7, devs)


def test_real_sounddevice_without_inputs_is_a_clear_error() -> None:
    from gesture_sim.audio.sources import list_input_devices

    try:
        devices = list_input_devices()
    except GestureSimError as exc:  # no PortAudio library at all: also one clear line
        assert "PortAudio" in str(exc) and "\n" not in str(exc)
        return
    if devices:
        pytest.skip("this machine has an audio input device")
    with pytest.raises(GestureSimError, match="no audio input device"):
        MicrophoneSource()
