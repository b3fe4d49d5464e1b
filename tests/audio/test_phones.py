"""Phones with times: the TextGrid reader, PocketSphinx forced alignment, the live recogniser.

Known answers: the phones of a real BEAT2 take; the forced aligner against that take's own
TextGrid on the shipped excerpt (word boundaries within tens of ms); espeak-ng speech (no ground
truth: words in order, increasing, covering the speech; out-of-dictionary words warned, no crash);
the live recogniser's emissions are contiguous, causal, and do not depend on the chunk size.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.phones import (
    ARPABET,
    SIL,
    Phone,
    PhoneRecogniser,
    align_transcript,
    letter_pronunciation,
    normalise_label,
    number_words,
    phones_from_textgrid,
    recognise_phones,
    words_from_textgrid,
)
from gesture_sim.audio.sources import load_audio
from gesture_sim.errors import GestureSimError

TESTS = Path(__file__).resolve().parents[1]
TAKE = TESTS / "data" / "textgrids" / "2_scott_0_2_2.TextGrid"
EXCERPT = TESTS / "data" / "audio" / "beat2_scott_0_2_2_excerpt.wav"  # take 0_2_2, 10-22 s
EXCERPT_T0 = 10.0
needs_espeak = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="needs espeak-ng")


@pytest.fixture(scope="module")
def excerpt() -> np.ndarray:
    x, _ = load_audio(EXCERPT)
    return x


# -- labels and TextGrids --------------------------------------------------------------------


def test_labels_are_normalised() -> None:
    assert normalise_label("ay1") == "AY"
    assert normalise_label("EH2") == "EH"
    assert normalise_label("") == SIL
    assert normalise_label("sp") == SIL
    assert normalise_label("+NSN+") == SIL
    with pytest.raises(GestureSimError):
        normalise_label("QQ")


def test_textgrid_phones_of_a_real_take() -> None:
    phones = phones_from_textgrid(TAKE)
    assert len(phones) > 500
    assert all(p.label in ARPABET for p in phones)
    assert not any(ch.isdigit() for p in phones for ch in p.label)
    starts = np.array([p.start_s for p in phones])
    assert np.all(np.diff(starts) > 0)
    # contiguous, pauses merged
    assert all(abs(a.end_s - b.start_s) < 1e-9 for a, b in zip(phones, phones[1:], strict=False))
    assert not any(a.label == b.label == SIL for a, b in zip(phones, phones[1:], strict=False))
    words = words_from_textgrid(TAKE)
    assert len(words) > 150
    first = words[0]
    assert first.phones and all(first.start_s <= p.centre_s <= first.end_s
                                for p in first.phones)
    milan = next(w for w in words if w.text == "milan")
    assert [p.label for p in milan.phones][:2] == ["M", "IH"]


def test_textgrid_errors_are_one_line(tmp_path) -> None:
    bad = tmp_path / "x.TextGrid"
    bad.write_text("not a textgrid")
    with pytest.raises(GestureSimError) as e:
        phones_from_textgrid(bad)
    assert "\n" not in str(e.value)
    with pytest.raises(GestureSimError, match="tier"):
        phones_from_textgrid(TAKE, tier="nope")


def test_letter_rules_give_arpabet() -> None:
    pron = letter_pronunciation("zorblaxian")
    assert pron and all(p in ARPABET for p in pron)
    assert letter_pronunciation("ship") == ["SH", "IH", "P"]
    assert letter_pronunciation("10") == []
    assert number_words(1984) == ["nineteen", "eighty", "four"]
    assert number_words(105) == ["one", "hundred", "five"]


# -- forced alignment --------------------------------------------------------------------------


def test_alignment_matches_the_takes_textgrid(excerpt) -> None:
    # the excerpt's stretch between two pauses of the TextGrid: 13.8-18.9 s of the take
    a, b = 13.8, 18.9
    x = excerpt[int((a - EXCERPT_T0) * 16000):int((b - EXCERPT_T0) * 16000)]
    ref = [w for w in words_from_textgrid(TAKE) if w.start_s >= a and w.end_s <= b]
    tr = align_transcript(x, 16000, " ".join(w.text for w in ref))
    assert [w.text for w in tr.words] == [w.text for w in ref]
    err = [abs(w.start_s + a - r.start_s) for w, r in zip(tr.words, ref, strict=True)]
    err += [abs(w.end_s + a - r.end_s) for w, r in zip(tr.words, ref, strict=True)]
    assert np.median(err) < 0.04 and np.percentile(err, 90) < 0.1
    # phones: contiguous, cover the audio, the words' phones inside the words
    assert tr.phones[0].start_s == 0.0
    assert abs(tr.phones[-1].end_s - len(x) / 16000) < 0.011
    relax = tr.words[-1]
    assert [p.label for p in relax.phones] == ["R", "IH", "L", "AE", "K", "S"]


def _say(tmp: Path, text: str) -> tuple[np.ndarray, int]:
    from scipy.io import wavfile

    wav = tmp / "say.wav"
    subprocess.run(["espeak-ng", "-v", "en-us", "-w", str(wav), text], check=True,
                   capture_output=True)
    sr, data = wavfile.read(wav)
    return data.astype(np.float32) / 32768.0, int(sr)


@needs_espeak
def test_alignment_of_espeak_speech_with_an_unknown_word(tmp_path) -> None:
    text = "The quick brown fox jumps over the lazy zorblax -- and 10 dogs sleep."
    x, sr = _say(tmp_path, text)
    assert sr != 16000  # espeak-ng writes 22050 Hz: the aligner resamples
    with pytest.warns(UserWarning, match="zorblax"):
        tr = align_transcript(x, sr, text)
    assert tr.fallback == ("zorblax",) and tr.skipped == ("--",)
    words = [w.text for w in tr.words]
    assert words == ["the", "quick", "brown", "fox", "jumps", "over", "the", "lazy", "zorblax",
                     "and", "ten", "dogs", "sleep"]
    starts = np.array([w.start_s for w in tr.words])
    ends = np.array([w.end_s for w in tr.words])
    assert np.all(np.diff(starts) > 0) and np.all(ends > starts)
    assert np.all(starts[1:] >= ends[:-1] - 1e-9)
    dur = len(x) / sr
    # the speech: where espeak's samples are not silent
    loud = np.flatnonzero(np.abs(x) > 0.02)
    on, off = loud[0] / sr, loud[-1] / sr
    assert abs(starts[0] - on) < 0.15 and abs(ends[-1] - off) < 0.2
    assert ends[-1] <= dur + 1e-6
    assert all(w.phones for w in tr.words)


def test_alignment_errors_are_one_line(excerpt) -> None:
    with pytest.raises(GestureSimError, match="no words"):
        with pytest.warns(UserWarning, match="without letters"):
            align_transcript(excerpt[:16000], 16000, "  % -- ")
    with pytest.raises(GestureSimError, match="too short"):
        align_transcript(excerpt[:1600], 16000, "the rest of the time i usually go")


# -- the live recogniser -----------------------------------------------------------------------


def _check_stream(em, dur: float, t0: float = 0.0) -> None:
    assert em
    phones = [e.phone for e in em]
    assert abs(phones[0].start_s - t0) < 1e-9
    for a, b in zip(phones, phones[1:], strict=False):
        assert abs(a.end_s - b.start_s) < 1e-9  # contiguous
        assert b.end_s > b.start_s
    assert abs(phones[-1].end_s - (t0 + dur)) < 0.002  # (a resampler's delay)
    em_t = np.array([e.emitted_s for e in em])
    assert np.all(np.diff(em_t) >= 0)
    assert all(e.emitted_s >= e.phone.end_s - 1e-9 for e in em)  # causal
    assert all(p.label in ARPABET for p in phones)


def test_allphone_recogniser_is_causal_and_chunk_independent(excerpt) -> None:
    x = excerpt[:16000 * 5]
    em = recognise_phones(x, 16000, chunk_s=0.01)
    _check_stream(em, 5.0)
    speech = [e for e in em if e.phone.label != SIL]
    assert len(speech) > 25  # about 12 phones/s of speech
    lat = np.array([e.latency_s for e in speech])
    assert np.median(lat) < 0.2 and lat.max() < 0.6
    em2 = recognise_phones(x, 16000, chunk_s=0.0371)
    assert [e.phone for e in em2] == [e.phone for e in em]
    assert [e.emitted_s for e in em2] == [e.emitted_s for e in em]
    # utterances restarted at pauses (bounded memory) keep the stream contiguous
    rec = PhoneRecogniser(max_utt_s=1.0)
    em3 = [e for i in range(0, len(x), 800) for e in rec.push(x[i:i + 800])] + rec.finish()
    assert rec.stats.utterances > 1
    _check_stream(em3, 5.0)


def test_recogniser_resamples_and_keeps_the_stream_clock(excerpt) -> None:
    from scipy.signal import resample_poly

    x = resample_poly(excerpt[:16000 * 3], 3, 1).astype(np.float32)  # 48 kHz
    rec = PhoneRecogniser(sr=48000, t0=100.0)
    em = []
    for i in range(0, len(x), 480 * 2):
        em += rec.push(x[i:i + 960])
    em += rec.finish()
    _check_stream(em, 3.0, t0=100.0)
    assert rec.finish() == []
    with pytest.raises(GestureSimError):
        rec.push(x[:10])


def test_words_mode_gives_words_and_their_phones(excerpt) -> None:
    x = excerpt[int(4.0 * 16000):int(8.9 * 16000)]  # "rest of the time ... and relax"
    rec = PhoneRecogniser("words")
    em = []
    for i in range(0, len(x), 1600):
        em += rec.push(x[i:i + 1600])
    em += rec.finish()
    _check_stream(em, len(x) / 16000)
    words = [w.text for w, _ in rec.words]
    assert len(words) >= 5 and {"library", "interesting", "books"} & set(words)
    assert all(t >= w.end_s - 1e-9 for w, t in rec.words)


def test_unknown_mode_is_an_error() -> None:
    with pytest.raises(GestureSimError, match="mode"):
        PhoneRecogniser("grammar")
    assert Phone(0.0, 0.1, "M").centre_s == pytest.approx(0.05)
