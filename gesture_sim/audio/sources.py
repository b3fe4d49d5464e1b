"""Audio sources: files and the microphone, delivered as :class:`AudioBlock` streams.

Every source converts at the edge to the one format the pipeline sees (docs/DESIGN.md §1–2): float32
mono at :data:`~gesture_sim.contracts.SAMPLE_RATE` (16 kHz), in blocks that carry the stream time
of their first sample (s). Files of any WAV width (8/16/24/32-bit integer, 32/64-bit float), any
channel count (mixed down by averaging) and any rate (resampled with a Kaiser-windowed polyphase
anti-aliasing filter, :func:`scipy.signal.resample_poly`) are read directly; other formats (FLAC,
MP3, OGG, ...) are decoded by the ffmpeg binary that ships with ``imageio-ffmpeg``.

The microphone source runs a PortAudio ``InputStream`` (through ``sounddevice``) whose callback
only copies samples into a preallocated single-producer/single-consumer ring buffer: no locks,
no allocation beyond numpy views, never blocking. Overflows (PortAudio's flag and a full ring)
are counted and reported.
"""

from __future__ import annotations

import math
import re
import subprocess
import threading
import time
import wave
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.errors import GestureSimError

#: Default block size (samples) of the sources: 10 ms at 16 kHz, one prosody frame.
DEFAULT_BLOCK_SIZE = 160
#: Lowest sample rate of a file taken as speech (Hz); below it there is no speech band left.
MIN_SOURCE_RATE = 4000
#: A file whose peak amplitude stays below this (-60 dBFS) is refused as silent (render, train
#: --signs: :func:`check_not_silent`).
SILENCE_PEAK = 1e-3
#: Highest sample rate a WAV header may give (Hz): 768 kHz is the most any audio interface
#: records; a larger one (4e9 Hz) is a damaged header, not a recording.
MAX_SOURCE_RATE = 768_000
#: Float WAV samples beyond this magnitude mean a broken or mislabelled file (full scale is 1).
FLOAT_PEAK_MAX = 1e3


@dataclass(frozen=True)
class AudioInfo:
    """What a file held before conversion.

    Attributes:
        path: the file read.
        format: ``"wav"`` or the container ffmpeg reported (e.g. ``"flac"``).
        source_rate: its sample rate (Hz), or 0 when the decoder did not say.
        channels: its channel count (0 when unknown).
        sample_format: e.g. ``"int16"``, ``"int24"``, ``"float32"``.
        duration_s: duration after conversion (s).
    """

    path: str
    format: str
    source_rate: int
    channels: int
    sample_format: str
    duration_s: float


# --------------------------------------------------------------------------------------------
# Conversion helpers
# --------------------------------------------------------------------------------------------


def to_float_mono(data: np.ndarray) -> np.ndarray:
    """Integer or float PCM of shape (n,) or (n, channels) to float32 (n,) in [-1, 1].

    Unsigned 8-bit is centred on 128; signed integers are scaled by their full range (24-bit
    WAV data arrives left-justified in int32, so the same scale applies). Channels are averaged.
    """
    if data.dtype == np.uint8:
        x = (data.astype(np.float32) - 128.0) / 128.0
    elif np.issubdtype(data.dtype, np.signedinteger):
        x = data.astype(np.float32) / float(2 ** (8 * data.dtype.itemsize - 1))
    elif np.issubdtype(data.dtype, np.floating):
        x = data.astype(np.float32, copy=False)
    else:
        raise GestureSimError(f"unsupported sample type {data.dtype}")
    if x.ndim == 2:
        x = x.mean(axis=1, dtype=np.float32) if x.shape[1] > 1 else x[:, 0]
    x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=-1.0)
    return np.ascontiguousarray(x, dtype=np.float32)


