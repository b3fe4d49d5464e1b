"""The lips form the speech, through the pipeline and the physics, with known answers:
espeak-ng says a sentence full of /p b m/ between open vowels; its text, force-aligned to the
audio, gives the phones; the simulated lips must close on the bilabials and open on the
vowels — and without phones (the loudness jaw) they do not close on them."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.feed import run_file
from gesture_sim.pipeline import GesturePipeline
from gesture_sim.signals.face_rig import LIP_RADIUS_M
from gesture_sim.sim import humanoid as hm
from tests.pipeline.stimuli import HAVE_TOOLS, concat, say, silence

pytestmark = pytest.mark.skipif(not HAVE_TOOLS, reason="espeak-ng and sox are needed")
TEXT = "bob put the map by my bag"
OPEN = {"AA", "AE", "AH", "AO", "AW", "AY"}


def _gap_mm(pipe: GesturePipeline) -> tuple[np.ndarray, np.ndarray]:
    tr = pipe.trace()
    col = {n: i for i, n in enumerate(hm.ACTUATED_JOINTS)}
    q = tr.q
    gap = (LIP_RADIUS_M * np.sin(q[:, col["jaw_open"]]) - q[:, col["lower_lip_raise"]]
           + q[:, col["upper_lip_raise"]])
    return tr.time - tr.time[0], 1e3 * gap


@pytest.fixture(scope="module")
def speech() -> dict:
    from gesture_sim.audio.phones import align_transcript

    x, _ = concat([silence(0.4), say(TEXT, speed=140), silence(0.6)])
    phones = list(align_transcript(x, 16000, TEXT).phones)
    return {"x": x, "phones": phones}


def _run(x: np.ndarray, phones) -> GesturePipeline:
    pipe = GesturePipeline.create(seed=0, phones=phones)
    run_file(pipe, y=x, sr=16000)
    return pipe


def test_aligned_phones_close_the_lips_on_p_b_m_and_open_them_on_vowels(speech) -> None:
    phones = speech["phones"]
    bilabial = [(p.start_s, p.end_s) for p in phones if p.label in ("P", "B", "M")]
    vowels = [(p.start_s, p.end_s) for p in phones if p.label in OPEN]
    assert len(bilabial) >= 7 and len(vowels) >= 4, [p.label for p in phones]
    t, gap = _gap_mm(_run(speech["x"], phones))
    closed = [gap[(t >= a) & (t <= b)].min() <= 1.5 for a, b in bilabial]
    opened = [gap[(t >= a) & (t <= b)].max() >= 4.0 for a, b in vowels]
    assert np.mean(closed) >= 0.9, closed
    assert np.mean(opened) >= 0.8, opened
    # the degraded mode (no phones): the jaw follows the loudness, the lips do not close
    t0, gap0 = _gap_mm(_run(speech["x"], None))
    closed0 = [gap0[(t0 >= a) & (t0 <= b)].min() <= 1.5 for a, b in bilabial]
    assert np.mean(closed0) < np.mean(closed) - 0.3


def test_recognised_phones_move_the_lips_live(speech) -> None:
    """The live path: phones recognised from the audio as it comes, shown once known."""
    pipe = _run(speech["x"], "recognise")
    mouth = pipe._layer("mouth")
    assert mouth is not None and not pipe.signals.loudness_jaw
    t, gap = _gap_mm(pipe)
    speaking = (t > 0.6) & (t < len(speech["x"]) / 16000 - 0.6)
    assert gap[speaking].max() >= 4.0                    # the mouth opens while speaking
    assert (gap[speaking] <= 1.5).mean() > 0.05          # and closes now and then
    assert np.all(np.abs(gap[t < 0.3]) < 0.5)            # nothing before the speech
