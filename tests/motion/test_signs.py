"""Chiu (2014) gestural signs on the motion library (issue 33): the form labeller on synthetic
hand paths with known answers, the prototype pass and the agreement, the annotation importer,
the signs saved with a library, and `library info` / `library build --signs`."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.motion import signs as sg
from gesture_sim.motion.library import MotionLibrary

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_LIBRARY_DIR = ROOT / "motion_library" / "default"
MOTION = ROOT / "tests" / "data" / "motion"

# the body frame of SegmentForm (m, relative to the pelvis): shoulders, chest point, hands down
SHOULDER = np.array([[0.0, 0.2, 0.47], [0.0, -0.2, 0.47]])
CHEST = np.array([0.12, 0.0, 0.35])
HANGING = np.array([[0.05, 0.25, -0.13], [0.05, -0.25, -0.13]])
MEDIAL = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])      # palms facing the thighs


def _form(hand: np.ndarray, palm: np.ndarray | None = None, pitch: np.ndarray | None = None,
          fps: float = 30.0) -> sg.SegmentForm:
    t = len(hand)
    palm = np.broadcast_to(MEDIAL if palm is None else palm, (t, 2, 3)).astype(float)
    palm = palm / np.linalg.norm(palm, axis=2, keepdims=True)
    return sg.SegmentForm(fps=fps, hand=np.asarray(hand, float),
                          shoulder=np.broadcast_to(SHOULDER, (t, 2, 3)).copy(),
                          chest=np.broadcast_to(CHEST, (t, 3)).copy(), palm=palm,
                          head_pitch=np.zeros(t) if pitch is None else pitch)


def _line(a, b, t: int = 30) -> np.ndarray:
    u = np.linspace(0.0, 1.0, t)[:, None]
    return np.asarray(a, float) + u * (np.asarray(b, float) - np.asarray(a, float))


def _sweep(arc: float = 0.0, t: int = 30) -> np.ndarray:
    """Both hands from together in front of the belly straight apart (arc: a bump in z)."""
    bump = arc * np.sin(np.linspace(0, math.pi, t))
    left = _line([0.35, 0.04, 0.15], [0.35, 0.45, 0.15], t)
    right = _line([0.35, -0.04, 0.15], [0.35, -0.45, 0.15], t)
    left[:, 2] += bump
    right[:, 2] += bump
    return np.stack([left, right], axis=1)


def test_signs_are_the_thesis_list() -> None:
    from gesture_sim.signals.sign_lexicon import SIGNS as LEXICON_SIGNS

    assert len(sg.SIGNS) == 14 and sg.SIGNS[0] == "Rest" and sg.SIGNS[-1] == "Beats"
    assert sg.SIGNS == LEXICON_SIGNS
    assert sg.canonical_sign("everything") == "Whole"
    assert sg.canonical_sign(" palm face up ") == "Palm-face-up"
    assert sg.canonical_sign("deictic_self") == "Deictic.Self"
    with pytest.raises(GestureSimError, match="not a gestural sign"):
        sg.canonical_sign("wave")


def test_a_lateral_sweep_is_wipe_or_whole() -> None:
    down = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    assert sg.label_form(_form(_sweep(), down))[0] == "Wipe"
    assert sg.label_form(_form(_sweep(arc=0.12), down))[0] == "Whole"


def test_still_hands_are_rest_and_a_nodding_head_is_head_nod() -> None:
    t = 30
    rng = np.random.default_rng(0)
    still = np.broadcast_to(HANGING, (t, 2, 3)) + rng.normal(0, 0.001, (t, 2, 3))
    assert sg.label_form(_form(still))[0] == "Rest"
    pitch = 0.12 * np.sin(np.linspace(0, 2 * math.pi, t))
    assert sg.label_form(_form(still, pitch=pitch))[0] == "Head-nod"


def test_a_pointing_arm_is_deictic_other() -> None:
    right = _line(HANGING[1], [0.55, -0.32, 0.45])
    left = np.broadcast_to(HANGING[0], (30, 3))
    assert sg.label_form(_form(np.stack([left, right], axis=1)))[0] == "Deictic.Other"


def test_circles_are_process_and_a_hand_at_the_chest_is_deictic_self() -> None:
    a = np.linspace(0, 2 * math.pi, 40)
    right = np.stack([0.35 + 0 * a, -0.2 + 0.08 * np.cos(a), 0.15 + 0.08 * np.sin(a)], axis=1)
    left = np.broadcast_to(HANGING[0], (40, 3))
    assert sg.label_form(_form(np.stack([left, right], axis=1)))[0] == "Process"
    right = _line([0.35, -0.25, 0.05], CHEST + [0.06, 0.0, 0.0])
    palm = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])          # right palm to the body
    hand = np.stack([np.broadcast_to(HANGING[0], (30, 3)), right], axis=1)
    assert sg.label_form(_form(hand, palm))[0] == "Deictic.Self"


def test_prototypes_and_kappa() -> None:
    assert set(sg.PROTOTYPES) == set(sg.SIGNS)
    assert all(len(v) == len(sg.FEATURES) for v in sg.PROTOTYPES.values())
    assert len(sg.FEATURE_SCALES) == len(sg.FEATURES)
    assert sg.cohen_kappa(["a", "b", "a"], ["a", "b", "a"])["kappa"] == 1.0
    k = sg.cohen_kappa(["a", "a", "b", "b"], ["a", "b", "a", "b"])
    assert k["agreement"] == 0.5 and k["kappa"] == 0.0
    with pytest.raises(GestureSimError):
        sg.cohen_kappa(["a"], [])


@pytest.fixture(scope="module")
def cospeech() -> MotionLibrary:
    """The shipped library's co-speech clip (67 segments), as a library of its own."""
    return MotionLibrary.load(DEFAULT_LIBRARY_DIR).subset(["2_scott_0_1_1"])