def resample_to_16k(x: np.ndarray, rate: int) -> np.ndarray:
    """Resample float32 (n,) from ``rate`` Hz to 16 kHz with an anti-aliasing polyphase filter."""
    if rate == SAMPLE_RATE or len(x) == 0:
        return x.astype(np.float32, copy=False)
    from scipy.signal import resample_poly

    g = math.gcd(int(rate), SAMPLE_RATE)
    y = resample_poly(x.astype(np.float64), SAMPLE_RATE // g, int(rate) // g)
    return y.astype(np.float32)


class StreamingResampler:
    """Causal polyphase resampler from ``rate`` to 16 kHz for live streams.

    Uses the same Kaiser-windowed FIR as :func:`scipy.signal.resample_poly` (half-length 10 taps
    per phase, beta 5), applied incrementally: ``process(block)`` returns every output sample
    whose inputs have arrived, so output never depends on how the input was split into blocks.
    Adds a group delay of about 10 input samples.
    """

    def __init__(self, rate: int) -> None:
        from scipy.signal import firwin

        g = math.gcd(int(rate), SAMPLE_RATE)
        self.up, self.down = SAMPLE_RATE // g, int(rate) // g
        max_rate = max(self.up, self.down)
        half_len = 10 * max_rate
        h = firwin(2 * half_len + 1, 1.0 / max_rate, window=("kaiser", 5.0)) * self.up
        self._taps_per_phase = int(math.ceil(len(h) / self.up))
        # Polyphase table: phase p holds h[p + u*up] for u = 0..taps_per_phase-1 (zero-padded).
        padded = np.zeros(self._taps_per_phase * self.up)
        padded[: len(h)] = h
        self._phases = padded.reshape(self._taps_per_phase, self.up).T.copy()  # (up, taps)
        self._x = np.zeros(self._taps_per_phase - 1, dtype=np.float64)  # history
        self._x_start = -(self._taps_per_phase - 1)  # absolute index of self._x[0]
        self._n_in = 0
        self._m = 0  # next output index

    def process(self, block: np.ndarray) -> np.ndarray:
        """Feed float input (n,); return the float32 16 kHz samples now computable."""
        self._x = np.concatenate([self._x, np.asarray(block, dtype=np.float64)])
        self._n_in += len(block)
        # Output m uses upsampled index n = m*down; inputs j = n//up - u for u < taps.
        last_m = (self._n_in * self.up - 1) // self.down if self._n_in else -1
        ms = np.arange(self._m, last_m + 1)
        if len(ms) == 0:
            return np.zeros(0, dtype=np.float32)
        n = ms * self.down
        phase = n % self.up
        j_newest = n // self.up
        idx = j_newest[:, None] - np.arange(self._taps_per_phase)[None, :] - self._x_start
        xs = np.where(idx >= 0, self._x[np.clip(idx, 0, None)], 0.0)
        y = np.einsum("mt,mt->m", xs, self._phases[phase])
        self._m = int(last_m + 1)
        # Keep only the history the next output can need.
        keep_from = (self._m * self.down) // self.up - (self._taps_per_phase - 1)
        drop = keep_from - self._x_start
        if drop > 0:
            self._x = self._x[drop:]
            self._x_start = keep_from
        return y.astype(np.float32)


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def _read_wav(path: Path) -> tuple[np.ndarray, int, str]:
    """Raw WAV data (n,) or (n, ch), its rate and sample format name."""
    import warnings

    from scipy.io import wavfile

    from gesture_sim.audio.g711 import read_g711_wav

    try:
        g711 = read_g711_wav(path)      # telephony A-law / µ-law: scipy reads PCM and float only
    except OSError as exc:
        raise GestureSimError(f"{path}: cannot read: {exc.strerror}") from exc
    if g711 is not None:
        return g711
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", wavfile.WavFileWarning)
            rate, data = wavfile.read(str(path), mmap=False)
    except Exception as exc:  # noqa: BLE001 - scipy raises many types on broken headers
        # scipy cannot read some legal headers (e.g. 8-bit via odd chunk layouts): try `wave`.
        try:
            with wave.open(str(path), "rb") as w:
                rate, width, ch = w.getframerate(), w.getsampwidth(), w.getnchannels()
                raw = w.readframes(w.getnframes())
        except Exception as exc2:  # noqa: BLE001 - wave.Error, struct.error, EOFError, ...
            # the readers' own words are often about their code ("cannot access local
            # variable 'data'", "integer division or modulo by zero"): say what is wrong
            problem = _wav_header_problem(path)
            if problem is None:
                said = [str(e) for e in (exc, exc2)
                        if isinstance(e, ValueError | wave.Error) and str(e)]
                problem = "broken header?" + (f": {said[0][:200]}" if said else "")
            raise GestureSimError(f"{path}: not a readable WAV file ({problem})") from exc
        if width == 3:
            b = np.frombuffer(raw, dtype=np.uint8).reshape(-1, 3)
            data = (b[:, 0].astype(np.int32) << 8 | b[:, 1].astype(np.int32) << 16
                    | b[:, 2].astype(np.int32) << 24)
        else:
            data = np.frombuffer(raw, dtype={1: np.uint8, 2: "<i2", 4: "<i4"}[width])
        data = data.reshape(-1, ch) if ch > 1 else data
        return data, rate, f"int{8 * width}"
    if data.dtype == np.int32 and _wav_bits(path) == 24:
        fmt = "int24"
    else:
        fmt = str(data.dtype)
    return data, int(rate), fmt


def _wav_header_problem(path: Path) -> str | None:
    """What is wrong with a WAV file's chunk layout or fmt chunk, in words, or None when no
    fault is found there (the RIFF chunks are walked: id, size, contents)."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        return exc.strerror or str(exc)
    if raw[:4] != b"RIFF" or raw[8:12] != b"WAVE":
        return None   # RIFX/RF64: left to the readers
    pos, fmt, has_data = 12, None, False
    while pos + 8 <= len(raw):
        cid, size = raw[pos:pos + 4], int.from_bytes(raw[pos + 4:pos + 8], "little")
        name = cid.decode("ascii", "replace").strip() or "unnamed"
        end = pos + 8 + size
        if cid == b"fmt ":
            fmt = raw[pos + 8:min(end, len(raw))]
        elif cid == b"data":
            has_data = True
        if end > len(raw) and cid != b"data":
            return (f"its {name!r} chunk at byte {pos} claims {size} bytes, running past the "
                    f"end of the {len(raw)}-byte file; truncated or damaged")
        pos = end + (size & 1)
    if fmt is None:
        return "no 'fmt ' chunk (the format of the samples)"
    if len(fmt) < 16:
        return f"its 'fmt ' chunk is {len(fmt)} bytes, fewer than the 16 it needs"
    channels = int.from_bytes(fmt[2:4], "little")
    rate = int.from_bytes(fmt[4:8], "little")
    align = int.from_bytes(fmt[12:14], "little")
    bits = int.from_bytes(fmt[14:16], "little")
    if channels == 0:
        return "the header says 0 channels"
    if rate == 0:
        return "the header says 0 samples per second"
    if bits == 0 or align == 0:
        return f"the header gives {bits} bits per sample and {align} bytes per frame"
    if not has_data:
        return "no 'data' chunk (no samples)"
    return None


def _wav_bits(path: Path) -> int:
    """Bits per sample from a WAV fmt chunk (0 when it cannot be found)."""
    try:
        head = path.read_bytes()[:4096]
    except OSError:
        return 0
    i = head.find(b"fmt ")
    if i < 0 or i + 24 > len(head):
        return 0
    return int.from_bytes(head[i + 22 : i + 24], "little")


def _decode_ffmpeg(path: Path) -> tuple[np.ndarray, AudioInfo]:
    """Decode any audio file ffmpeg understands to float32 16 kHz mono."""
    try:
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as exc:
        raise GestureSimError(f"{path}: not a WAV file and no ffmpeg to decode it") from exc
    cmd = [exe, "-hide_banner", "-nostdin", "-i", str(path), "-vn", "-f", "f32le", "-ac", "1",
           "-ar", str(SAMPLE_RATE), "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    err = proc.stderr.decode("utf-8", "replace")
    m = re.search(r"Audio: (\w+)[^,]*, (\d+) Hz, ([^,]+)", err)
    if proc.returncode != 0 or m is None:
        raise GestureSimError(f"{path}: not an audio file (ffmpeg could not decode it)")
    samples = np.frombuffer(proc.stdout, dtype="<f4").astype(np.float32)
    layout = m.group(3).strip()
    channels = {"mono": 1, "stereo": 2}.get(layout, 0)
    ch = re.match(r"(\d+) channels", layout)
    if ch:
        channels = int(ch.group(1))
    fmt = re.search(r"Input #0, ([\w,]+), from", err)
    info = AudioInfo(str(path), fmt.group(1).split(",")[0] if fmt else m.group(1),
                     int(m.group(2)), channels, m.group(1), len(samples) / SAMPLE_RATE)
    return samples, info


def check_audio_file(path: str | Path) -> tuple[Path, bytes]:
    """The checks every audio reader makes first: the file exists, is not a folder, can be
    read and is not empty. Returns the path and its first 12 bytes (the container's magic).

    Raises:
        GestureSimError: one line naming the file.
    """
    p = Path(path)
    if not p.exists():
        raise GestureSimError(f"{p}: no such file")
    if p.is_dir():
        raise GestureSimError(f"{p}: is a folder, not an audio file")
    try:
        size = p.stat().st_size
        with p.open("rb") as f:
            head = f.read(12)
    except OSError as exc:
        raise GestureSimError(f"{p}: cannot read: {exc.strerror}") from exc
    if size == 0:
        raise GestureSimError(f"{p}: empty file (0 bytes)")
    return p, head


def is_wav(head: bytes) -> bool:
    """Whether the first 12 bytes of a file are a WAV header (RIFF/RIFX/RF64 + WAVE)."""
    return head[:4] in (b"RIFF", b"RIFX", b"RF64") and head[8:12] == b"WAVE"


def read_wav_checked(p: Path) -> tuple[np.ndarray, int, str]:
    """A WAV file's samples as stored ((n,) or (n, C)), its rate (Hz) and sample format, after
    the checks: samples present, a sane rate for speech, float samples finite (stray NaN/inf are
    silenced) and within range.

    Raises:
        GestureSimError: one line naming the file.
    """
    data, rate, fmt = _read_wav(p)
    if data.size == 0 or data.shape[0] == 0:
        raise GestureSimError(f"{p}: WAV file contains no samples")
    if rate <= 0:
        raise GestureSimError(f"{p}: WAV header gives an invalid sample rate ({rate} Hz)")
    if rate > MAX_SOURCE_RATE:
        raise GestureSimError(
            f"{p}: the WAV header gives {rate:,} samples per second, above the "
            f"{MAX_SOURCE_RATE:,} Hz any audio is recorded at (a damaged header)")
    if rate < MIN_SOURCE_RATE:
        raise GestureSimError(
            f"{p}: sample rate {rate} Hz is too low for speech (need at least "
            f"{MIN_SOURCE_RATE} Hz)")
    if np.issubdtype(data.dtype, np.floating):
        finite = np.isfinite(data)
        if not finite.any():
            raise GestureSimError(
                f"{p}: every sample is NaN or infinite (a broken float WAV, not silence)")
        if not finite.all():  # stray NaN/inf (a glitch): silence them, not full scale
            data = np.where(finite, data, 0.0).astype(data.dtype)
        peak = float(np.max(np.abs(data)))
        if peak > FLOAT_PEAK_MAX:
            raise GestureSimError(
                f"{p}: float samples reach {peak:.3g}, far outside [-1, 1] (a broken or "
                "mislabelled float WAV)")
    return data, rate, fmt


def load_audio(path: str | Path) -> tuple[np.ndarray, AudioInfo]:
    """Read an audio file as float32 mono 16 kHz samples, shape (n,).

    Raises:
        GestureSimError: no such file, empty file, not audio / broken header, no samples.
    """
    p, head = check_audio_file(path)
    if is_wav(head):
        data, rate, fmt = read_wav_checked(p)
        channels = 1 if data.ndim == 1 else data.shape[1]
        x = resample_to_16k(to_float_mono(data), rate)
        info = AudioInfo(str(p), "wav", rate, channels, fmt, len(x) / SAMPLE_RATE)
    elif head[:4] in (b"RIFF",):
        raise GestureSimError(f"{p}: RIFF file that is not WAVE audio")
    else:
        x, info = _decode_ffmpeg(p)
    if len(x) == 0:
        raise GestureSimError(f"{p}: audio file contains no samples")
    return x, info


def check_not_silent(samples: np.ndarray, name: str, why: str = "nothing to gesture to") -> None:
    """One clear error for audio with no samples or that is silent (peak below
    :data:`SILENCE_PEAK`, -60 dBFS); ``name`` the file, ``why`` what silence means here."""
    if len(samples) == 0:
        raise GestureSimError(f"{name}: no audio samples")
    peak = float(np.max(np.abs(samples)))
    if peak < SILENCE_PEAK:
        level = 20.0 * np.log10(max(peak, 1e-12))
        raise GestureSimError(f"{name}: silent (peak {level:.0f} dBFS); {why}")


def audio_duration_s(path: str | Path) -> float:
    """The length of an audio file (s), cheaply: a PCM or G.711 WAV's from its header (the
    ``data`` chunk's bytes over the frame size, cut at the file's end), any other file as
    :func:`load_audio` decodes it. For the checks of side files against their audio before the
    analysis starts (:func:`gesture_sim.validation.side_file_times`).

    Raises:
        GestureSimError: as :func:`load_audio`, for a file it cannot read.
    """
    p, head = check_audio_file(path)
    if head[:4] == b"RIFF" and head[8:12] == b"WAVE":
        try:
            with p.open("rb") as f:
                raw = f.read(1 << 16)
                size = f.seek(0, 2)
        except OSError as exc:
            raise GestureSimError(f"{p}: cannot read: {exc.strerror}") from exc
        pos, fmt = 12, None
        while pos + 8 <= len(raw):
            cid, n = raw[pos:pos + 4], int.from_bytes(raw[pos + 4:pos + 8], "little")
            if cid == b"fmt ":
                fmt = raw[pos + 8:pos + 8 + n]
            elif cid == b"data" and fmt is not None and len(fmt) >= 16:
                rate = int.from_bytes(fmt[4:8], "little")
                align = int.from_bytes(fmt[12:14], "little")
                if MIN_SOURCE_RATE <= rate <= MAX_SOURCE_RATE and align > 0:
                    return min(n, size - pos - 8) // align / rate
                break
            pos += 8 + n + (n & 1)
    x, _ = load_audio(p)
    return len(x) / SAMPLE_RATE


class FileSource:
    """Iterate an audio file as :class:`AudioBlock` s of ``block_size`` samples (last one shorter).

    The file is read and converted once on construction (errors surface there); iterating does
    not pace to real time (the pipeline's clock does that where wanted).
    """

    def __init__(self, path: str | Path, block_size: int = DEFAULT_BLOCK_SIZE) -> None:
        if block_size <= 0:
            raise GestureSimError(f"block size must be positive, got {block_size}")
        self.samples, self.info = load_audio(path)
        self.block_size = int(block_size)

    @property
    def duration(self) -> float:
        """Duration after conversion (s)."""
        return len(self.samples) / SAMPLE_RATE

    def __iter__(self) -> Iterator[AudioBlock]:
        n, b = len(self.samples), self.block_size
        for i in range(0, n, b):
            yield AudioBlock(self.samples[i : i + b], i / SAMPLE_RATE)


def iter_blocks(samples: np.ndarray, block_size: int | None) -> Iterator[AudioBlock]:
    """Cut float32 (n,) samples into blocks (``None``: one block of everything)."""
    b = len(samples) if block_size is None else int(block_size)
    b = max(b, 1)
    for i in range(0, len(samples), b):
        yield AudioBlock(samples[i : i + b], i / SAMPLE_RATE)


# --------------------------------------------------------------------------------------------
# Microphone
# --------------------------------------------------------------------------------------------


class RingBuffer:
    """Single-producer / single-consumer float32 ring buffer without locks.

    The producer (audio callback) only calls :meth:`write`; the consumer only :meth:`read`.
    Each side advances only its own counter (Python int assignment is atomic under the GIL),
    so neither ever waits. A write that does not fit drops the newest samples and counts them.
    """

    def __init__(self, capacity: int) -> None:
        self._buf = np.zeros(int(capacity), dtype=np.float32)
        self.capacity = int(capacity)
        self._written = 0  # total samples written (producer-owned)
        self._read = 0  # total samples read (consumer-owned)
        self.dropped = 0  # samples dropped because the ring was full (producer-owned)

    def available(self) -> int:
        """Samples ready to read."""
        return self._written - self._read

    def write(self, x: np.ndarray) -> None:
        """Copy ``x`` (n,) in; drop what does not fit. No allocation, no blocking."""
        free = self.capacity - (self._written - self._read)
        n = len(x)
        if n > free:
            self.dropped += n - free
            n = free
        if n <= 0:
            return
        i = self._written % self.capacity
        first = min(n, self.capacity - i)
        self._buf[i : i + first] = x[:first]
        if n > first:
            self._buf[: n - first] = x[first:n]
        self._written += n

    def read(self, n: int) -> np.ndarray:
        """Copy out up to ``n`` samples (consumer side)."""
        n = min(n, self.available())
        i = self._read % self.capacity
        first = min(n, self.capacity - i)
        out = np.empty(n, dtype=np.float32)
        out[:first] = self._buf[i : i + first]
        if n > first:
            out[first:] = self._buf[: n - first]
        self._read += n
        return out


def _import_sounddevice() -> Any:
    try:
        import sounddevice
    except OSError as exc:  # PortAudio library missing
        raise GestureSimError(
            "no audio input: the PortAudio library is missing (install libportaudio2)"
        ) from exc
    return sounddevice


def list_input_devices() -> list[dict[str, Any]]:
    """Input-capable audio devices: dicts with ``index``, ``name``, ``channels``,
    ``default_samplerate`` (Hz), ``hostapi`` (name) and ``default`` (bool)."""
    sd = _import_sounddevice()
    try:
        devices = sd.query_devices()
        hostapis = sd.query_hostapis()
        default_in = sd.default.device[0]
    except Exception as exc:  # PortAudioError and friends
        raise GestureSimError(f"cannot list audio devices: {exc}") from exc
    out = []
    for i, d in enumerate(devices):
        if d["max_input_channels"] > 0:
            out.append({
                "index": i, "name": d["name"], "channels": int(d["max_input_channels"]),
                "default_samplerate": float(d["default_samplerate"]),
                "hostapi": hostapis[d["hostapi"]]["name"], "default": i == default_in,
            })
    return out


def resolve_input_device(
    device: int | str | None, devices: list[dict[str, Any]],
) -> dict[str, Any]:
    """Pick an input device: ``None`` = the default (else the first), an index, or a
    case-insensitive name substring. Raises a one-line :class:`GestureSimError`."""
    if not devices:
        raise GestureSimError("no audio input device found (is a microphone connected?)")
    if device is None:
        for d in devices:
            if d.get("default"):
                return d
        return devices[0]
    if isinstance(device, int) or (isinstance(device, str) and device.strip().isdigit()):
        idx = int(device)
        for d in devices:
            if d["index"] == idx:
                return d
        raise GestureSimError(
            f"no input device with index {idx} (inputs: "
            + ", ".join(f"{d['index']}: {d['name']}" for d in devices) + ")"
        )
    matches = [d for d in devices if str(device).lower() in d["name"].lower()]
    if not matches:
        raise GestureSimError(
            f"no input device matches {device!r} (inputs: "
            + ", ".join(f"{d['index']}: {d['name']}" for d in devices) + ")"
        )
    return matches[0]


class MicrophoneSource:
    """Live audio from an input device as a stream of :class:`AudioBlock` s.

    Args:
        device: ``None`` (default input), a device index, or a name substring.
        block_size: samples per delivered block at 16 kHz.
        buffer_s: ring-buffer capacity (s); audio the consumer has not taken within this time
            is dropped and counted in :attr:`dropped_samples`.
        samplerate: device rate to open (Hz); ``None`` tries 16 kHz, then the device's default
            rate with a :class:`StreamingResampler`.
        stream_factory: called like ``sounddevice.InputStream(samplerate=, channels=,
            dtype="float32", blocksize=, device=, callback=)``; returns an object with
            ``start()``, ``stop()``, ``close()`` and ``active``. Tests pass a fake device here.
        devices: the device list (``list_input_devices()`` format); queried when ``None`` and
            no ``stream_factory`` is given.
        max_duration: stop after this much audio (s); ``None`` runs until :meth:`stop`.

    Iterating starts the stream; blocks are delivered as they fill. The stream time of a
    block counts the samples delivered (dropped samples are replaced by nothing, so after an
    overflow the stream clock lags wall time by the dropped amount; overflows are counted).
    """

    def __init__(
        self, device: int | str | None = None, block_size: int = DEFAULT_BLOCK_SIZE,
        buffer_s: float = 5.0, samplerate: int | None = None,
        stream_factory: Callable[..., Any] | None = None,
        devices: list[dict[str, Any]] | None = None, max_duration: float | None = None,
    ) -> None:
        if block_size <= 0:
            raise GestureSimError(f"block size must be positive, got {block_size}")
        self.block_size = int(block_size)
        self.max_duration = max_duration
        self._factory = stream_factory
        if stream_factory is None:
            sd = _import_sounddevice()
            self._factory = sd.InputStream
            if devices is None:
                devices = list_input_devices()
        self.device_info: dict[str, Any] | None = None
        if devices is not None:
            self.device_info = resolve_input_device(device, devices)
            self._device = self.device_info["index"]
        else:
            self._device = device
        self._rates = [samplerate] if samplerate else [SAMPLE_RATE]
        if samplerate is None and self.device_info is not None:
            dev_rate = int(round(self.device_info["default_samplerate"]))
            if dev_rate != SAMPLE_RATE:
                self._rates.append(dev_rate)
        self.rate: int = self._rates[0]
        self._ring_capacity_s = buffer_s
        self._ring = RingBuffer(1)
        self._stream: Any = None
        self._resampler: StreamingResampler | None = None
        self.overflow_events = 0  # PortAudio input_overflow flags seen
        self._stopped = threading.Event()

    # The callback runs on PortAudio's thread: copy, count, return. Nothing else.
    def _callback(self, indata: np.ndarray, frames: int, time_info: Any, status: Any) -> None:
        if status is not None and getattr(status, "input_overflow", False):
            self.overflow_events += 1
        self._ring.write(indata[:, 0] if indata.ndim == 2 else indata)

    @property
    def dropped_samples(self) -> int:
        """Samples lost because the consumer fell behind (ring full)."""
        return self._ring.dropped

    def stats(self) -> dict[str, float]:
        """Overflow report: PortAudio overflow events, dropped samples and seconds."""
        return {"overflow_events": self.overflow_events, "dropped_samples": self.dropped_samples,
                "dropped_s": self.dropped_samples / max(self.rate, 1)}

    def start(self) -> None:
        """Open and start the input stream (idempotent)."""
        if self._stream is not None:
            return
        last_exc: Exception | None = None
        for rate in self._rates:
            self._ring = RingBuffer(int(self._ring_capacity_s * rate) + 4 * self.block_size)
            try:
                stream = self._factory(
                    samplerate=rate, channels=1, dtype="float32", blocksize=0,
                    device=self._device, callback=self._callback,
                )
                stream.start()
            except GestureSimError:
                raise
            except Exception as exc:  # sounddevice.PortAudioError, ValueError on bad rate
                last_exc = exc
                continue
            self._stream, self.rate = stream, int(rate)
            self._resampler = StreamingResampler(rate) if rate != SAMPLE_RATE else None
            return
        name = self.device_info["name"] if self.device_info else self._device
        raise GestureSimError(
            f"cannot open input device {name!r} (busy or unsupported): {last_exc}"
        )

    def stop(self) -> None:
        """Stop and close the stream; iteration ends after the buffered audio."""
        self._stopped.set()
        if self._stream is not None:
            try:
                self._stream.stop()
                self._stream.close()
            except Exception:  # noqa: BLE001 - closing a dead stream must not mask results
                pass

    def __enter__(self) -> MicrophoneSource:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __iter__(self) -> Iterator[AudioBlock]:
        self.start()
        pending = np.zeros(0, dtype=np.float32)
        delivered = 0
        limit = None if self.max_duration is None else int(self.max_duration * SAMPLE_RATE)
        poll = max(self.block_size / SAMPLE_RATE / 4, 0.001)
        try:
            while True:
                ended = self._stopped.is_set() or not bool(getattr(self._stream, "active", True))
                avail = self._ring.available()
                if avail:
                    raw = self._ring.read(avail)
                    if self._resampler is not None:
                        raw = self._resampler.process(raw)
                    pending = np.concatenate([pending, raw]) if len(pending) else raw
                while len(pending) >= self.block_size or (ended and len(pending) and not avail):
                    n = min(self.block_size, len(pending))
                    if limit is not None:
                        n = min(n, limit - delivered)
                    if n <= 0:
                        return
                    yield AudioBlock(pending[:n].copy(), delivered / SAMPLE_RATE)
                    pending = pending[n:]
                    delivered += n
                if limit is not None and delivered >= limit:
                    return
                if ended and not avail and self._ring.available() == 0 and not len(pending):
                    return
                if not avail:
                    time.sleep(poll)
        finally:
            self.stop()
