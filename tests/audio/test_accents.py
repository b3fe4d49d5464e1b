"""The causal accent detector: known-answer stimuli (harmonic tones, espeak-ng speech with
emphasised words, louder and faster halves), causality, gain and block-size invariance,
boundaries at inserted pauses, voice activity and vocal energy."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from gesture_sim.audio.accents import AccentConfig, AccentDetector, analyze_accents, detect_accents
from gesture_sim.audio.prosody import ProsodyConfig, ProsodyTracker
from gesture_sim.audio.sources import iter_blocks, resample_to_16k
from gesture_sim.audio.vad import VadConfig
from gesture_sim.contracts import SAMPLE_RATE

needs_espeak = pytest.mark.skipif(shutil.which("espeak-ng") is None,
                                  reason="espeak-ng binary not installed")
GAIN_12DB = np.float32(10 ** (-12 / 20))
#: Harmonic tones are no voice to a voice-activity detector: the tone tests of the energy rule
#: and the accent detector switch it off (the espeak-ng tests below keep it on).
TONES = ProsodyConfig(vad=VadConfig(engine="off"))


def _silence(s: float) -> np.ndarray:
    return np.zeros(int(round(s * SAMPLE_RATE)), dtype=np.float32)


def _vowel(f0: float, dur: float, amp: float) -> np.ndarray:
    """A harmonic complex (8 harmonics, 1/k amplitudes) with a raised-cosine envelope."""
    t = np.arange(int(dur * SAMPLE_RATE)) / SAMPLE_RATE
    x = sum(np.sin(2 * np.pi * f0 * k * t) / k for k in range(1, 9))
    return (amp * np.sin(np.pi * t / dur) ** 2 * x / 2).astype(np.float32)


def _tone_phrase(n: int, loud: set[int], f0: float = 120.0) -> tuple[np.ndarray, list[float]]:
    """``n`` 0.18 s 'syllables' 0.07 s apart; those in ``loud`` 10 dB louder and 4 semitones
    higher. Returns the signal and the syllable centres (s)."""
    parts, centres, t = [], [], 0.0
    for i in range(n):
        hi = i in loud
        parts.append(_vowel(f0 * (2 ** (4 / 12) if hi else 1.0), 0.18, 0.3 if hi else 0.095))
        centres.append(t + 0.09)
        gap = _silence(0.07)
        parts.append(gap)
        t += 0.18 + len(gap) / SAMPLE_RATE
    return np.concatenate(parts), centres


def test_louder_higher_tone_syllables_are_the_accents() -> None:
    loud = {4, 9, 13, 18}
    x, centres = _tone_phrase(22, loud)
    x = np.concatenate([_silence(0.3), x])
    acc, _ = detect_accents(x, prosody_config=TONES)
    t = np.array([a.t for a in acc])
    for i in loud:
        c = 0.3 + centres[i]
        assert np.any(np.abs(t - (c - 0.03)) <= 0.08), f"no accent on loud syllable {i} ({c})"
    # after the first few syllables (statistics warming up) only the loud ones are accents
    later = t[t > 0.3 + centres[3] + 0.12]
    on_loud = [np.any([abs(tt - (0.3 + centres[i])) <= 0.12 for i in loud]) for tt in later]
    assert all(on_loud)
    for a in acc:
        assert a.t <= a.t_emitted <= a.t + 0.1


def test_rising_edge_comes_before_the_peak() -> None:
    """An accent is emitted while the nucleus is still rising: before its intensity peak."""
    x, centres = _tone_phrase(12, {6, 10})
    acc, _ = detect_accents(x, prosody_config=TONES)
    for i in (6, 10):
        a = min(acc, key=lambda a: abs(a.t - centres[i]))
        assert centres[i] - 0.09 <= a.t < centres[i]  # onset .. peak of a raised cosine
        assert a.t_emitted < centres[i] + 0.09  # known before the syllable ends


def test_gain_and_block_size_invariance() -> None:
    x, _ = _tone_phrase(20, {3, 8, 15})
    ref = detect_accents(x, prosody_config=TONES)
    # -12 dB: the same accent times (the tracker's absolute 30 dB silence floor may flip the
    # first onset frame, which moves the running statistics a little, so not bit-identical)
    quiet = [a.t for a in detect_accents(x * GAIN_12DB, prosody_config=TONES)[0]]
    t = [a.t for a in ref[0]]
    assert len(quiet) == len(t)
    assert np.max(np.abs(np.array(quiet) - t)) <= 0.0101
    for block in (160, 1000, 4096):
        tracker, det = ProsodyTracker(TONES), AccentDetector()
        acc, bnd = [], []
        for b in iter_blocks(x, block):
            tracker.push(b)
            a, d = det.update(tracker)
            acc += a
            bnd += d
        tracker.flush()
        a, d = det.finish(tracker)
        assert (acc + a, bnd + d) == ref


def test_causal_a_truncated_stream_gives_the_same_early_decisions() -> None:
    x, _ = _tone_phrase(24, {4, 10, 17, 21})
    full, full_b = detect_accents(x, prosody_config=TONES)
    cut = 3.3  # s
    part, part_b = detect_accents(x[: int(cut * SAMPLE_RATE)], prosody_config=TONES)
    assert len(full) >= 4
    assert [a for a in full if a.t_emitted <= cut] == [a for a in part if a.t_emitted <= cut]
    assert [b for b in full_b if b.t_emitted <= cut] == [
        b for b in part_b if b.t_emitted <= cut and b.kind == "pause"]


def test_silence_gives_nothing_and_resampling_is_handled() -> None:
    acc, bnd = detect_accents(np.zeros(2 * SAMPLE_RATE, dtype=np.float32))
    assert acc == [] and bnd == []
    x, _ = _tone_phrase(16, {5, 11})
    x44 = resample_to_16k(x, SAMPLE_RATE)  # identity check of the helper
    x44 = np.interp(np.arange(int(len(x) * 44100 / 16000)) * 16000 / 44100,
                    np.arange(len(x)), x44).astype(np.float32)
    a16 = [a.t for a in detect_accents(x, prosody_config=TONES)[0]]
    a44 = [a.t for a in detect_accents(x44, sample_rate=44100, prosody_config=TONES)[0]]
    assert len(a16) >= 2
    assert len(a44) == pytest.approx(len(a16), abs=1)
    assert all(np.min(np.abs(np.array(a16) - t)) <= 0.02 for t in a44)


def test_threshold_sets_how_selective_it_is() -> None:
    x, _ = _tone_phrase(24, {4, 10, 17, 21})
    n = [len(detect_accents(x, config=AccentConfig(threshold_sd=s), prosody_config=TONES)[0])
         for s in (-1.5, 0.0, 1.5)]
    assert n[0] > n[1] >= n[2] >= 1


# ------------------------------------------------------------------ espeak-ng speech

def _say(tmp: Path, text: str, speed: int = 160, pitch: int = 50, amp: int = 40) -> np.ndarray:
    """espeak-ng speech as 16 kHz float32, trimmed to 10 ms around the voice."""
    wav = tmp / "say.wav"
    subprocess.run(["espeak-ng", "-w", str(wav), "-s", str(speed), "-p", str(pitch),
                    "-a", str(amp), text], check=True, capture_output=True)
    rate, x = wavfile.read(wav)
    x = resample_to_16k(x.astype(np.float32) / 32768.0, rate).astype(np.float32)
    idx = np.flatnonzero(np.abs(x) > 0.01 * np.abs(x).max())
    return x[max(idx[0] - 160, 0) : idx[-1] + 160]


@pytest.fixture(scope="module")
def emphasis(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A lead-in sentence, then two phrases separated by inserted silences, each with one
    word spoken 10 dB louder and higher ('market', 'river'; stress on the first syllable)."""
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng binary not installed")
    tmp = tmp_path_factory.mktemp("emphasis")
    loud = {"pitch": 75, "amp": 126}
    pieces = [("sil", _silence(0.3)),
              ("lead", _say(tmp, "this is a plain sentence that we say at first, then we go on")),
              ("sil", _silence(0.6)), ("plain", _say(tmp, "we went to the")),
              ("emph", _say(tmp, "market", **loud)), ("plain", _say(tmp, "in the morning and")),
              ("sil", _silence(1.0)), ("plain", _say(tmp, "then we walked to the")),
              ("emph", _say(tmp, "river", **loud)), ("plain", _say(tmp, "by the old house")),
              ("sil", _silence(0.5))]
    spans, t = [], 0.0
    for kind, x in pieces:
        spans.append((kind, t, t + len(x) / SAMPLE_RATE))
        t = spans[-1][2]
    x = np.concatenate([p for _, p in pieces])
    assert np.abs(x).max() < 1.0
    return {"x": x, "spans": spans, "analysis": analyze_accents(x)}


