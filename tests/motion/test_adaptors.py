"""Self-touches (adaptors) are found from the humanoid's kinematics and never play unprompted."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gesture_sim import DEFAULT_LIBRARY_DIR
from gesture_sim.motion import adaptors
from gesture_sim.motion.adaptors import (
    MIN_HOLD_S,
    MIN_TOUCH_SHARE,
    SELF_TOUCH_TAG,
    TOUCH_GAP_M,
    head_touch,
)

ROOT = Path(__file__).resolve().parents[2]
#: The right arm's joints and two poses of them (rad), solved on the humanoid: the fingers of the
#: right hand at the chin (1 cm surface gap), and a beat's stroke 0.4 m in front of the chest.
ARM = ("right_shoulder_flex", "right_shoulder_abduct", "right_shoulder_twist",
       "right_elbow_flex", "right_forearm_twist", "right_wrist_flex")
CHIN = np.array([0.34, -0.40, -0.77, 2.28, 0.27, 0.37])
BEAT = np.array([0.41, -0.11, -0.06, 1.55, 0.14, 0.16])


def _segment(pose: np.ndarray, hold: int, ramp: int = 8) -> np.ndarray:
    """Frames (2 ramp + hold, 6): from the hanging arm to ``pose``, held, and back."""
    up = np.linspace(0.0, 1.0, ramp, endpoint=False)[:, None] * pose
    return np.concatenate([up, np.repeat(pose[None], hold, axis=0), up[::-1]])


def test_a_hand_at_the_chin_is_a_self_touch_and_a_beat_is_not() -> None:
    touch = head_touch()
    assert touch.gaps(CHIN[None], ARM)[0, 1] <= TOUCH_GAP_M          # the right hand
    assert touch.gaps(BEAT[None], ARM).min() >= 0.1                    # far from the head
    assert touch.gaps(np.zeros((1, len(ARM))), ARM).min() >= 0.1       # arms hanging
    assert touch.is_adaptor(_segment(CHIN, hold=14), ARM)
    assert not touch.is_adaptor(_segment(BEAT, hold=14), ARM)
    # a hand passing the chin for a moment is no self-touch: under a quarter of the frames
    brief = _segment(CHIN, hold=2, ramp=12)
    assert 0 < touch.touches(brief, ARM).mean() < MIN_TOUCH_SHARE
    assert not touch.is_adaptor(brief, ARM)


def test_a_short_hold_at_the_chin_is_a_self_touch_a_sweep_past_the_face_is_not() -> None:
    """The hold rule: a hand held at the chin for MIN_HOLD_S (8 frames at 30 fps) inside a
    longer gesture is an adaptor though its touches are far under a quarter of the frames; a
    hand swept to the chin and away, or held there one frame short of the hold, is not."""
    touch = head_touch()
    hold = adaptors.hold_frames(MIN_HOLD_S, 30.0)
    assert hold == 8
    beat = _segment(BEAT, hold=24)

    def inside(frames: int) -> np.ndarray:       # approach, hold at the chin, retreat, a beat
        return np.concatenate([_segment(CHIN, hold=frames, ramp=12), beat])

    held = inside(hold)
    t = touch.touches(held, ARM)
    assert t.mean() < MIN_TOUCH_SHARE / 2 and adaptors.longest_run(t) >= hold
    assert touch.is_adaptor(held, ARM, fps=30.0)
    assert not touch.is_adaptor(held, ARM, hold_s=None)          # the share alone misses it
    assert not touch.is_adaptor(held, ARM, fps=60.0)             # 8 frames at 60 fps: 0.13 s
    short = inside(hold - 1)
    assert 0 < adaptors.longest_run(touch.touches(short, ARM)) < hold
    assert not touch.is_adaptor(short, ARM)
    # a sweep: from the beat's stroke to the chin and straight back, in a longer segment
    s = np.linspace(0.0, 1.0, 12)[:, None]
    sweep = np.concatenate([beat, BEAT + s * (CHIN - BEAT), BEAT + s[::-1] * (CHIN - BEAT), beat])
    t = touch.touches(sweep, ARM)
    assert t.any() and adaptors.longest_run(t) < hold
    assert not touch.is_adaptor(sweep, ARM)
    # a duck-typed library at 30 fps reads the hold from its frame rate
    segs = [held, short, sweep]
    lib = SimpleNamespace(segments=segs, joint_names=ARM, segment_qpos=lambda i: segs[i],
                          fps=30.0)
    assert adaptors.adaptor_segments(lib).tolist() == [True, False, False]
    assert adaptors.longest_run(np.array([1, 1, 0, 1, 1, 1, 0], bool)) == 3
    assert adaptors.longest_run(np.zeros(0, bool)) == 0


def test_adaptor_segments_reads_a_duck_typed_library() -> None:
    segs = [_segment(CHIN, hold=14), _segment(BEAT, hold=14), _segment(CHIN, hold=20)]
    lib = SimpleNamespace(segments=segs, joint_names=ARM, segment_qpos=lambda i: segs[i])
    assert adaptors.adaptor_segments(lib).tolist() == [True, False, True]
    assert adaptors.adaptor_segments(lib, [0, 1]).tolist() == [True, False, False]
    foreign = SimpleNamespace(segments=segs, joint_names=("a", "b", "c", "d", "e", "f"),
                              segment_qpos=lambda i: segs[i])
    from gesture_sim.errors import GestureSimError

    with pytest.raises(GestureSimError):
        adaptors.adaptor_segments(foreign)


@pytest.fixture(scope="module")
def shipped():
    from gesture_sim.motion.library import MotionLibrary

    return MotionLibrary.load(DEFAULT_LIBRARY_DIR)


def test_the_control_library_leaves_self_touches_out_of_the_co_speech_choice(
        shipped, monkeypatch) -> None:
    from gesture_sim.control.inputs import ControlLibrary

    untagged = np.array([not shipped.clips[s.clip].tags for s in shipped.segments])
    plain = ControlLibrary.from_motion_library(shipped)
    # the shipped library as measured: co-speech = untagged segments that are no self-touch
    assert np.array_equal(plain.cospeech, untagged & ~plain.adaptor)
    assert np.array_equal(plain.adaptor, adaptors.adaptor_segments(shipped,
                                                                  np.nonzero(untagged)[0]))
    # pretend the detector found two self-touches among the co-speech segments
    found = np.zeros(len(shipped.segments), bool)
    found[np.nonzero(untagged)[0][:2]] = True
    monkeypatch.setattr(adaptors, "adaptor_segments", lambda lib, idx=None, **k: found.copy())
    lib = ControlLibrary.from_motion_library(shipped)
    assert np.array_equal(lib.adaptor, found)
    assert np.array_equal(lib.cospeech, untagged & ~found) and lib.cospeech.any()
    assert set(lib.segments_with_tag(SELF_TOUCH_TAG)) == set(np.nonzero(found)[0])
    assert SELF_TOUCH_TAG in lib.all_tags()              # a label, as the emblems are
    assert lib.fingerprint != shipped.fingerprint        # a policy for the old mask is refused
    # a library of nothing but self-touches keeps them co-speech (the mask stays non-empty)
    monkeypatch.setattr(adaptors, "adaptor_segments", lambda lib, idx=None, **k: untagged.copy())
    only = ControlLibrary.from_motion_library(shipped)
    assert np.array_equal(only.cospeech, untagged) and not only.adaptor.any()


def test_library_info_reports_the_shares(capsys) -> None:
    from gesture_sim.cli import main

    assert main(["library", "info", str(DEFAULT_LIBRARY_DIR), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    kinds = info["segment_kinds"]
    assert set(kinds) == {"cospeech", "emblem", "adaptor", "acting"}
    assert sum(k["segments"] for k in kinds.values()) == info["segments"]
    assert sum(k["seconds_share"] for k in kinds.values()) == pytest.approx(1.0, abs=0.01)
    assert info["adaptor_rule"]["touch_gap_m"] == TOUCH_GAP_M
    assert main(["library", "info", str(DEFAULT_LIBRARY_DIR)]) == 0
    assert "adaptor" in capsys.readouterr().out


def _speech_files() -> list[Path]:
    """The repository's real speech files, each content once."""
    files = [ROOT / "tests/data/audio/jfk.wav", ROOT / "tests/data/pipeline/beat2_scott_0_2_2.wav",
             *sorted((ROOT / "assets/audio").glob("*.wav"))]
    seen, out = set(), []
    for f in files:
        digest = hashlib.sha256(f.read_bytes()).hexdigest()
        if digest not in seen:
            seen.add(digest)
            out.append(f)
    return out


