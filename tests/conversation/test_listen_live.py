"""``gesture-sim live --listen``: the live loop with the microphone as the partner.

A recording of one person's statements (the espeak-ng dialogue's first turn) is played through
the live path (a file feed in real time, as a microphone would deliver it) into the shipped
pipeline wrapped by :class:`~gesture_sim.app.listening.ListeningPipeline`, with a stand-in
viewer: the avatar must backchannel after the statements' pauses and keep its hands at rest (its
own voice is silent) — the wiring of the microphone to the partner path is what is tested.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from gesture_sim.app.listening import ListeningPipeline
from gesture_sim.app.live import LiveLoop, LiveOptions
from gesture_sim.audio.feeds import FileFeed
from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.errors import GestureSimError
from gesture_sim.pipeline import GesturePipeline
from tests.app.test_live import FakeViewer

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None or shutil.which("sox") is None,
                                reason="needs espeak-ng and sox")


def test_live_listener_nods_to_the_microphone_and_rests(tmp_path: Path) -> None:
    from gesture_sim.testing.dialogue import make_dialogue

    d = make_dialogue(seed=0)
    first = [t for t in d.turns if t.person == 0]
    end = first[0].t_end
    for t in first[1:]:                      # person 0's first turn: utterances 1 s apart
        if t.t_start - end > 1.05:
            break
        end = t.t_end
    n = int((end + 1.2) * SAMPLE_RATE)
    wav = tmp_path / "partner.wav"
    wavfile.write(wav, SAMPLE_RATE, d.channels[:n, 0].astype(np.float32))
    pipe = GesturePipeline.create(listener=True, record=True)
    loop = LiveLoop(ListeningPipeline(pipe), FileFeed(wav, speakers=False),
                    LiveOptions(duration=n / SAMPLE_RATE + 0.3, fps=30, print_keys=False,
                                shadow_size=None),
                    viewer_factory=lambda m, dd, key_callback, **kw: FakeViewer(key_callback))
    stats = loop.run().to_dict()
    assert stats["audio"]["pushed_s"] > 0.8 * n / SAMPLE_RATE
    bcs = pipe.listener.backchannels
    invited = [p for p in d.inviting_pauses if p[0] == 0 and p[1] < end]
    assert invited and len(bcs) >= 1, (invited, bcs)
    assert all(b.invited for b in bcs)
    # the avatar itself said nothing: no segment, hands at rest
    assert all(s < 0 for s in pipe.log.segments)
    tr = pipe.trace()
    hands = tr.sim_sites[:, :2]
    speed = np.max(np.linalg.norm(np.diff(hands, axis=0), axis=2), axis=1) / np.diff(tr.time)
    assert np.percentile(speed[tr.time[1:] > 0.5], 95) < 0.05


def test_listening_needs_a_listener_pipeline() -> None:
    with pytest.raises(GestureSimError):
        ListeningPipeline(object())
