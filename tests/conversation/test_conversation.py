"""Two people in one scene, with known answers (a scripted espeak-ng dialogue in two voices).

Each person gestures in its own turns and rests in the other's; the listener backchannels
0.2-1.5 s after the pauses that invite it (a statement's low-pitch end), on at least half of them,
never while it speaks itself; both bodies stand on their own (no fall, no assist, feet planted);
``render --two`` / ``render --rttm`` write a video of both with the roles of the turns.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from gesture_sim.app.conversation import conversation_summary  # noqa: E402
from gesture_sim.conversation import (  # noqa: E402
    Conversation,
    conversation_channels,
    run_conversation,
)

pytestmark = [pytest.mark.skipif(shutil.which("espeak-ng") is None
                                 or shutil.which("sox") is None, reason="needs espeak-ng and sox"),
              pytest.mark.xdist_group("conversation")]    # one physics run of the dialogue

#: A nod counts as answering a pause when its reference peaks this long after the pause start.
NOD_WINDOW_S = (0.2, 1.5)


@pytest.fixture(scope="module")
def dialogue():
    from gesture_sim.testing.dialogue import make_dialogue

    return make_dialogue(seed=0)


@pytest.fixture(scope="module")
def stack():
    from gesture_sim.loading import load_stack

    return load_stack(None, None, policy=True)


def _conversation(stack, seeds=(0, 1), physics=True) -> Conversation:
    return Conversation(stack.library, stack.model, stack.policy, seeds=seeds, physics=physics,
                        control_library=stack.control_library)


@pytest.fixture(scope="module")
def run(dialogue, stack):
    """The stereo dialogue through the two-person scene with physics (turns from the channels)."""
    voices, turns = conversation_channels(channels=dialogue.channels)
    return run_conversation(_conversation(stack), voices, turns)


@pytest.fixture(scope="module")
def summary(run):
    return conversation_summary(run)


def _own(dialogue, p):
    return [(t.t_start, t.t_end) for t in dialogue.turns if t.person == p]


def test_turns_found_in_the_channels_match_the_script(run, dialogue) -> None:
    found = sorted((t.person, t.t_start, t.t_end) for t in run.turns)
    truth = sorted((t.person, t.t_start, t.t_end) for t in dialogue.turns)
    assert len(found) == len(truth)
    for (pf, af, bf), (pt, at, bt) in zip(found, truth, strict=True):
        assert pf == pt and abs(af - at) < 0.15 and abs(bf - bt) < 0.15


def test_each_person_gestures_in_its_own_turns_and_rests_in_the_others(summary,
                                                                       dialogue) -> None:
    for p, person in enumerate(summary["people"]):
        assert len(person["segments"]) >= 3, p
        # every segment starts inside one of its own turns (0.5 s of slack for the end)
        assert person["segment_starts_in_own_turns"] == 1.0, p
        hands = person["hands_in_partner_turns"]
        assert hands["rest_share"] >= 0.9, (p, hands)
        assert hands["wrist_speed_p95_m_s"] < 0.1, (p, hands)


def test_listener_nods_after_the_pauses_that_invite_them(summary, dialogue) -> None:
    answered = 0
    for speaker, t0, _t1 in dialogue.inviting_pauses:
        listener = summary["people"][1 - speaker]
        delays = [b["t_peak"] - t0 for b in listener["backchannels"]]
        answered += any(NOD_WINDOW_S[0] <= d <= NOD_WINDOW_S[1] for d in delays)
    assert answered >= 0.5 * len(dialogue.inviting_pauses), (answered,
                                                              len(dialogue.inviting_pauses))
    for p, person in enumerate(summary["people"]):
        assert person["backchannels"], p
        assert person["backchannels_while_speaking"] == 0, p
        for b in person["backchannels"]:           # no nod while this person speaks
            assert not any(a <= b["t_peak"] <= e for a, e in _own(dialogue, p)), (p, b)


def test_listener_is_not_a_nodding_machine(summary, dialogue) -> None:
    """Backchannels answer pauses: none mid-utterance, about one per inviting pause at most."""
    for p, person in enumerate(summary["people"]):
        partner = [(t.t_start, t.t_end) for t in dialogue.turns if t.person == 1 - p]
        for b in person["backchannels"]:
            assert not any(a + 0.3 < b["t_emitted"] < e for a, e in partner), (p, b)
    total = sum(len(person["backchannels"]) for person in summary["people"])
    pauses = len(dialogue.inviting_pauses) + len(dialogue.other_pauses) + len(
        dialogue.turns)
    assert total <= pauses


def test_both_bodies_stand_on_their_own(summary) -> None:
    for p, person in enumerate(summary["people"]):
        phys = person["physics"]
        assert phys["fell"] is False, p
        assert phys["assist_impulse_per_s"] == 0.0, p
        assert phys["foot_skate_mm_s"] < 2.0, (p, phys)
        assert phys["ground_penetration_max_mm"] < 5.0, (p, phys)


def test_mono_with_a_diarization_gives_the_same_roles(dialogue, stack, tmp_path: Path) -> None:
    from gesture_sim.audio.turns import read_rttm, write_rttm

    rttm = tmp_path / "d.rttm"
    write_rttm(rttm, dialogue.turns)
    turns, names = read_rttm(rttm)
    assert names == ("A", "B")
    voices, turns = conversation_channels(mono=dialogue.mono, turns=turns)
    run = run_conversation(_conversation(stack, physics=False), voices, turns)
    summary = conversation_summary(run)
    for p, person in enumerate(summary["people"]):
        assert person["segments"] and person["segment_starts_in_own_turns"] == 1.0, p
        assert person["backchannels_while_speaking"] == 0, p


def test_render_two_people_from_an_rttm(dialogue, tmp_path: Path, capsys) -> None:
    """The command: a short mono mix + RTTM -> an mp4 of both bodies, the timeline and metrics
    whose roles are the RTTM's."""
    import imageio_ffmpeg

    from gesture_sim import cli
    from gesture_sim.audio.turns import write_rttm
    from gesture_sim.contracts import SAMPLE_RATE, Turn

    cut = 9.0       # the first two turns are enough for the command
    n = int(cut * SAMPLE_RATE)
    from scipy.io import wavfile

    mono = tmp_path / "short.wav"
    wavfile.write(mono, SAMPLE_RATE, (dialogue.mono[:n] * 32767).astype(np.int16))
    rttm = tmp_path / "short.rttm"
    # the turns of the cut audio, cut at its end (a turn may run past it by 0.5 s at most)
    kept = [Turn(t.person, t.t_start, min(t.t_end, cut)) for t in dialogue.turns
            if t.t_start < cut - 0.5]
    write_rttm(rttm, kept)
    out, tl, met = tmp_path / "talk.mp4", tmp_path / "talk.png", tmp_path / "talk.json"
    rc = cli.main(["render", str(mono), "--rttm", str(rttm), "-o", str(out), "--width", "320",
                   "--height", "180", "--quality", "fast", "--workers", "1", "--timeline",
                   str(tl), "--metrics", str(met), "--json"])
    assert rc == 0
    doc = json.loads(met.read_text())
    assert [(t["person"], round(t["t_start"], 3)) for t in doc["turns"]] == [
        (t.person, round(t.t_start, 3)) for t in kept]
    assert len(doc["people"]) == 2 and doc["frames"] == int(np.ceil(cut * 30))
    assert tl.stat().st_size > 10_000
    # a frame in the middle shows two people: the blue shirt left, the red one right
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    w, h = meta["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]
    img = frames[len(frames) // 2].astype(int)
    blue = (img[..., 2] > img[..., 0] + 40) & (img[..., 2] > 100)
    red = (img[..., 0] > img[..., 2] + 40) & (img[..., 0] > 100)
    assert blue.sum() > 100 and red.sum() > 100
    assert np.mean(np.nonzero(blue)[1]) < np.mean(np.nonzero(red)[1])


@pytest.mark.slow
def test_bench_pipeline_conversation_reports_the_scene_against_its_bare_step(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``bench pipeline --conversation STEREO --json`` runs the two-person scene and the bare
    ``mj_step`` of the same two-body model: a real-time factor for each and their ratio."""
    from scipy.io import wavfile

    from gesture_sim import cli
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.contracts import SAMPLE_RATE

    speech, _ = load_audio(Path(__file__).resolve().parents[1] / "data" / "audio"
                           / "arctic_a0007.wav")
    half = len(speech) // 2
    stereo = np.zeros((2 * half, 2), dtype=np.float32)
    stereo[:half, 0] = speech[:half]                 # A speaks, then B answers
    stereo[half:, 1] = speech[half: 2 * half]
    path = tmp_path / "two.wav"
    wavfile.write(path, SAMPLE_RATE, stereo)
    capsys.readouterr()
    assert cli.main(["bench", "pipeline", "--conversation", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    bare, two = doc["bare_step"], doc["two_people"]
    assert bare["steps"] == 2000 and bare["realtime_factor"] > 0
    assert doc["pipeline_to_bare_step"] == pytest.approx(
        two["realtime_factor"] / bare["realtime_factor"])
    assert 0 < doc["pipeline_to_bare_step"] < 1.5
    assert doc["turns"] >= 1