def _per_span(spans: list, accents: list, syllables: list) -> tuple[list, int, int]:
    """(first accent time in each emphasised word or None, accents in plain speech, tracker
    syllables in plain speech)."""
    t = np.array([a.t for a in accents])
    emph, n_acc, n_syl = [], 0, 0
    for kind, a, b in spans:
        inside = t[(t >= a - 0.03) & (t <= b)]
        if kind == "emph":
            emph.append(float(inside[0]) - a if len(inside) else None)
        elif kind == "plain":
            n_acc += len(inside)
            n_syl += sum(a <= s.t_start < b for s in syllables)
    return emph, n_acc, n_syl


@needs_espeak
def test_emphasised_words_get_accents_plain_ones_fewer(emphasis: dict) -> None:
    an = emphasis["analysis"]
    emph, n_acc, n_syl = _per_span(emphasis["spans"], an.accents, an.syllables)
    # default: an accent on the stressed first syllable of each emphasised word
    assert all(e is not None and e <= 0.1 for e in emph), emph
    assert n_syl >= 12 and n_acc <= 0.6 * n_syl
    # a stricter threshold keeps the emphasised words and drops the plain ones
    strict = analyze_accents(emphasis["x"], config=AccentConfig(threshold_sd=1.0))
    emph, n_acc, _ = _per_span(emphasis["spans"], strict.accents, strict.syllables)
    assert all(e is not None and e <= 0.1 for e in emph), emph
    assert n_acc <= 1


