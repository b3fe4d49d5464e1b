"""Live words (gesture_sim.audio.live_words): known speech from espeak-ng is recognised with
times inside it and emitted after it, emission is causal and deterministic, the worker never
blocks ``push`` (drops are counted), and the sign filter reveals a pushed word only at its
``t_emitted``."""

from __future__ import annotations

import shutil
import subprocess
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pocketsphinx")

from gesture_sim.audio.live_words import (  # noqa: E402
    LiveWord,
    LiveWords,
    LiveWordsSettings,
    LiveWordsStats,
    recognise_words,
)
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock  # noqa: E402
from gesture_sim.errors import GestureSimError  # noqa: E402

needs_espeak = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="needs espeak-ng")

SENTENCES = ("the president said that the economy is growing",
             "i think it is very important to get a good sleep during the weekend")


def _wer(ref: list[str], hyp: list[str]) -> float:
    d = np.arange(len(hyp) + 1)
    for i, r in enumerate(ref, 1):
        prev, d = d, np.empty_like(d)
        d[0] = i
        for j, h in enumerate(hyp, 1):
            d[j] = min(prev[j] + 1, d[j - 1] + 1, prev[j - 1] + (r != h))
    return float(d[-1]) / len(ref)


@pytest.fixture(scope="module")
def speech(tmp_path_factory) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """The two sentences, 0.5 s of silence before, between (0.8 s) and after; with the spans
    (s) where each sentence is loud."""
    if shutil.which("espeak-ng") is None:
        pytest.skip("needs espeak-ng")
    from scipy.io import wavfile

    from gesture_sim.audio.sources import resample_to_16k

    tmp: Path = tmp_path_factory.mktemp("say")
    parts, spans, t = [np.zeros(SAMPLE_RATE // 2, np.float32)], [], 0.5
    for k, text in enumerate(SENTENCES):
        wav = tmp / f"s{k}.wav"
        subprocess.run(["espeak-ng", "-v", "en-us+f2", "-s", "140", "-w", str(wav), text],
                       check=True, capture_output=True)
        sr, data = wavfile.read(wav)
        x = resample_to_16k(data.astype(np.float32) / 32768.0, int(sr))
        loud = np.flatnonzero(np.abs(x) > 0.02)
        spans.append((t + loud[0] / SAMPLE_RATE, t + loud[-1] / SAMPLE_RATE))
        parts += [x, np.zeros(int(0.8 * SAMPLE_RATE) if k == 0 else SAMPLE_RATE // 2,
                              np.float32)]
        t += len(x) / SAMPLE_RATE + len(parts[-1]) / SAMPLE_RATE
    return np.concatenate(parts), spans


@pytest.fixture(scope="module")
def heard(speech) -> tuple[list[LiveWord], LiveWordsStats]:
    stats = LiveWordsStats()
    return recognise_words(speech[0], stats=stats), stats


@needs_espeak
def test_known_speech_gives_its_words_with_times_inside_it(speech, heard) -> None:
    x, spans = speech
    words, stats = heard
    ref = " ".join(SENTENCES).split()
    assert _wer(ref, [w.text for w in words]) <= 0.5
    for w in words:
        assert any(a - 0.3 <= w.start_s < w.end_s <= b + 0.3 for a, b in spans), w
        assert w.t_emitted >= w.end_s - 1e-9
        assert w.t_emitted <= len(x) / SAMPLE_RATE + 1e-6
    assert [w.t_emitted for w in words] == sorted(w.t_emitted for w in words)
    assert [w.start_s for w in words] == sorted(w.start_s for w in words)
    assert stats.utterances >= 2 and stats.dropped_blocks == 0
    assert stats.recognised_s < stats.decoded_s  # the silence is not decoded
    assert 0 < stats.core_share < 1.5


@needs_espeak
def test_causal_the_first_half_never_yields_words_of_the_second(speech, heard) -> None:
    x, _ = speech
    full = heard[0]
    n = len(x) // 2 // 160 * 160  # inside the second sentence
    half_t = n / SAMPLE_RATE
    half = recognise_words(x[:n])
    assert half, "the first sentence is heard"
    assert all(w.start_s < half_t and w.end_s <= half_t + 1e-9 for w in half)
    assert all(w.t_emitted <= half_t + 1e-9 for w in half)
    # what the full run had decided by then is exactly what the half run decided
    before = [w for w in full if w.t_emitted <= half_t]
    assert before == half[:len(before)]
    assert len(before) >= 3


@needs_espeak
def test_whole_file_mode_is_deterministic_and_threaded_matches(speech, heard) -> None:
    x, _ = speech
    n = int(2.6 * SAMPLE_RATE)  # the first sentence
    ref = recognise_words(x[:n], LiveWordsSettings(emit="utterance"))
    assert ref and all(w.final for w in ref)
    rec = LiveWords(LiveWordsSettings(emit="utterance"), max_queue_s=60)  # unpaced: keep all
    got = []
    for i in range(0, n, 160):
        rec.push(AudioBlock(x[i:i + 160], i / SAMPLE_RATE))
        got.extend(rec.poll())
    got.extend(rec.finish(timeout_s=60))
    rec.close()
    # a second run, in another thread with other timing, gives the same words and times
    assert got == ref
    assert rec.stats.dropped_blocks == 0 and rec.stats.decoded_s == pytest.approx(2.6)


def test_push_never_blocks_and_counts_drops() -> None:
    rec = LiveWords(max_queue_s=0.1)
    gate = threading.Event()
    feed = rec._decoder.feed

    def slow_feed(samples, t_start):  # a decoder stuck until the gate opens
        gate.wait(30)
        return feed(samples, t_start)

    rec._decoder.feed = slow_feed
    block = np.zeros(160, np.float32)
    for i in range(100):  # 1 s of audio while the worker is stuck: push returns every time
        rec.push(AudioBlock(block, i * 0.01))
    assert not gate.is_set()
    s = rec.stats
    assert 85 <= s.dropped_blocks <= 90 and s.dropped_s == pytest.approx(0.01 * s.dropped_blocks)
    assert s.max_backlog_s <= 0.1 + 1e-9 and s.backlog_s > 0
    assert rec.poll() == []
    gate.set()
    rec.finish(timeout_s=30)
    rec.close()
    assert s.restarts >= 1  # the gap left by the drops restarts the stream
    assert s.decoded_s == pytest.approx(1.0 - s.dropped_s)
    with pytest.raises(GestureSimError, match="after finish"):
        rec.push(AudioBlock(block, 2.0))


def test_settings_are_checked() -> None:
    with pytest.raises(GestureSimError, match="emit"):
        LiveWordsSettings(emit="sometimes")
    with pytest.raises(GestureSimError):
        LiveWordsSettings(poll_s=0)


def test_the_sign_filter_reveals_a_pushed_word_at_its_t_emitted() -> None:
    from gesture_sim.contracts import Syllable
    from gesture_sim.inference import sign_model as sm

    words = [(k + 0.2, k + 0.6, "alpha" if k % 3 == 0 else "then") for k in range(30)]
    spans = [(k, k + 1.0, "Whole" if k % 3 == 0 else "Beats") for k in range(30)]
    syl = [Syllable(k + 0.1, k + 0.4, k + 0.5, 120.0, 60.0, True) for k in range(30)]
    cfg = replace(sm.SignModelSettings(min_count=1, iterations=30))
    model = sm.train_on_takes([sm.LabelledTake("t", 30.0, syl, words, spans)], cfg,
                              tagger="rules")
    f = model.new_filter()
    alpha = model.layout.vocabulary.index("alpha")
    lex = model.layout.blocks()["words"]
    # said 2.0-2.5 s, known at 3.2 s: later than word_latency_s after its end
    assert f.push_words([LiveWord(2.0, 2.5, "alpha", 3.2)]) == 1
    for t in np.arange(0.0, 3.2 - 1e-6, 1 / 30):
        f.step(float(t))
        assert not any(alpha in v for v in f.builder.words.values())
    f.step(3.2)
    assert f.builder.row(2)[lex][alpha] == 1.0 and f.heard_words == 1
    f.reset()  # a new stream: the live words are gone
    assert f.words == [] and f.heard_words == 0
    f.step(4.0)
    assert not any(alpha in v for v in f.builder.words.values())
    # words given in advance win: live words are not taken
    g = model.new_filter([(2.0, 2.5, "alpha")])
    assert g.push_words([(5.0, 5.5, "alpha", 6.0)]) == 0
