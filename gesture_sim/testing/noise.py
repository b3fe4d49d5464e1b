"""Real-sounding noise for known-answer tests and the voice-activity benchmark.

Everything is float64 mono at :data:`~gesture_sim.contracts.SAMPLE_RATE`; levels are dBFS RMS
(full scale = 1.0). Word masks are per 10 ms frame.

* :func:`room_tone`: a recording's own pauses (the room it was made in), looped;
* :func:`line_noise`: a telephone line's hiss (white noise band-passed to 300–3400 Hz);
* :func:`hum`: 50/60 Hz mains hum with its harmonics;
* :func:`click`: a short raised-cosine click;
* :func:`at_level` scales a noise to an RMS level; :func:`rms_db` measures one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE

_HOP = SAMPLE_RATE // 100


def rms_db(x: np.ndarray) -> float:
    """RMS level (dBFS) of ``x``."""
    return float(10 * np.log10(np.mean(np.square(x, dtype=np.float64)) + 1e-20))


def at_level(noise: np.ndarray, db: float) -> np.ndarray:
    """``noise`` scaled to ``db`` dBFS RMS."""
    return noise * 10 ** ((db - rms_db(noise)) / 20)


def word_frames(textgrid: str | Path, n_frames: int, offset_s: float = 0.0) -> np.ndarray:
    """Bool (n_frames,): 10 ms frames inside a non-empty interval of the ``words`` tier, the
    TextGrid's times shifted by ``offset_s``."""
    from gesture_sim.audio.textgrid import read_textgrid

    mask = np.zeros(n_frames, bool)
    for iv in read_textgrid(textgrid).tier("words"):
        if iv.text.strip():
            a = int(np.ceil((iv.xmin + offset_s) / 0.01))
            b = int(np.floor((iv.xmax + offset_s) / 0.01))
            mask[max(a, 0):max(min(b + 1, n_frames), 0)] = True
    return mask


def room_tone(x: np.ndarray, words: np.ndarray, n: int, min_pause_s: float = 0.4,
              trim_s: float = 0.1) -> np.ndarray:
    """The recording's own pauses — runs of at least ``min_pause_s`` outside words before its
    last word, ``trim_s`` cut at each end so that no word edge the aligner missed comes along —
    mean removed and looped to ``n`` samples. ``words``: the per-frame word mask of ``x``. The
    tail after the last word is left out: a speaker may still make sounds there that nobody
    transcribed (BEAT2 take 1 ends with pitched murmurs at 120–180 Hz), which are no room tone.
    """
    parts = []
    k, m, trim = 0, int(round(min_pause_s * 100)), int(round(trim_s * 100))
    last = int(np.flatnonzero(words)[-1]) if words.any() else len(words)
    words = words[:last]
    while k < len(words):
        if words[k]:
            k += 1
            continue
        j = k
        while j < len(words) and not words[j]:
            j += 1
        if j - k >= m:
            parts.append(x[(k + trim) * _HOP:(j - trim) * _HOP])
        k = j
    if not parts:
        raise ValueError("the recording has no pause long enough for room tone")
    tone = np.concatenate(parts).astype(np.float64)
    tone = tone - tone.mean()
    return np.tile(tone, int(np.ceil(n / len(tone))))[:n]


def line_noise(n: int, rng: np.random.Generator) -> np.ndarray:
    """Telephone-line hiss: white noise band-passed to 300–3400 Hz, unit RMS, ``n`` samples."""
    from scipy.signal import butter, sosfilt

    sos = butter(4, [300, 3400], btype="bandpass", fs=SAMPLE_RATE, output="sos")
    hiss = sosfilt(sos, rng.standard_normal(n))
    return hiss / np.sqrt(np.mean(hiss**2))


def hum(n: int, mains_hz: float = 60.0) -> np.ndarray:
    """Mains hum (fundamental and harmonics 2, 3, 5 falling as 1/h), unit RMS."""
    t = np.arange(n) / SAMPLE_RATE
    h = sum(np.sin(2 * np.pi * mains_hz * k * t + k) / k for k in (1, 2, 3, 5))
    return h / np.sqrt(np.mean(h**2))


def click(n: int, at: int, peak_db: float = -40.0, width: int = 16) -> np.ndarray:
    """``n`` samples of silence with one raised-cosine click of ``peak_db`` dBFS at ``at``."""
    out = np.zeros(n)
    out[at:at + width] = 10 ** (peak_db / 20) * np.hanning(width)[: max(0, min(width, n - at))]
    return out


def noisy_recording(x: np.ndarray, words: np.ndarray, level_db: float, lead_s: float = 6.0,
                    seconds: float | None = None, seed: int = 0) -> np.ndarray:
    """A real recording under real-sounding noise that starts ``lead_s`` before it and goes on
    under it: room tone (the recording's own pauses, ``words`` its word mask) at ``level_db``
    dBFS, line hiss 6 dB and hum 10 dB below that, and a click 10 dB above it at 2.5 s. Only the
    first ``seconds`` of ``x`` are used (None: all; the room tone comes from all of it).
    Returns float32 samples; the recording's times move by ``lead_s``."""
    full = np.asarray(x, dtype=np.float64)
    x = full if seconds is None else full[: int(seconds * SAMPLE_RATE)]
    lead = int(lead_s * SAMPLE_RATE)
    n = lead + len(x)
    rng = np.random.default_rng(seed)
    noise = (at_level(room_tone(full, words, n), level_db)
             + at_level(line_noise(n, rng), level_db - 6)
             + at_level(hum(n), level_db - 10)
             + click(n, min(int(2.5 * SAMPLE_RATE), n - 16), level_db + 10))
    return (np.concatenate([np.zeros(lead), x]) + noise).astype(np.float32)