@needs_espeak
def test_no_accents_in_silence_and_boundaries_at_the_pauses(emphasis: dict) -> None:
    an = emphasis["analysis"]
    pauses = [(a, b) for kind, a, b in emphasis["spans"] if kind == "sil" and a > 0]
    for a, b in pauses:
        assert not [x for x in an.accents if a + 0.03 < x.t < b], f"accent in silence {a:.2f}"
        # the phrase ends at its last non-silent frame: a weak final fricative ('house')
        # already counts as silence
        near = [d for d in an.boundaries if a - 0.2 <= d.t <= a + 0.05]
        assert len(near) == 1 and near[0].kind == "pause", f"no boundary at {a:.2f}"
        assert 0.2 <= near[0].t_emitted - near[0].t <= 0.35
        assert near[0].t_emitted <= a + 0.35
        # voice activity: not speaking in the middle of the pause, the silence counted
        k = int((0.5 * (a + b)) / 0.01)
        assert not an.speaking[k]
    for b in an.boundaries:
        assert b.t <= b.t_emitted


@needs_espeak
def test_minus_12_db_gives_the_same_accents(emphasis: dict) -> None:
    ref = emphasis["analysis"]
    quiet = analyze_accents(emphasis["x"] * GAIN_12DB)
    tr, tq = [a.t for a in ref.accents], [a.t for a in quiet.accents]
    assert len(tq) == pytest.approx(len(tr), abs=1)
    same = sum(np.min(np.abs(np.array(tq) - t)) <= 0.011 for t in tr)
    assert same >= 0.9 * len(tr)
    assert [(b.t, b.kind) for b in quiet.boundaries] == [(b.t, b.kind) for b in ref.boundaries]
    assert np.max(np.abs(quiet.energy - ref.energy)) < 0.05


@needs_espeak
def test_streaming_state_speaking_silence_and_level(emphasis: dict) -> None:
    x = emphasis["x"]
    _, pause_a, pause_b = [s for s in emphasis["spans"] if s[0] == "sil"][2]
    tracker, det = ProsodyTracker(), AccentDetector()
    seen = {}
    for block in iter_blocks(x, 800):
        tracker.push(block)
        det.update(tracker)
        t = det.t_frame
        if pause_a + 0.5 <= t < pause_a + 0.55:
            seen["pause"] = (det.speaking, det.silence_s)
        if pause_b + 0.3 <= t < pause_b + 0.35:
            seen["speech"] = (det.speaking, det.silence_s, det.level)
    assert seen["pause"][0] is False and 0.45 <= seen["pause"][1] <= 0.75
    assert seen["speech"][0] is True and seen["speech"][1] < 0.2
    assert -4.0 <= seen["speech"][2] <= 4.0


@needs_espeak
def test_energy_is_higher_when_louder_and_faster(tmp_path: Path) -> None:
    text = ("the weather was fine so we walked along the river and talked about the plans "
            "for the summer holiday")
    calm = _say(tmp_path, text, speed=150, amp=40)
    lively = _say(tmp_path, text, speed=210, amp=120)  # +9.5 dB, 40 % faster
    x = np.concatenate([calm, _silence(0.3), lively])
    assert np.abs(x).max() < 1.0
    an = analyze_accents(x)
    n = len(calm) // 160
    e1 = an.energy[:n][an.speaking[:n]].mean()
    e2 = an.energy[n + 30 :][an.speaking[n + 30 :]].mean()
    assert abs(e1) < 0.15
    assert e2 > 0.2 and e2 - e1 > 0.2
    # gain-invariant
    quiet = analyze_accents(x * GAIN_12DB)
    assert np.max(np.abs(quiet.energy - an.energy)) < 0.05
    # the quiet, slow version after the lively one reads as calmer than usual
    back = analyze_accents(np.concatenate([lively, _silence(0.3), calm]))
    m = len(lively) // 160
    assert back.energy[m + 30 :][back.speaking[m + 30 :]].mean() < -0.1


def test_the_energy_averages_are_running_stats_to_the_last_bit() -> None:
    """The detector's short/long exponential averages (inlined for speed) are the means of
    :class:`~gesture_sim.running.RunningStat` with the same weights."""
    from gesture_sim.audio.accents import _Ewmas
    from gesture_sim.running import RunningStat

    rng = np.random.default_rng(2)
    pair = _Ewmas(200.0, 3000.0)
    short = RunningStat(mean=float("nan"), min_weight=1 / 200.0, location="first")
    long = RunningStat(mean=float("nan"), min_weight=1 / 3000.0, location="first")
    for x in (rng.normal(60, 8, 5000) * rng.uniform(0, 2, 5000)).tolist():
        pair.update(x)
        short.update(x)
        long.update(x)
        assert (pair.short, pair.long) == (short.mean, long.mean)