def test_no_self_touch_plays_unprompted_on_real_speech() -> None:
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(physics=False)          # the default method: controller
    lib = pipe.control_library
    touch = head_touch()
    for wav in _speech_files():
        run_file(pipe, wav)
        log = pipe.log
        played = sorted({s for s in log.segments if s >= 0})
        assert len(log.decisions) >= 3 and played, wav.name
        assert not any(lib.adaptor[s] for s in played), wav.name
        assert all(lib.cospeech[d.segment_id] for d in log.decisions), wav.name
        # and the body it drives never holds a hand at the head: no touch in the targets
        gaps = touch.gaps(np.asarray(log.targets), lib.joint_names)
        assert gaps.min() > TOUCH_GAP_M, (wav.name, float(gaps.min()))


def test_a_self_touch_plays_only_when_asked_for(shipped, monkeypatch) -> None:
    """The whole chain on a library with self-touches (a third of the BEAT2 segments, as if the
    detector had found them): the policy trained for it never switches into one without a
    label, and the label ``self_touch`` brings one."""
    from gesture_sim.control.inputs import ControlLibrary, StateModel
    from gesture_sim.feed import run_file
    from gesture_sim.inference.model import GestureModel
    from gesture_sim.loading import train_library_policy
    from gesture_sim.pipeline import GesturePipeline

    sub = shipped.subset(["2_scott_0_1_1", "dataset-2_wave-*"])
    untagged = np.array([not sub.clips[s.clip].tags for s in sub.segments])
    found = np.zeros(len(sub.segments), bool)
    found[np.nonzero(untagged)[0][::3]] = True
    monkeypatch.setattr(adaptors, "adaptor_segments", lambda lib, idx=None, **k: found.copy())
    lib = ControlLibrary.from_motion_library(sub)
    model = GestureModel.load(DEFAULT_LIBRARY_DIR / "model")
    policy = train_library_policy(lib, StateModel.from_inference(model))
    pipe = GesturePipeline(sub, model, policy, control_library=lib, physics=False)
    assert SELF_TOUCH_TAG in pipe.labels
    run_file(pipe, ROOT / "tests/data/audio/jfk.wav", labels=[(2.0, SELF_TOUCH_TAG)])
    decisions = pipe.log.decisions
    unlabelled = [d for d in decisions if d.kind != "label"]
    assert len(unlabelled) >= 5 and not any(found[d.segment_id] for d in unlabelled)
    served = [d for d in decisions if d.kind == "label"]
    assert served and found[served[0].segment_id] and 2.0 <= served[0].t <= 3.0