def test_the_library_is_labelled_deterministically(cospeech: MotionLibrary) -> None:
    stored = cospeech.form_signs
    cospeech.form_signs = None          # label from the forms, not from the manifest
    try:
        a = sg.label_library(cospeech)
        sg._LABELS.clear()
        b = sg.label_library(cospeech)
    finally:
        cospeech.form_signs = stored
    assert stored is not None and list(stored[1]) == a    # the shipped labels are current
    assert a == b and len(a) == len(cospeech.segments) == 67
    assert set(a) <= set(sg.SIGNS) and len(set(a)) >= 4     # more than Beats and Rest
    p2 = sg.prototype_library(cospeech)
    assert p2 == sg.prototype_library(cospeech) and set(p2) <= set(sg.SIGNS)
    k = sg.cohen_kappa(a, p2)
    assert k["n"] == 67 and -1.0 <= k["kappa"] <= 1.0
    labels, source = sg.library_signs(cospeech)
    assert source == "form labeller" and labels == a


def test_csv_and_elan_annotations_label_segments_and_are_saved(cospeech: MotionLibrary,
                                                               tmp_path: Path) -> None:
    lib = MotionLibrary.load(DEFAULT_LIBRARY_DIR).subset(["2_scott_0_1_1"])
    s0, s1 = lib.segments[0], lib.segments[1]
    csv_file = tmp_path / "signs.csv"
    csv_file.write_text("clip,start_s,end_s,sign,note\n"
                        f"2_scott_0_1_1,{s0.start / 30:.3f},{s0.end / 30:.3f},everything,x\n",
                        encoding="utf-8")
    elan = tmp_path / "2_scott_0_1_1.txt"    # the file named as the clip; tier "signs"
    a, b = s1.start / 30, s1.end / 30
    elan.write_text(f"signs\t\t00:00:{a:06.3f}\t00:00:{b:06.3f}\t0.5\tDeictic.Self\n",
                    encoding="utf-8")
    notes = [*sg.read_sign_annotations(csv_file), *sg.read_sign_annotations(elan)]
    assert [(n.sign, n.clip, n.tier) for n in notes] == [
        ("Whole", "2_scott_0_1_1", ""), ("Deictic.Self", None, "signs")]
    got = sg.apply_sign_annotations(lib, notes)
    assert got["labelled"] == 2 and got["unlabelled"] == 65
    assert lib.segments[0].sign == "Whole" and lib.segments[1].sign == "Deictic.Self"
    assert lib.segments[2].sign is None
    labels, source = sg.library_signs(lib)
    assert source == "annotations + form labeller" and labels[:2] == ["Whole", "Deictic.Self"]
    lib.save(tmp_path / "lib")
    back = MotionLibrary.load(tmp_path / "lib")
    assert [s.sign for s in back.segments] == [s.sign for s in lib.segments]
    assert back.fingerprint == cospeech.fingerprint       # annotations are no content
    # a library saved before signs existed loads with none
    assert all(s.sign is None for s in cospeech.segments)
    # errors name the file and line
    bad = tmp_path / "bad.csv"
    bad.write_text("clip,start_s,end_s,sign\n2_scott_0_1_1,1.0,2.0,wave\n", encoding="utf-8")
    with pytest.raises(GestureSimError, match=r"bad.csv:2: .*not a gestural sign"):
        sg.read_sign_annotations(bad)
    other = tmp_path / "other.csv"
    other.write_text("clip,start_s,end_s,sign\nnope,1.0,2.0,Rest\n", encoding="utf-8")
    with pytest.raises(GestureSimError, match="no clip 'nope'"):
        sg.apply_sign_annotations(lib, sg.read_sign_annotations(other))


