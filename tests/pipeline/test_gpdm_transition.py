"""``transition="gpdm"``: Chiu 2014's GPDM transitions as the timing layer's switch path, on
real speech. The choices and the playhead are the ramp's; the targets differ from a switch on
(the path, then the joint-speed bound catching up), nowhere else."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.feed import run_file
from gesture_sim.loading import load_stack
from gesture_sim.motion.gpdm import GPDMPath
from gesture_sim.pipeline import GesturePipeline

JFK = Path(__file__).resolve().parents[1] / "data" / "audio" / "jfk.wav"


@pytest.fixture(scope="module")
def stack():
    return load_stack(None, None, policy=True)


def _run(stack, transition: str):
    pipe = GesturePipeline(stack.library, stack.model, stack.policy, physics=False,
                           control_library=stack.control_library, transition=transition)
    run_file(pipe, JFK)
    decisions = [(d.segment_id, d.frame) for d in pipe.log.decisions]
    return pipe, np.asarray(pipe.log.targets), decisions


def test_gpdm_transitions_change_only_the_switch_windows(stack) -> None:
    ramp_pipe, ramp_q, ramp_d = _run(stack, "ramp")
    gpdm_pipe, gpdm_q, gpdm_d = _run(stack, "gpdm")
    assert isinstance(gpdm_pipe.player.path, GPDMPath) and ramp_pipe.player.path is None
    assert gpdm_d == ramp_d and len(ramp_d) >= 3            # the same choices
    differ = np.abs(gpdm_q - ramp_q).max(axis=1) > 1e-9
    segments = np.asarray(ramp_pipe.log.segments)
    switches = set(np.nonzero(segments[1:] != segments[:-1])[0] + 1)
    starts = [i for i in np.nonzero(differ)[0] if i == 0 or not differ[i - 1]]
    assert len(starts) >= 3                                 # the switches are crossed anew
    assert set(starts) <= switches                          # ... and only from a switch on
    assert (~differ).sum() >= 30 and np.isfinite(gpdm_q).all()     # a second alike at least


def test_an_unknown_transition_is_one_clear_error(stack) -> None:
    with pytest.raises(GestureSimError, match="unknown transition 'spline'"):
        GesturePipeline(stack.library, stack.model, stack.policy, physics=False,
                        control_library=stack.control_library, transition="spline")


def test_render_hands_the_transition_to_the_pipeline(monkeypatch, tmp_path, capsys) -> None:
    """``render --transition gpdm`` builds its pipeline with it; a conversation refuses it in
    one line, before any work."""
    from gesture_sim import cli

    seen: dict = {}

    def create(*args, **kwargs):
        seen.update(kwargs)
        raise GestureSimError("stopped by the test")

    monkeypatch.setattr(GesturePipeline, "create", staticmethod(create))
    base = ["render", str(JFK), "-o", str(tmp_path / "a.mp4"), "--width", "160", "--height",
            "90", "--quality", "fast", "--workers", "1", "--transition", "gpdm"]
    assert cli.main(base) == 2 and "stopped by the test" in capsys.readouterr().err
    assert seen["transition"] == "gpdm"
    assert cli.main([*base, "--two"]) == 2
    err = capsys.readouterr().err
    assert "--transition gpdm" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.mp4").exists()
