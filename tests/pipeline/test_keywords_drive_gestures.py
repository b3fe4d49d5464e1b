"""Words call for gestures: spoken keywords (espeak-ng, known times) make the pipeline play the
tagged emblems at those words, through the real PocketSphinx spotter; a transcript does the same."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.feed import run_file
from gesture_sim.pipeline import GesturePipeline

from . import stimuli as st

pytestmark = pytest.mark.skipif(not st.HAVE_TOOLS, reason="needs espeak-ng and sox")
pytest.importorskip("pocketsphinx")

PHRASES = [("hello everyone", "wave"), ("thank you so much", "bow"), ("see you later", "bye")]
VOICE = "en-us+f5"           # the spotter's thresholds were set on this voice (BENCHMARKS.md)


@pytest.fixture(scope="module")
def dialogue(tmp_path_factory) -> tuple:
    tmp = tmp_path_factory.mktemp("kw")
    filler = "we talked for a while about the weather and the trip"
    parts, times = [], []
    for phrase, _label in PHRASES:
        parts += [st.say(filler, voice=VOICE), st.silence(0.4)]
        parts.append(st.say(phrase, voice=VOICE))
        parts.append(st.silence(0.6))
    parts.append(st.silence(1.5))                 # time for the last gesture to play
    x, starts = st.concat(parts)
    for i, (_, label) in enumerate(PHRASES):
        k = 4 * i + 2
        times.append((label, starts[k], starts[k] + len(parts[k]) / st.SR))
    path = st.write(tmp / "dialogue.wav", st.gain(x / np.abs(x).max(), -6.0))
    return path, times


def _tagged_spans(pipe: GesturePipeline, label: str) -> np.ndarray:
    lib = pipe.control_library
    segs = np.asarray(pipe.log.segments)
    t = np.asarray(pipe.log.step_times)
    return t[[s >= 0 and label in lib.tags[s] for s in segs]]


def test_spoken_keywords_bring_their_gestures(dialogue) -> None:
    from gesture_sim.audio.keywords import KeywordTable

    path, times = dialogue
    pipe = GesturePipeline.create(physics=False)
    run_file(pipe, path, keywords=KeywordTable.load(None))
    spotted = {w.label for w in pipe.log.words}
    assert {label for label, _, _ in times} <= spotted, pipe.log.words
    for label, t0, t1 in times:
        played = _tagged_spans(pipe, label)
        # the emblem plays after the word was spotted, within 2 s of its end
        assert np.any((played >= t0) & (played <= t1 + 2.0)), (label, t0, t1, played[:5])
    # nothing tagged plays in the filler before the first keyword
    first = times[0][1]
    lib = pipe.control_library
    early = [s for s, t in zip(pipe.log.segments, pipe.log.step_times, strict=True)
             if t < first and s >= 0 and lib.tags[s]]
    assert not early


def test_a_transcript_requests_the_same_gestures(dialogue, tmp_path) -> None:
    from gesture_sim.audio.keywords import KeywordTable

    path, times = dialogue
    lines = []
    for (phrase, _), (_, t0, t1) in zip(PHRASES, times, strict=True):
        words = phrase.split()
        step = (t1 - t0) / len(words)
        lines += [f"{t0 + i * step:.3f} {t0 + (i + 1) * step:.3f} {w}"
                  for i, w in enumerate(words)]
    tr = tmp_path / "words.txt"
    tr.write_text("\n".join(lines) + "\n")
    pipe = GesturePipeline.create(physics=False)
    run_file(pipe, path, keywords=KeywordTable.load(None), transcript=tr)
    for label, t0, t1 in times:
        played = _tagged_spans(pipe, label)
        assert np.any((played >= t0) & (played <= t1 + 2.0)), label
