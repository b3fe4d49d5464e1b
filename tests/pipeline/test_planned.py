"""Speech known ahead (issue 51): a text-to-speech voice with its word timings (espeak-ng words
said one by one, so every word's span is known exactly) through the planned method; and the
planned method without the speech ahead (live) is the causal controller step for step."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.sources import iter_blocks, load_audio
from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.loading import load_stack
from gesture_sim.pipeline import GesturePipeline

from . import stimuli as st

DATA = Path(__file__).resolve().parents[1] / "data"
#: Monosyllabic content words: the stressed vowel is the word's only vowel.
WORDS = ("stop", "big", "red", "dogs", "jump", "fast", "cold", "lamps", "ships", "burn",
         "grass", "moon", "black", "trains")


@pytest.fixture(scope="module")
def stack():
    return load_stack(None, None, policy=True)


def _pipe(stack, method: str) -> GesturePipeline:
    return GesturePipeline(stack.library, stack.model, stack.policy, method=method,
                           physics=False, control_library=stack.control_library)


def _tts() -> tuple[np.ndarray, list[tuple[float, float, str]]]:
    """Two phrases of espeak-ng words (0.12 s apart) with a 1.5 s pause between, 0.5 s of
    silence first; each word's (start, end, text) known from the concatenation."""
    parts, spans, t = [st.silence(0.5)], [], 0.5
    for i, w in enumerate(WORDS):
        x = st.say(w, speed=160)
        parts += [x, st.silence(1.5 if i == len(WORDS) // 2 - 1 else 0.12)]
        spans.append((t, t + len(x) / SAMPLE_RATE, w))
        t += (len(x) + len(parts[-1])) / SAMPLE_RATE
    return np.concatenate(parts).astype(np.float32), spans


def _play(pipe: GesturePipeline, y: np.ndarray) -> None:
    for block in iter_blocks(y, 160):
        pipe.push_audio(block)
    pipe.finish()


@pytest.mark.skipif(not st.HAVE_TOOLS, reason="needs espeak-ng and sox")
def test_a_tts_voice_known_ahead_gets_its_strokes_on_the_stressed_words(stack) -> None:
    y, words = _tts()
    pipe = _pipe(stack, "planned")
    pipe.reset()
    pipe.expect_speech(y, words=words)            # before playback: audio + timed words
    plan = pipe.motion.plan
    stress = pipe.motion.known.stress
    assert pipe.motion.known.source == "words" and len(stress) == len(WORDS)
    _play(pipe, y)
    strokes = np.asarray(pipe.player.log.strokes)
    assert len(plan.strokes) >= len(WORDS) // 2 and len(strokes) >= len(WORDS) // 2
    # the strokes played are the planned ones (within a control step) ...
    d_play = np.abs(strokes[:, None] - plan.strokes[None, :]).min(axis=1)
    assert np.median(d_play) <= 1.0 / 30 + 1e-9
    # ... and most stressed words have one within 0.15 s (the stroke-to-stress error)
    err = np.abs(stress[:, None] - strokes[None, :]).min(axis=1)
    assert np.mean(err <= 0.15) >= 0.6, err
    # voice onset -> first stroke: the plan prepares before the first word, the stroke on it
    onset = words[0][0]
    first = strokes[strokes >= onset - 0.3][0]
    assert first - onset <= 0.6
    # the 1.5 s pause between the phrases is rest
    mid_a, mid_b = words[len(WORDS) // 2 - 1][1], words[len(WORDS) // 2][0]
    times = np.asarray(pipe.log.step_times)
    segs = np.asarray(pipe.log.segments)
    inside = (times > mid_a + 0.8) & (times < mid_b - 0.35)
    assert inside.any() and np.all(segs[inside] < 0)


def test_planned_without_the_speech_ahead_is_the_causal_controller(stack) -> None:
    y, _ = load_audio(DATA / "audio" / "jfk.wav")
    y = y[: 4 * SAMPLE_RATE]
    out = {}
    for method in ("controller", "planned"):
        pipe = _pipe(stack, method)
        pipe.reset()
        _play(pipe, y)                             # live: no expect_audio, nothing ahead
        out[method] = (np.asarray(pipe.log.targets), list(pipe.log.segments))
        assert method == "controller" or pipe.motion.plan is None
    assert out["planned"][1] == out["controller"][1]
    np.testing.assert_array_equal(out["planned"][0], out["controller"][0])


def test_a_file_with_its_textgrid_is_planned_by_run_file(stack, tmp_path) -> None:
    from gesture_sim.feed import run_file

    y, _ = load_audio(DATA / "audio" / "jfk.wav")
    y = y[: 4 * SAMPLE_RATE]
    grid = tmp_path / "w.TextGrid"
    tiers = {"words": [(0.0, 1.0, ""), (1.0, 1.4, "cat"), (1.4, 4.0, "")],
             "phones": [(0.0, 1.0, ""), (1.0, 1.1, "K"), (1.1, 1.3, "AE1"), (1.3, 1.4, "T"),
                        (1.4, 4.0, "")]}
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0",
             "xmax = 4", "tiers? <exists>", f"size = {len(tiers)}", "item []:"]
    for k, (name, ivs) in enumerate(tiers.items(), 1):
        lines += [f"    item [{k}]:", '        class = "IntervalTier"',
                  f'        name = "{name}"', "        xmin = 0", "        xmax = 4",
                  f"        intervals: size = {len(ivs)}"]
        for j, (a, b, text) in enumerate(ivs, 1):
            lines += [f"        intervals [{j}]:", f"            xmin = {a}",
                      f"            xmax = {b}", f'            text = "{text}"']
    grid.write_text("\n".join(lines) + "\n")
    pipe = _pipe(stack, "planned")
    run_file(pipe, y=y, sr=SAMPLE_RATE, transcript=grid)
    known = pipe.motion.known
    assert known.source == "phones" and known.stress.tolist() == pytest.approx([1.2])
    assert pipe.motion.plan is not None and pipe.motion.costs["planning"].calls == 1


def test_a_requested_emblem_plays_through_the_plan(stack) -> None:
    from gesture_sim.feed import run_file

    y, _ = load_audio(DATA / "audio" / "jfk.wav")
    y = y[: 5 * SAMPLE_RATE]
    pipe = _pipe(stack, "planned")
    run_file(pipe, y=y, sr=SAMPLE_RATE, labels=[(1.5, "wave")])
    assert pipe.motion.plan is not None and pipe.motion.plan.items
    tags = stack.control_library.tags
    times = np.asarray(pipe.log.step_times)
    segs = np.asarray(pipe.log.segments)
    waved = [t for t, s in zip(times, segs, strict=True) if s >= 0 and "wave" in tags[s]]
    assert waved and 1.5 <= waved[0] <= 2.2
    # after the emblem the plan resumes: planned segments play again
    planned = {it.segment for it in pipe.motion.plan.items}
    assert any(s in planned for s in segs[times > waved[-1] + 0.1])
