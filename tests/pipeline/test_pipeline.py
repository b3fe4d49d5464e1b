"""The causal pipeline: determinism, causality, block-size invariance, and a 60 s real-speech run
whose simulated body must pass the physics-plausibility thresholds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.sources import iter_blocks, load_audio
from gesture_sim.feed import run_file
from gesture_sim.pipeline import GesturePipeline

DATA = Path(__file__).resolve().parents[1] / "data"
JFK = DATA / "audio" / "jfk.wav"
BEAT2_62S = DATA / "pipeline" / "beat2_scott_0_2_2.wav"


@pytest.fixture(scope="module")
def kinematic_pipeline() -> GesturePipeline:
    """The default library and model, without physics (decisions only)."""
    return GesturePipeline.create(physics=False)


def _decisions(pipe: GesturePipeline) -> list[tuple[float, int, int, str]]:
    return [(round(d.t, 6), d.segment_id, d.frame, d.kind) for d in pipe.log.decisions]


def test_block_size_does_not_change_the_decisions(kinematic_pipeline: GesturePipeline) -> None:
    runs = {}
    for block in (64, 160, 4096):
        run_file(kinematic_pipeline, JFK, block_size=block)
        runs[block] = (_decisions(kinematic_pipeline),
                       np.asarray(kinematic_pipeline.log.beliefs).copy())
    assert len(runs[160][0]) > 5
    for block in (64, 4096):
        assert runs[block][0] == runs[160][0]
        np.testing.assert_allclose(runs[block][1], runs[160][1], atol=1e-9)


def test_a_step_only_uses_audio_it_has_heard(kinematic_pipeline: GesturePipeline) -> None:
    """Truncating the audio after 5 s leaves every earlier step unchanged (causality)."""
    samples, _ = load_audio(JFK)
    pipe = kinematic_pipeline
    pipe.reset()
    for block in iter_blocks(samples[: 5 * 16000], 160):
        pipe.push_audio(block)
    short_beliefs = np.asarray(pipe.log.beliefs).copy()
    short = _decisions(pipe)
    run_file(pipe, JFK)
    full = _decisions(pipe)
    n = len(short_beliefs)
    assert n == int(5 * 30) + 1
    np.testing.assert_allclose(np.asarray(pipe.log.beliefs)[:n], short_beliefs, atol=1e-12)
    assert full[: len(short)] == short


def test_the_belief_follows_the_speech(kinematic_pipeline: GesturePipeline) -> None:
    run_file(kinematic_pipeline, JFK)
    beliefs = np.asarray(kinematic_pipeline.log.beliefs)
    entropy = -(beliefs * np.log(np.clip(beliefs, 1e-12, None))).sum(axis=1)
    assert np.allclose(beliefs.sum(axis=1), 1.0, atol=1e-6)
    assert entropy.std() > 0.05
    assert len(set(beliefs.argmax(axis=1).tolist())) >= 3


@pytest.mark.slow
def test_sixty_seconds_of_real_speech_is_physically_plausible() -> None:
    """A 62 s take the model never saw, through the whole pipeline with physics."""
    from gesture_sim.metrics.physics import physics_metrics
    from gesture_sim.metrics.selection import selection_summary

    pipe = GesturePipeline.create(seed=3)
    run = run_file(pipe, BEAT2_62S)
    m = physics_metrics(pipe.trace())
    assert m.duration_s == pytest.approx(62.0, abs=0.1)
    assert not m.fell
    assert m.assist_impulse_per_s == 0.0
    assert m.foot_skate_mm_s < 2.0           # feet planted
    assert m.ground_penetration_max_mm < 5.0
    assert m.joint_limit_max_excess_deg < 2.0
    assert m.saturation_share_any < 0.01
    # hands no faster than real co-speech motion, at transitions and interruptions too (issue
    # 17): the speaker's own take (BEAT2, tracked) has p99.9 3.16 m/s, all real clips 7.5;
    # measured here p99 2.83, p99.9 3.32, max 3.63 m/s (seeds 0-2: max 3.3-4.0); and no
    # start-up jump (the render begins at rest: 0.016 m/s in the first 0.5 s)
    trace = pipe.trace()
    speed = np.linalg.norm(np.diff(trace.sim_sites[:, :2], axis=0), axis=-1) / trace.dt
    assert np.percentile(speed, 99) <= 3.0
    assert np.percentile(speed, 99.9) < 4.0
    assert speed.max() < 5.0
    assert speed[: int(0.5 / trace.dt)].max() < 0.05
    sel = selection_summary(run)
    # a varied sequence from the 67 co-speech segments: many distinct ones, no immediate
    # repeats; interruptions happen (early terminations for accents, Levine 2009), and a
    # quarter or more of the segments still play out
    assert sel["distinct_segments"] >= 0.3 * sel["segments_played"]
    assert sel["back_to_back_repeats"] == 0
    assert 0.0 < sel["interrupted_share"] <= 0.75
    assert sel["unrequested_emblems"] == 0
    assert sel["source_order_share"] <= 0.5              # not the training take replayed


def test_a_requested_label_brings_the_tagged_gesture(kinematic_pipeline: GesturePipeline) -> None:
    """A semantic label (as from a key press or a keyword) at 3 s leads, within the policy's
    stated delay, to a segment tagged with it; an unknown label is a clear error."""
    from gesture_sim.errors import GestureSimError

    pipe = kinematic_pipeline
    delay_frames = int(pipe.controller.policy.meta["max_label_delay_frames"])
    for label in ("wave", "bow"):
        run_file(pipe, JFK, labels=[(3.0, label)])
        lib = pipe.control_library
        times = np.asarray(pipe.log.step_times)
        segs = np.asarray(pipe.log.segments)
        window = (times >= 3.0) & (times <= 3.0 + (delay_frames + 2) / lib.fps)
        assert any(label in lib.tags[s] for s in segs[window]), label
        assert any(d.kind == "label" for d in pipe.log.decisions)
    with pytest.raises(GestureSimError, match="unknown semantic label"):
        run_file(pipe, JFK, labels=[(1.0, "juggle")])


@pytest.mark.parametrize("kind", ["silent", "empty", "text"])
def test_render_refuses_bad_audio_with_one_line(tmp_path: Path, kind: str) -> None:
    import subprocess
    import sys
    import wave

    audio = tmp_path / f"{kind}.wav"
    if kind == "silent":
        with wave.open(str(audio), "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(16000)
            w.writeframes(np.zeros(16000, np.int16).tobytes())
    elif kind == "empty":
        audio.write_bytes(b"")
    else:
        audio.write_text("not audio")
    out = tmp_path / "out.mp4"
    proc = subprocess.run([sys.executable, "-m", "gesture_sim.cli", "render", str(audio), "-o",
                           str(out)], capture_output=True, text=True)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gesture-sim: error:")
    assert not out.exists()


def test_a_model_that_does_not_fit_the_library_is_refused(tmp_path: Path) -> None:

    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.errors import GestureSimError
    from gesture_sim.inference.model import GestureModel

    model = GestureModel.load(DEFAULT_LIBRARY_DIR / "model")
    model.param_normalisation = dict(model.param_normalisation,
                                     W=[2.0 * w for w in model.param_normalisation["W"]])
    model.save(tmp_path / "other")
    with pytest.raises(GestureSimError, match="does not fit library"):
        GesturePipeline.create(model=tmp_path / "other", physics=False)


@pytest.mark.parametrize("method", ["dcnf", "mimic", "levine09", "random", "random_sync"])
def test_every_method_runs_on_real_speech_with_co_speech_segments(method: str) -> None:
    """Every selection method plays the library on real speech: segments change, only
    co-speech segments without a label, and the speech-timed ones rest in the pauses."""
    pipe = GesturePipeline.create(method=method, physics=False)
    run_file(pipe, JFK)
    lib = pipe.control_library
    played = [d.segment_id for d in pipe.log.decisions if not d.costs.get("continue")]
    assert len(set(played)) >= 3
    assert all(lib.cospeech[s] for s in played)
    beliefs = np.asarray(pipe.log.beliefs)
    assert np.allclose(beliefs.sum(axis=1), 1.0, atol=1e-6)
    if method in ("dcnf", "mimic", "random_sync"):
        assert "rest" in pipe.log.modes            # JFK pauses: the hands rest
