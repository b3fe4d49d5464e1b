"""A library swap that keeps the inference model (issue 18 item 5; Gesture Controllers'
modularity): a library built from a subset of the default library's clips with the shipped
model's normalisation drives real speech with the shipped model; only its control layer (the
policy) is trained, beside the library, and the model folder is never written."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gesture_sim import DEFAULT_LIBRARY_DIR
from gesture_sim.cli import main
from gesture_sim.errors import GestureSimError
from gesture_sim.loading import (
    POLICY_DIR,
    POLICY_FILE,
    is_own_library,
    load_stack,
    normalisation_from,
    policy_path,
    same_normalisation,
)
from gesture_sim.motion.build import check_normalisation
from gesture_sim.motion.library import MotionLibrary

DATA = Path(__file__).resolve().parents[1] / "data"
MOTION = DATA / "motion"
JFK = DATA / "audio" / "jfk.wav"
SHIPPED_MODEL = DEFAULT_LIBRARY_DIR / "model"
#: Clips of the default library that are in tests/data/motion whole (the Bandai emblems), and
#: the first 10 s of its co-speech take.
EMBLEMS = ("dataset-1_bow_active_001", "dataset-1_bye_sad_001",
           "dataset-2_wave-right-hand_normal_001")
COSPEECH = "2_scott_0_1_1_first10s"


def _folder_digest(folder: Path) -> dict[str, tuple[str, int]]:
    """{file name: (sha256, mtime ns)} of every file in a folder."""
    return {p.name: (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def model_before() -> dict[str, tuple[str, int]]:
    """The shipped model folder before anything in this module ran."""
    return _folder_digest(SHIPPED_MODEL)


@pytest.fixture(scope="module")
def swap_dir(tmp_path_factory, model_before) -> Path:
    """`library build` of the co-speech excerpt and three emblem clips with the shipped model's
    normalisation (the command line, as a user would run it)."""
    out = tmp_path_factory.mktemp("swap") / "lib"
    files = [MOTION / f"{COSPEECH}.npz", *(MOTION / f"{name}.bvh" for name in EMBLEMS)]
    rc = main(["library", "build", *map(str, files), "-o", str(out),
               "--normalisation-from", str(SHIPPED_MODEL), "--json"])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def default_library() -> MotionLibrary:
    return MotionLibrary.load(DEFAULT_LIBRARY_DIR)


def test_the_build_keeps_the_models_normalisation(swap_dir: Path,
                                                  default_library: MotionLibrary) -> None:
    """Built with the shipped model's B_X / W_X, the emblem clips get exactly the default
    library's segments and parameters (the default library was built from the same files)."""
    lib = MotionLibrary.load(swap_dir)
    shipped = json.loads((SHIPPED_MODEL / "model.json").read_text())["param_normalisation"]
    assert same_normalisation(lib.param_normalisation, shipped)
    assert lib.info["normalisation"] == "given"
    assert [c.name for c in lib.clips] == [COSPEECH, *EMBLEMS]
    by_name = {c.name: k for k, c in enumerate(default_library.clips)}
    for ci, name in enumerate(EMBLEMS, start=1):
        ours = [s for s in lib.segments if s.clip == ci]
        theirs = [s for s in default_library.segments if s.clip == by_name[name]]
        assert [(s.start, s.end, s.tags) for s in ours] == [(s.start, s.end, s.tags)
                                                            for s in theirs]
        np.testing.assert_allclose(np.stack([s.params for s in ours]),
                                   np.stack([s.params for s in theirs]), atol=1e-4)
    assert not same_normalisation(lib.param_normalisation, _fitted(lib))


def _fitted(lib: MotionLibrary) -> dict:
    """The normalisation `library build` would fit to these segments without the option."""
    from gesture_sim.motion.kinematics import fit_normalisation

    b = np.asarray(lib.param_normalisation["B"])
    w = np.asarray(lib.param_normalisation["W"])
    raw = np.exp(lib.params / w) / b              # invert W * log(B * x)
    return fit_normalisation(raw)


