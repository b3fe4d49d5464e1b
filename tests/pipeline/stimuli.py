"""Speech with known answers for the pipeline tests: espeak-ng words, sox for rate conversion,
numpy for gains, pauses and concatenation. Every function returns 16 kHz mono float32."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import wave
from pathlib import Path

import numpy as np

SR = 16_000
HAVE_TOOLS = shutil.which("espeak-ng") is not None and shutil.which("sox") is not None


def say(text: str, *, speed: int = 150, pitch: int = 50, amplitude: int = 60,
        voice: str = "en-us") -> np.ndarray:
    """espeak-ng speech, resampled by sox to 16 kHz mono, leading/trailing silence trimmed."""
    with tempfile.TemporaryDirectory() as tmp:
        raw, out = Path(tmp) / "raw.wav", Path(tmp) / "out.wav"
        subprocess.run(["espeak-ng", "-v", voice, "-s", str(speed), "-p", str(pitch),
                        "-a", str(amplitude), "-w", str(raw), text], check=True,
                       capture_output=True)
        # -R: repeatable (sox dithers with a random seed otherwise: tests would vary by run)
        subprocess.run(["sox", "-R", str(raw), "-r", str(SR), "-c", "1", "-b", "16", str(out)],
                       check=True, capture_output=True)
        with wave.open(str(out)) as w:
            x = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2").astype(np.float32)
    x /= 32768.0
    loud = np.nonzero(np.abs(x) > 0.01)[0]
    return x[max(loud[0] - 160, 0): loud[-1] + 160] if len(loud) else x


def silence(seconds: float) -> np.ndarray:
    return np.zeros(int(round(seconds * SR)), dtype=np.float32)


def gain(x: np.ndarray, db: float) -> np.ndarray:
    return (x * 10.0 ** (db / 20.0)).astype(np.float32)


def write(path: Path, x: np.ndarray) -> Path:
    """16-bit PCM WAV (clipped to [-1, 1])."""
    pcm = np.clip(np.round(np.asarray(x) * 32767.0), -32768, 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(SR)
        w.writeframes(pcm.tobytes())
    return path


def concat(parts: list[np.ndarray]) -> tuple[np.ndarray, list[float]]:
    """Concatenated parts and the start time (s) of each."""
    starts, t = [], 0.0
    for p in parts:
        starts.append(t)
        t += len(p) / SR
    return np.concatenate(parts).astype(np.float32), starts
