"""Nothing moves before the first word: a real take after 6 s of real-sounding noise (room tone
from its own pauses, line hiss, hum, a click; the noise goes on under the speech), through the
whole pipeline with physics, at -30, -45 and -60 dBFS."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.sources import load_audio
from gesture_sim.feed import run_file
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics.points import EVAL_FPS, POINT_NAMES, PointFK, trace_positions
from gesture_sim.pipeline import GesturePipeline
from gesture_sim.testing import noise as nz

from . import stimuli as st

DATA = Path(__file__).resolve().parents[1] / "data"
TAKE = DATA / "pipeline" / "beat2_scott_0_2_2.wav"
TAKE_TG = DATA / "textgrids" / "2_scott_0_2_2.TextGrid"
LEAD_S = 6.0
WRISTS = [POINT_NAMES.index("left_wrist"), POINT_NAMES.index("right_wrist")]

pytestmark = pytest.mark.xdist_group("noise_before_speech")


@pytest.fixture(scope="module")
def pipe() -> GesturePipeline:
    return GesturePipeline.create(seed=0)


@pytest.mark.slow
@pytest.mark.parametrize("level_db", [-30.0, -45.0, -60.0])
def test_no_gesture_until_the_first_word(tmp_path, pipe, level_db) -> None:
    x, _ = load_audio(TAKE)
    words = nz.word_frames(TAKE_TG, -(-len(x) // 160))
    first = LEAD_S + float(np.argmax(words)) * 0.01      # the first word, on the mix's clock
    y = nz.noisy_recording(x, words, level_db, LEAD_S, seconds=12.0)
    path = st.write(tmp_path / "noisy.wav", y)
    run_file(pipe, path)
    log = pipe.log
    starts = [d.t for d in log.decisions if not d.costs.get("continue") and d.t < first]
    assert not starts, starts
    assert not [t for t in log.strokes if t < first]
    pos = trace_positions(pipe.trace(), PointFK())
    wrist = mm.joint_speeds(pos, EVAL_FPS)[:, WRISTS].mean(axis=1)
    assert wrist[: int(first * EVAL_FPS)].max() < 0.05
    # and the speech is gestured to: strokes soon after the first word, hands moving
    assert [t for t in log.strokes if first <= t < first + 2.0], log.strokes[:5]
    assert wrist[int(first * EVAL_FPS):].max() > 0.5
