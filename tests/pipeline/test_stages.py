"""The composed step: every registered method against the declared protocols, one speech view per
step, the one switch ramp, and the one feed loop for a file and for samples (``y=, sr=``)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.sources import iter_blocks, load_audio
from gesture_sim.audio.speech import SpeechState
from gesture_sim.contracts import SAMPLE_RATE, BeliefFilter
from gesture_sim.control.protocols import SegmentChooser, StepSelector, SyllableSelector
from gesture_sim.control.ramp import SwitchRamp
from gesture_sim.errors import GestureSimError
from gesture_sim.feed import run_file
from gesture_sim.loading import load_stack
from gesture_sim.methods import METHODS, REGISTRY, method_spec
from gesture_sim.pipeline import GesturePipeline
from gesture_sim.stages import SelectorMotion, SyllableMotion, TimedMotion

DATA = Path(__file__).resolve().parents[1] / "data"
JFK = DATA / "audio" / "jfk.wav"
PKG = Path(__file__).resolve().parents[2] / "gesture_sim"


@pytest.fixture(scope="module")
def stack():
    return load_stack(None, None, policy=True, graph=True)


@pytest.mark.parametrize("method", METHODS)
def test_every_registered_method_meets_its_protocols(stack, method: str) -> None:
    spec = REGISTRY[method]
    pipe = GesturePipeline(stack.library, stack.model, stack.policy, method=method,
                           physics=False, control_library=stack.control_library,
                           graph=stack.graph)
    motion = pipe.motion
    assert isinstance(motion.filter, BeliefFilter)
    if spec.timed:
        assert isinstance(motion, TimedMotion) and pipe.player is not None
        assert isinstance(motion.chooser, SegmentChooser)
    elif isinstance(motion, SyllableMotion):
        assert isinstance(motion.chooser, SyllableSelector)
        assert motion.filter is motion.chooser.filter
    else:
        assert isinstance(motion, SelectorMotion)
        assert isinstance(motion.chooser, StepSelector)
    assert (pipe.signals is None) == (not spec.hears)
    # labels: the policy's, or the chooser's own tags (MIMiC's graph serves them too)
    assert bool(pipe.labels) == (spec.policy or bool(getattr(motion.chooser, "tags", ())))
    assert bool(pipe.labels) == (spec.policy or method == "mimic")


def test_an_unknown_method_is_one_clear_error() -> None:
    with pytest.raises(GestureSimError, match="unknown method 'nope'; choose one of controller"):
        method_spec("nope")


def test_no_method_is_tested_by_name_outside_the_registry() -> None:
    """``if method == "..."`` (or ``x.method == "..."``) belongs to the registry alone
    (evaluation's own kinds "real" and "mismatched" are not pipeline methods)."""
    found = []
    for path in PKG.rglob("*.py"):
        if path.name == "methods.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            left = getattr(node, "left", None)
            named = (isinstance(left, ast.Name) and left.id == "method") or (
                isinstance(left, ast.Attribute) and left.attr == "method")
            if isinstance(node, ast.Compare) and named:
                consts = [c.value for c in node.comparators if isinstance(c, ast.Constant)]
                if any(c in METHODS for c in consts):
                    found.append(f"{path.relative_to(PKG)}:{node.lineno}")
    assert not found, found


def test_each_step_sees_only_what_was_emitted_by_then() -> None:
    samples, _ = load_audio(JFK)
    state = SpeechState(frames=True)
    emitted = []
    for block in iter_blocks(samples, 160):
        emitted += state.push(block).syllables
    emitted += state.flush().syllables
    seen, n_frames, t = [], 0, 0.0
    while t <= len(samples) / SAMPLE_RATE + 0.5:
        heard = state.view(t)
        assert all(s.t_emitted <= t + 1e-9 for s in heard.syllables)
        assert all(a.t_emitted <= t + 1e-9 for a in heard.accents)
        seen += heard.syllables
        if heard.frames is not None:
            n_frames += len(heard.frames.known)
        t += 1.0 / 30.0
    assert len(emitted) > 10 and seen == emitted         # each syllable exactly once, in order
    assert n_frames == state.tracker.n_frames


def test_the_switch_ramp_blends_in_n_steps_then_follows() -> None:
    ramp = SwitchRamp(3)
    a, b = np.zeros(2), np.ones(2)
    assert ramp(b) is b                                  # no ramp started: the stream itself
    ramp.start(a)
    out = [float(ramp(b)[0]) for _ in range(5)]
    w = [x * x * (3 - 2 * x) for x in (0.25, 0.5, 0.75)]
    np.testing.assert_allclose(out[:3], w)
    assert out[3:] == [1.0, 1.0]
    zero = SwitchRamp(0)
    zero.start(a)
    assert zero(b) is b


def test_samples_feed_like_the_file(stack) -> None:
    """``run_file(y=, sr=)`` at 16 kHz is the file's run; at 48 kHz it is resampled."""
    pipe = GesturePipeline(stack.library, stack.model, stack.policy, physics=False,
                           control_library=stack.control_library)
    samples, _ = load_audio(JFK)
    a = run_file(pipe, JFK)
    ref = np.asarray(a.pipeline.log.targets).copy()
    b = run_file(pipe, y=samples, sr=SAMPLE_RATE)
    np.testing.assert_array_equal(np.asarray(b.pipeline.log.targets), ref)
    up = np.repeat(samples, 3)                                  # 48 kHz, same content
    c = run_file(pipe, y=up, sr=48_000)
    assert abs(c.duration - a.duration) < 1e-3
    with pytest.raises(GestureSimError, match="sr="):
        run_file(pipe, y=samples)
    with pytest.raises(GestureSimError, match="not both"):
        run_file(pipe, JFK, y=samples, sr=SAMPLE_RATE)
    with pytest.raises(GestureSimError, match="silent"):
        run_file(pipe, y=np.zeros(16000, np.float32), sr=SAMPLE_RATE)


def test_mimic_serves_the_librarys_labels(stack) -> None:
    """Okwechime's MIMiC graph switches into a segment with a requested tag (issue 34 item 4):
    its labels are reachable as the controller's are."""
    pipe = GesturePipeline(stack.library, stack.model, stack.policy, method="mimic",
                           physics=False, control_library=stack.control_library,
                           graph=stack.graph)
    assert "wave" in pipe.labels
    run = run_file(pipe, JFK, labels=[(1.0, "wave")])
    served = [d for d in run.pipeline.log.decisions if d.kind == "label"]
    assert served and served[0].t >= 1.0
    assert "wave" in stack.library.segments[served[0].segment_id].tags