def test_a_different_normalisation_is_one_line_naming_both_fixes(tmp_path: Path,
                                                                 swap_dir: Path) -> None:
    lib = MotionLibrary.load(swap_dir)
    lib.param_normalisation = dict(lib.param_normalisation,
                                   W=[2.0 * w for w in lib.param_normalisation["W"]])
    lib._fingerprint = None
    lib.save(tmp_path / "other")
    with pytest.raises(GestureSimError) as err:
        load_stack(tmp_path / "other", SHIPPED_MODEL, policy=False)
    msg = str(err.value)
    assert "\n" not in msg
    assert "does not fit library" in msg
    assert f"--normalisation-from {SHIPPED_MODEL}" in msg
    assert f"gesture-sim train --library {tmp_path / 'other'}" in msg


def test_normalisation_is_read_from_a_model_or_a_library_and_checked(tmp_path: Path) -> None:
    a = normalisation_from(SHIPPED_MODEL)
    b = normalisation_from(DEFAULT_LIBRARY_DIR)
    assert same_normalisation(a, b)          # the shipped model fits the shipped library
    with pytest.raises(GestureSimError, match="neither an inference model"):
        normalisation_from(tmp_path)
    with pytest.raises(GestureSimError, match="positive finite"):
        check_normalisation(dict(a, W=[1.0, 1.0, 0.0, 1.0, 1.0, 1.0]))
    with pytest.raises(GestureSimError, match="not T D V A C H"):
        check_normalisation(dict(a, names=["T", "D", "V", "A", "C", "X"]))
    with pytest.raises(GestureSimError, match="needs names, B and W"):
        check_normalisation({"names": list("TDVACH")})


def test_a_subset_of_the_default_library_keeps_its_parameters(
        default_library: MotionLibrary) -> None:
    sub = default_library.subset(["2_scott_0_1_1", "*_bow_normal_*", "*_byebye_normal_*"])
    names = [c.name for c in sub.clips]
    assert names == ["2_scott_0_1_1", "dataset-1_bow_normal_001", "dataset-1_byebye_normal_001"]
    src = {c.name: k for k, c in enumerate(default_library.clips)}
    expected = [s for s in default_library.segments
                if default_library.clips[s.clip].name in names]
    assert len(sub.segments) == len(expected)
    np.testing.assert_array_equal(sub.params, np.stack([s.params for s in expected]))
    assert [s.tags for s in sub.segments] == [s.tags for s in expected]
    for s in sub.segments:                   # links renumbered within each clip
        assert s.index == sub.segments.index(s)
        if s.successor >= 0:
            assert sub.segments[s.successor].predecessor == s.index
            assert sub.segments[s.successor].start == s.end
        assert sub.clips[s.clip].name in src
    assert sub.segments[0].predecessor == -1
    assert sum(c.n_frames for c in sub.clips) == sum(
        default_library.clips[src[n]].n_frames for n in names)
    assert same_normalisation(sub.param_normalisation, default_library.param_normalisation)
    with pytest.raises(GestureSimError, match="no clip of the library matches nothing_*"):
        default_library.subset(["2_scott_0_1_1", "nothing_*"])


