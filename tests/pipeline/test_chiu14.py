"""``--method chiu14`` (Chiu 2014): real speech through the pipeline without physics; the
chosen segments carry the predicted signs, words are heard only once said, and without words
(live) it runs on prosody alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.control.sign_chooser import SIGNS, SignChooser
from gesture_sim.feed import run_file
from gesture_sim.inference.sign_model import SignFilter
from gesture_sim.pipeline import GesturePipeline

SPEECH = Path(__file__).resolve().parents[1] / "data" / "audio" / "arctic_a0007.wav"
#: timed words planted on the 4-s file (lexicon words: never -> Whole, i -> Deictic.Self)
WORDS = [(0.35, 0.6, "i"), (0.6, 1.0, "never"), (1.0, 1.3, "said"), (1.3, 1.6, "everything"),
         (2.0, 2.3, "all"), (2.3, 2.8, "the"), (2.8, 3.2, "time")]


@pytest.fixture(scope="module")
def pipe():
    return GesturePipeline.create(method="chiu14", physics=False)


def test_chiu14_runs_real_speech_and_realises_the_predicted_signs(pipe) -> None:
    run = run_file(pipe, SPEECH, words=WORDS)
    chooser, filt = pipe.controller, pipe.filter
    assert isinstance(chooser, SignChooser) and isinstance(filt, SignFilter)
    assert run.duration == pytest.approx(4.0, abs=0.01)
    segs = np.asarray(pipe.log.segments)
    assert (segs >= 0).sum() > 30                 # it gestured while the speech lasted
    assert chooser.choices, "no segment was chosen"
    for _t, predicted, seg, seg_sign in chooser.choices:
        i = SIGNS.index(predicted)
        if chooser.pool_source[i] in ("co-speech", "emblem"):
            assert seg_sign == predicted          # the segment carries the predicted sign
        assert seg in chooser.pools[i]
    assert pipe.filter.n_states == len(SIGNS)
    # "never / everything / all" call for Whole: it is predicted and played
    assert "Whole" in {c[1] for c in chooser.choices}
    # the dictionary's words were heard, and only after they ended
    assert {c[2] for c in filt.heard_cues} >= {"Whole"}, filt.heard_cues
    assert filt.heard_words == len(WORDS)


def test_chiu14_without_words_runs_on_prosody_alone(pipe) -> None:
    pipe.filter.set_words(None)           # as a live pipeline is built: no transcript
    run_file(pipe, SPEECH)
    filt = pipe.filter
    assert filt.words == [] and not filt.builder.words and not filt.heard_cues
    assert pipe.controller.choices
    assert all(seg in pipe.controller.pools[SIGNS.index(p)]
               for _, p, seg, _ in pipe.controller.choices)
    assert "Whole" not in {c[1] for c in pipe.controller.choices}    # the words made it


def test_render_text_gives_chiu14_the_aligned_words(tmp_path) -> None:
    """``render --text`` aligns the transcript for the lips and hands its words, with their
    aligned times, to a method that reads words (``run_file(words=...)``)."""
    from gesture_sim.app.render import speech_phones
    from gesture_sim.audio.sources import load_audio

    jfk = SPEECH.parent / "jfk.wav"
    text = tmp_path / "jfk.txt"
    text.write_text("And so my fellow Americans ask not what your country can do for you "
                    "ask what you can do for your country\n", encoding="utf-8")
    samples, _ = load_audio(jfk)
    phones, source, words = speech_phones(samples, "auto", None, text)
    assert phones and "aligned" in source
    assert [w.text.lower() for w in words][:4] == ["and", "so", "my", "fellow"]
    starts = [w.start_s for w in words]
    assert starts == sorted(starts) and 0.0 <= starts[0] and words[-1].end_s <= 11.1
    assert speech_phones(samples, "off", None, text)[2] is None
