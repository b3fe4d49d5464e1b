"""Words said as utterances of their own are recognised; words inside running speech are not."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.keywords import KeywordTable, spot_file, transcript_keywords
from gesture_sim.audio.sources import load_audio
from gesture_sim.audio.utterances import UtteranceRecognizer

DATA = Path(__file__).resolve().parents[1] / "data"
needs_espeak = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="needs espeak-ng")


def _say(tmp: Path, text: str, voice: str = "en-us+f5") -> np.ndarray:
    wav = tmp / "say.wav"
    subprocess.run(["espeak-ng", "-v", voice, "-w", str(wav), text], check=True,
                   capture_output=True)
    x, _ = load_audio(wav)
    return x


def _run(rec: UtteranceRecognizer, x: np.ndarray) -> list:
    hits = []
    for i in range(0, len(x), 160):
        hits += rec.push(x[i:i + 160], i / 16000)
    return hits + rec.finish()


@needs_espeak
def test_a_standalone_yes_is_recognised_when_it_ends(tmp_path) -> None:
    gap = np.zeros(8000, np.float32)
    yes = _say(tmp_path, "Yes.")
    x = np.concatenate([gap, yes, gap])
    rec = UtteranceRecognizer()
    hits = _run(rec, x)
    assert [(h.word, h.label) for h in hits] == [("yes", "respond")]
    h = hits[0]
    end = (len(gap) + len(yes)) / 16000
    # heard where it was said, known just after the utterance closed (hangover 0.25 s)
    assert 0.4 <= h.t_start < h.t_end <= end + 0.1
    assert h.t_end <= h.t_emitted <= end + 0.45
    assert rec.utterances == 1


def test_running_speech_is_not_decoded_and_gives_no_words() -> None:
    """Twenty seconds of a real monologue: every utterance is longer than the limit (none is
    decoded), so no greeting can be misheard in it."""
    x, _ = load_audio(DATA / "inference" / "beat2_scott_0_3_3_first20s.wav")
    rec = UtteranceRecognizer()
    assert _run(rec, x) == []
    assert rec.decoded_s < 2.5          # at most one short utterance looked at


def test_words_without_a_library_label_are_not_listened_for() -> None:
    rec = UtteranceRecognizer(labels=["bow"])
    assert set(rec.words.values()) == {"bow"}
    assert not UtteranceRecognizer(labels=["nothing"]).active


@needs_espeak
def test_the_spotter_reports_utterance_words(tmp_path) -> None:
    gap = np.zeros(8000, np.float32)
    x = np.concatenate([gap, _say(tmp_path, "Yes."), gap])
    table = KeywordTable.load()
    hits = spot_file(x, table, labels=["respond"])
    assert [h.word for h in hits] == ["yes"]


def test_a_transcript_gives_the_utterance_words_too(tmp_path) -> None:
    words = tmp_path / "w.txt"
    words.write_text("0.5 0.9 hello\n1.0 1.2 thank\n1.2 1.5 you\n2.0 2.3 okay\n")
    hits = transcript_keywords(words, KeywordTable.load())
    assert [(h.word, h.label) for h in hits] == [("hello", "wave"), ("thank you", "bow"),
                                                 ("okay", "respond")]
