"""The timeline of a ``chiu14`` run names its belief's rows: the 14 gestural signs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SPEECH = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"      # 4 s of read speech


def test_a_chiu14_timeline_shows_the_signs(tmp_path) -> None:
    from gesture_sim.app.render import timeline_data
    from gesture_sim.app.timeline import plot_timeline
    from gesture_sim.feed import run_file
    from gesture_sim.inference.sign_model import SIGNS
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method="chiu14", physics=False)
    data = timeline_data(run_file(pipe, SPEECH))
    assert tuple(data.state_names) == SIGNS and data.state_velocity is None
    assert np.asarray(data.belief).shape[1] == len(SIGNS)
    out = tmp_path / "t.png"
    plot_timeline(data, out)
    assert out.stat().st_size > 10_000
    # another method keeps its hidden states
    other = timeline_data(run_file(GesturePipeline.create(physics=False), SPEECH))
    assert other.state_names is None
