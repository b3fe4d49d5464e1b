"""The causal prosody tracker: synthetic signals with known answers, real speech sanity,
espeak-ng speech with known syllable counts, block-size invariance and awkward audio."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from gesture_sim.audio.prosody import ProsodyConfig, ProsodyTracker, analyze_file, analyze_samples
from gesture_sim.audio.sources import FileSource, load_audio
from gesture_sim.audio.vad import VadConfig
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
JFK, ARCTIC, BEAT2 = (DATA / "jfk.wav", DATA / "arctic_a0007.wav",
                      DATA / "beat2_scott_0_2_2_excerpt.wav")
#: Harmonic tones are no voice to a voice-activity detector: the tone tests of the energy rule
#: switch it off.
TONES = ProsodyConfig(vad=VadConfig(engine="off"))


def _vowel(f0: float, dur: float, amp: float = 0.3) -> np.ndarray:
    """A harmonic complex (10 harmonics, 1/k amplitudes) with a raised-cosine envelope."""
    t = np.arange(int(dur * SAMPLE_RATE)) / SAMPLE_RATE
    x = sum(np.sin(2 * np.pi * f0 * k * t) / k for k in range(1, 11))
    env = np.sin(np.pi * t / dur) ** 2
    return (amp * env * x / 2).astype(np.float32)


def test_tone_bursts_are_syllables_with_their_pitch() -> None:
    pause = np.zeros(int(0.15 * SAMPLE_RATE), dtype=np.float32)
    f0s = [110.0, 150.0, 200.0, 240.0, 180.0]
    x = np.concatenate([pause] + [np.concatenate([_vowel(f, 0.2), pause]) for f in f0s])
    syl = analyze_samples(x, config=TONES).syllables
    assert len(syl) == len(f0s)
    for s, f, k in zip(syl, f0s, range(len(f0s)), strict=True):
        onset = 0.15 + k * 0.35
        assert s.voiced and s.f0_hz == pytest.approx(f, rel=0.03)
        assert onset - 0.01 <= s.t_start and s.t_end <= onset + 0.2 + 0.04
        assert s.t_end >= s.t_start + 0.08
        assert 0 <= s.t_emitted - s.t_end < 0.2


def test_amplitude_dips_without_silence_split_syllables() -> None:
    """A continuous voiced tone whose level dips 12 dB four times per second."""
    dur = 2.0
    t = np.arange(int(dur * SAMPLE_RATE)) / SAMPLE_RATE
    carrier = sum(np.sin(2 * np.pi * 140 * k * t) / k for k in range(1, 8))
    env_db = -6 * (1 + np.cos(2 * np.pi * 4 * t))  # 0 .. -12 dB, troughs at 0, 0.25, ...
    x = (0.2 * 10 ** (env_db / 20) * carrier).astype(np.float32)
    syl = analyze_samples(x, config=TONES).syllables
    # peaks at 0.125 + 0.25 k: 8 syllables, bounded by troughs every 0.25 s
    assert len(syl) in (7, 8)
    inner = [s.t_end for s in syl[:-1]]
    assert np.allclose(np.round(np.array(inner) / 0.25) * 0.25, inner, atol=0.03)


def test_pure_silence_and_noise_give_no_syllables() -> None:
    assert analyze_samples(np.zeros(SAMPLE_RATE * 2, dtype=np.float32)).syllables == []
    noise = np.random.default_rng(0).normal(0, 1e-3, SAMPLE_RATE * 2).astype(np.float32)
    a = analyze_samples(noise)
    assert a.summary["n_voiced_syllables"] == 0
    assert a.summary["voiced_share"] < 0.05


@pytest.mark.parametrize("path, f0_lo, f0_hi", [
    (ARCTIC, 70, 200),   # male read speech
    (JFK, 120, 350),     # male oratory, raised pitch
    (BEAT2, 80, 260),    # male, conversational monologue
])
def test_real_speech_is_plausible(path: Path, f0_lo: float, f0_hi: float) -> None:
    s = analyze_file(path).summary
    assert 3.0 <= s["syllable_rate"] <= 7.0
    assert 0.5 <= s["voiced_share"] <= 0.97
    assert f0_lo <= s["f0_p5_hz"] < s["f0_p50_hz"] < s["f0_p95_hz"] <= f0_hi
    assert 0.5 * s["duration_s"] <= s["speech_s"] <= s["duration_s"]


def test_jfk_syllable_count_matches_the_text(jfk_analysis) -> None:
    # "And so my fel-low A-mer-i-cans, ask not what your coun-try can do for you,
    #  ask what you can do for your coun-try."  = 28 syllables (counted by hand)
    n = jfk_analysis.summary["n_voiced_syllables"]
    assert abs(n - 28) <= 0.15 * 28


ESPEAK_TEXTS = [
    # (text, syllables counted by hand)
    ("And so my fellow Americans, ask not what your country can do for you.", 19),
    ("The quick brown fox jumps over the lazy dog. She sells sea shells by the sea shore.",
     19),
    ("Yesterday I went to the market and bought seven apples, a loaf of bread and some "
     "cheese.", 22),
]


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng binary not installed")
@pytest.mark.parametrize("text, n_syllables", ESPEAK_TEXTS)
def test_espeak_syllable_count(tmp_path: Path, text: str, n_syllables: int) -> None:
    wav = tmp_path / "tts.wav"
    subprocess.run(["espeak-ng", "-w", str(wav), text], check=True, capture_output=True)
    s = analyze_file(wav).summary
    # Syllable nuclei are voiced; unvoiced segments (loud fricatives) are kept by the tracker
    # as their own observations (Levine 2009 / 2010) but are not syllables of the text.
    assert abs(s["n_voiced_syllables"] - n_syllables) <= 0.15 * n_syllables
    assert abs(s["n_syllables"] - n_syllables) <= 0.25 * n_syllables


@pytest.mark.parametrize("path", [JFK, BEAT2])
def test_block_size_invariance(path: Path) -> None:
    x, _ = load_audio(path)
    ref = analyze_samples(x, None).syllables
    assert len(ref) > 20
    for block in (64, 160, 1000, 4096):
        got = analyze_samples(x, block).syllables
        assert len(got) == len(ref)
        for a, b in zip(got, ref, strict=True):
            assert abs(a.t_start - b.t_start) <= 0.01 and abs(a.t_end - b.t_end) <= 0.01
            assert a.voiced == b.voiced


def test_streaming_equals_whole_file(jfk_analysis) -> None:
    tracker = ProsodyTracker()
    got = []
    for block in FileSource(JFK, block_size=333):
        got.extend(tracker.push(block))
    got.extend(tracker.flush())
    assert got == jfk_analysis.syllables  # identical dataclasses, t_emitted included
    fr = tracker.frames()
    np.testing.assert_array_equal(fr.intensity_db, jfk_analysis.frames.intensity_db)
    np.testing.assert_array_equal(fr.f0_hz, jfk_analysis.frames.f0_hz)


def test_syllables_are_ordered_causal_and_frames_consistent(jfk_analysis) -> None:
    syl, fr = jfk_analysis.syllables, jfk_analysis.frames
    for a, b in zip(syl[:-1], syl[1:], strict=True):
        assert a.t_end <= b.t_start + 1e-9 and a.t_emitted <= b.t_emitted
    assert all(s.t_emitted >= s.t_end for s in syl)
    assert np.allclose(np.diff(fr.times), 0.01)
    assert not np.isfinite(fr.f0_hz[fr.silent]).any()  # no F0 in silence
    assert all((s.f0_hz is None) == (not s.voiced) for s in syl)


def test_stream_start_offset_shifts_times() -> None:
    x, _ = load_audio(ARCTIC)
    tracker = ProsodyTracker()
    out = tracker.push(AudioBlock(x, 100.0)) + tracker.flush()
    ref = analyze_samples(x).syllables
    assert [round(s.t_start - 100.0, 6) for s in out] == [round(s.t_start, 6) for s in ref]


def test_clipping_dc_offset_and_level_changes_are_tolerated(jfk_analysis) -> None:
    x, _ = load_audio(JFK)
    n = jfk_analysis.summary["n_syllables"]
    clipped = np.clip(4 * x, -1, 1)
    dc = x + 0.3
    quiet = x * 0.05  # -26 dB
    for y in (clipped, dc, quiet):
        s = analyze_samples(y).summary
        assert abs(s["n_syllables"] - n) <= 0.2 * n
        assert s["f0_p50_hz"] == pytest.approx(jfk_analysis.summary["f0_p50_hz"], rel=0.1)


def test_float32_wav_matches_int16(tmp_path: Path, jfk_analysis) -> None:
    x, _ = load_audio(JFK)
    path = tmp_path / "f32.wav"
    wavfile.write(path, SAMPLE_RATE, x)
    assert analyze_file(path).syllables == jfk_analysis.syllables


def _pink(n: int, seed: int = 0) -> np.ndarray:
    """Unit-RMS low-passed ("pinkish") noise, (n,)."""
    from scipy.signal import lfilter

    x = lfilter([1.0], [1.0, -0.9], np.random.default_rng(seed).standard_normal(n))
    return x / np.sqrt(np.mean(x**2))


@pytest.mark.parametrize("margin_db, vad, pause_silent",
                         [(None, "off", True), (-1000.0, "off", False), (-1000.0, "silero", True)])
def test_pauses_in_a_noisy_recording_are_silence(margin_db, vad, pause_silent) -> None:
    """Real speech with a 1.5 s pause, under steady noise 20 dB below the speech: the running
    noise floor makes the pause silent (≥ 90 % of its frames) while the speech stays speech;
    without it (``noise_margin_db`` off) and without the voice-activity detector the noise
    20 dB down is above the level-relative threshold (25 dB) and the pause is "speech"; the
    detector alone also makes it silent (the noise is no voice)."""
    x, _ = load_audio(BEAT2)
    x = x.astype(np.float64)[: 6 * SAMPLE_RATE]
    half = 3 * SAMPLE_RATE
    y = np.concatenate([x[:half], np.zeros(int(1.5 * SAMPLE_RATE)), x[half:]])
    frames = y[: len(y) // 320 * 320].reshape(-1, 320)
    e = np.sqrt((frames**2).mean(axis=1))
    speech_rms = np.sqrt(np.mean(e[e > np.median(e)] ** 2))
    noisy = (y + _pink(len(y)) * speech_rms * 10 ** (-20 / 20)).astype(np.float32)
    cfg = ProsodyConfig(vad=VadConfig(engine=vad))
    if margin_db is not None:
        cfg = ProsodyConfig(noise_margin_db=margin_db, vad=VadConfig(engine=vad))
    f = analyze_samples(noisy, config=cfg).frames
    clean = analyze_samples(y.astype(np.float32)).frames
    pause = (f.times > 3.2) & (f.times < 4.3)
    assert (f.silent[pause].mean() >= 0.9) == pause_silent, f.silent[pause].mean()
    speech = (f.times > 0.5) & (f.times < 2.8) & ~clean.silent
    assert f.silent[speech].mean() <= 0.2, f.silent[speech].mean()


def test_a_signal_without_pauses_has_no_noise_floor() -> None:
    """A voiced tone whose level dips 12 dB four times a second never pauses: its troughs are
    not a noise floor, so no frame is silent (without the 20 dB range condition on the floor,
    0.2 s means of the dips would set one and about 60 % of the frames would be silent)."""
    dur = 2.0
    t = np.arange(int(dur * SAMPLE_RATE)) / SAMPLE_RATE
    carrier = sum(np.sin(2 * np.pi * 140 * k * t) / k for k in range(1, 8))
    x = (0.2 * 10 ** (-6 * (1 + np.cos(2 * np.pi * 4 * t)) / 20) * carrier).astype(np.float32)
    assert not analyze_samples(x, config=TONES).frames.silent.any()