def test_library_info_lists_the_signs(capsys) -> None:
    from gesture_sim.cli import main

    assert main(["library", "info", str(DEFAULT_LIBRARY_DIR), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)["signs"]
    assert info["source"] == "form labeller"
    assert list(info["counts"]) == list(sg.SIGNS)
    assert sum(info["cospeech"].values()) == 67
    assert set(info["realisable_cospeech"]) <= set(info["realisable"]) <= set(sg.SIGNS)
    assert main(["library", "info", str(DEFAULT_LIBRARY_DIR)]) == 0
    out = capsys.readouterr().out
    assert "gestural signs (Chiu 2014" in out and "signs the library can realise" in out


def test_library_build_takes_sign_annotations(tmp_path: Path, capsys) -> None:
    from gesture_sim.cli import main

    clip = MOTION / "dataset-1_bow_active_001.bvh"
    notes = tmp_path / "signs.csv"
    # the whole 4.27 s clip (a span may run past its end by 0.5 s: validation.side_file_times)
    notes.write_text("clip,start_s,end_s,sign\ndataset-1_bow_active_001,0,4.5,Head-nod\n",
                     encoding="utf-8")
    out = tmp_path / "lib"
    assert main(["library", "build", str(clip), "-o", str(out), "--signs", str(notes),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    lib = MotionLibrary.load(out)
    assert summary["signs"]["labelled"] == len(lib.segments) > 0
    assert {s.sign for s in lib.segments} == {"Head-nod"}
    assert lib.info["signs"]["files"] == [str(notes)]
    assert main(["library", "info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["signs"]["source"] == "annotations"


def test_a_bad_signs_file_fails_cleanly_under_its_name(tmp_path: Path, capsys) -> None:
    from gesture_sim.cli import main

    bad = tmp_path / "signs.csv"
    bad.write_text("clip,start_s,end_s,sign\nx,0,1,wave\n", encoding="utf-8")
    status = main(["library", "build", str(MOTION / "dataset-1_bow_active_001.bvh"), "-o",
                   str(tmp_path / "lib"), "--signs", str(bad)])
    err = capsys.readouterr().err
    assert status == 2 and f"{bad}:2" in err and "Traceback" not in err
    assert not (tmp_path / "lib").exists()


def test_form_labels_are_stored_with_the_library_and_reused(cospeech: MotionLibrary,
                                                            tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """The form labeller runs once, when a library is saved; loading, subsetting and labelling
    afterwards read the stored labels, and labels of another labeller key are recomputed."""
    lib = MotionLibrary.load(DEFAULT_LIBRARY_DIR).subset(["2_scott_0_1_1"])
    lib.form_signs = None
    expected = sg.label_library(lib)
    lib.save(tmp_path / "lib")
    manifest = json.loads((tmp_path / "lib" / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["form_signs"] == {"labeller": sg.labeller_key(), "signs": expected}
    sg._LABELS.clear()

    def no_posing(*_a, **_k):
        raise AssertionError("the stored labels should have been used")

    monkeypatch.setattr(sg, "label_segment", no_posing)
    back = MotionLibrary.load(tmp_path / "lib")
    assert sg.label_library(back) == expected
    assert sg.library_signs(back) == (expected, "form labeller")
    part = back.subset(["2_scott_0_1_1"])
    assert sg.label_library(part) == expected
    # another labeller's labels (a stale key, other settings) are not reused
    back.form_signs = ("form-v0-stale", tuple(expected))
    with pytest.raises(AssertionError, match="stored labels"):
        sg.label_library(back)
    with pytest.raises(AssertionError, match="stored labels"):
        sg.label_library(part, sg.SignSettings(active_path_m=0.2))