def test_library_policy_trains_only_the_control_layer(tmp_path: Path, swap_dir: Path,
                                                      capsys, model_before) -> None:
    lib_dir = tmp_path / "lib"
    shutil.copytree(swap_dir, lib_dir, ignore=shutil.ignore_patterns(POLICY_DIR))
    capsys.readouterr()
    assert main(["library", "policy", str(lib_dir), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["trained"] is True
    assert first["model"] == str(SHIPPED_MODEL)      # no LIBRARY/model: the shipped one
    assert Path(first["policy"]).parent == lib_dir / POLICY_DIR
    assert first["library_fingerprint"] == MotionLibrary.load(lib_dir).fingerprint
    assert first["labels"] == ["bow", "bye", "wave"]
    assert first["train_s"] < 30.0
    assert main(["library", "policy", str(lib_dir), "--model", str(SHIPPED_MODEL),
                 "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["trained"] is False and again["policy"] == first["policy"]
    assert _folder_digest(SHIPPED_MODEL) == model_before


def test_the_swapped_library_drives_real_speech_with_the_shipped_model(
        swap_dir: Path, model_before, monkeypatch) -> None:
    from gesture_sim import loading
    from gesture_sim.control.policy import Policy
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    shipped_fp = json.loads((SHIPPED_MODEL / "model.json").read_text())["fingerprint"]
    pipe = GesturePipeline.create(swap_dir, physics=False)    # --model defaults to the shipped
    lib = pipe.library
    assert pipe.model.fingerprint == shipped_fp
    policy = pipe.controller.policy
    assert policy.library_fingerprint == lib.fingerprint != MotionLibrary.load(
        DEFAULT_LIBRARY_DIR).fingerprint
    assert policy.n_segments == len(lib.segments) == 35
    cached = swap_dir / POLICY_DIR / f"{policy.model_fingerprint}.npz"
    Policy.load(cached, lib.fingerprint, policy.model_fingerprint)   # stored beside the library
    run_file(pipe, JFK, labels=[(2.0, "wave")])
    played = [s for s in pipe.log.segments if s >= 0]
    decisions = pipe.log.decisions
    assert len(decisions) >= 6
    assert all(0 <= d.segment_id < len(lib.segments) for d in decisions)
    assert {pipe.segment_name(s) for s in played} <= {COSPEECH, *EMBLEMS}
    assert len(set(played)) >= 4
    # without a label only the co-speech take plays; the wave asked at 2 s is the library's
    unlabelled = [d for d in decisions if d.kind != "label"]
    assert all(lib.clips[lib.segments[d.segment_id].clip].name == COSPEECH for d in unlabelled)
    served = [d for d in decisions if d.kind == "label"]
    assert served and 2.0 <= served[0].t <= 3.0
    assert "wave" in lib.segments[served[0].segment_id].tags
    # the next run loads the cached policy: no training
    monkeypatch.setattr(loading, "train_library_policy",
                        lambda *a, **k: pytest.fail("the cached policy was not used"))
    again = GesturePipeline.create(swap_dir, SHIPPED_MODEL, physics=False)
    assert again.controller.policy.library_fingerprint == lib.fingerprint
    assert _folder_digest(SHIPPED_MODEL) == model_before     # the model folder never written
    assert not (SHIPPED_MODEL / POLICY_DIR).exists()


def test_the_swapped_library_with_physics_does_not_fall(swap_dir: Path, model_before) -> None:
    from gesture_sim.feed import run_file
    from gesture_sim.metrics.physics import physics_metrics
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(swap_dir, SHIPPED_MODEL, seed=0)
    run = run_file(pipe, JFK)
    m = physics_metrics(pipe.trace())
    assert m.duration_s == pytest.approx(run.duration, abs=0.1)
    assert not m.fell
    assert m.assist_impulse_per_s == 0.0
    assert m.foot_skate_mm_s < 2.0
    assert _folder_digest(SHIPPED_MODEL) == model_before


def test_the_default_pair_keeps_its_policy_in_the_model_folder(
        default_library: MotionLibrary) -> None:
    from gesture_sim.control.inputs import StateModel
    from gesture_sim.inference.model import GestureModel

    gm = GestureModel.load(SHIPPED_MODEL)
    assert is_own_library(gm, default_library)
    sm = StateModel.from_inference(gm)
    assert policy_path(SHIPPED_MODEL, sm, library_dir=DEFAULT_LIBRARY_DIR,
                       own_library=True) == SHIPPED_MODEL / POLICY_FILE
    other = policy_path(SHIPPED_MODEL, sm, library_dir=Path("elsewhere"), own_library=False)
    assert other == Path("elsewhere") / POLICY_DIR / f"{sm.fingerprint}.npz"
