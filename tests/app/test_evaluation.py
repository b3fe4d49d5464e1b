"""Tests of ``gesture_sim.app.evaluation`` and ``gesture-sim eval motion``.

The end-to-end fixture is the first 6 s of the BEAT2 take ``2_scott_0_1_1`` (audio and its
SMPL-X motion, cut from ``tests/data/eval`` and ``tests/data/motion``), one seed.
"""

from __future__ import annotations

import json
import wave
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gesture_sim.app import evaluation as ev
from gesture_sim.errors import GestureSimError
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics import points as pts
from gesture_sim.metrics import reference as ref

DATA = Path(__file__).resolve().parents[1] / "data"
WAV = DATA / "eval" / "2_scott_0_1_1_first10s.wav"
NPZ = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
SECONDS = 6.0


@pytest.fixture(scope="module")
def take(tmp_path_factory) -> tuple[Path, Path]:
    """The first 6 s of the fixture take: (wav, npz) with the same stem."""
    folder = tmp_path_factory.mktemp("take")
    wav = folder / "scott_take.wav"
    with wave.open(str(WAV)) as src, wave.open(str(wav), "wb") as dst:
        dst.setparams(src.getparams())
        dst.writeframes(src.readframes(int(SECONDS * src.getframerate())))
    n = int(SECONDS * 30)
    with np.load(NPZ) as d:
        arrays = {k: d[k] for k in d.files}
    arrays["poses"], arrays["trans"] = arrays["poses"][:n], arrays["trans"][:n]
    arrays["expressions"] = arrays["expressions"][:n]
    npz = folder / "scott_take.npz"
    np.savez(npz, **arrays)
    return wav, npz


@pytest.fixture(scope="module")
def evaluator() -> ev.Evaluator:
    return ev.Evaluator()


@pytest.fixture(scope="module")
def result(take, evaluator) -> ev.EvalResult:
    wav, npz = take
    return ev.evaluate([wav], [npz], seeds=1, evaluator=evaluator)


# ------------------------------------------------------------------------------ end to end


def test_every_method_is_run_and_scored(result):
    assert result.methods == list(ev.DEFAULT_METHODS)
    summary = result.summary()
    for method in ev.DEFAULT_METHODS:
        for key in ("bc", "bc_chance", "r_intensity_best", "fgd", "mean_jerk",
                    "hellinger_speed", "hand_error_rms_mm"):
            assert np.isfinite(summary[method][key]["mean"]), (method, key)
    # the body stands: none of the methods makes it fall
    assert all(r["metrics"]["fell"] == 0.0 for r in result.rows)


def test_real_motion_is_closer_to_real_motion_than_scrambled_motion(result, evaluator, take):
    """The speed histogram tells real motion from the same frames in random order (FGD's
    covariance needs more than the few windows of 5 s to be reliable: checked elsewhere)."""
    run = result.runs[(result.inputs[0]["name"], "real")]
    order = np.random.default_rng(0).permutation(len(run.positions))
    scrambled = ev.MotionRun("scrambled", run.audio, 0, run.positions[order], None,
                             run.physics)
    inp = ev.load_input(take[0])
    real, bad = evaluator.score(run, inp), evaluator.score(scrambled, inp)
    assert real["hellinger_speed"] < bad["hellinger_speed"]


def test_mismatched_control_scores_the_same_motion_against_other_audio(result):
    rows = {r["method"]: r for r in result.rows}
    ctrl, mis = rows["controller"]["metrics"], rows["mismatched"]["metrics"]
    assert rows["mismatched"]["scored_against"].endswith("_rotated")
    # motion-only figures are those of the controller's motion ...
    assert mis["mean_jerk"] == pytest.approx(ctrl["mean_jerk"])
    assert mis["fgd"] == pytest.approx(ctrl["fgd"])
    # ... the audio ones are not, and BC against unrelated audio sits at its chance level
    assert mis["n_audio_beats"] != ctrl["n_audio_beats"] or mis["bc"] != ctrl["bc"]
    assert abs(mis["bc"] - mis["bc_chance"]) < 0.1


def test_report_folder_has_table_plots_and_timelines(result, tmp_path):
    from gesture_sim.app.report import write_report

    written = write_report(result, tmp_path / "rep", command="gesture-sim eval x.wav")
    rep = tmp_path / "rep"
    for name in ("report.json", "table.md", "bars.png", "velocity_hist.png"):
        assert (rep / name).is_file() and (rep / name).stat().st_size > 0, name
        assert rep / name in written
    stem = result.inputs[0]["name"]
    for method in (m for m in ev.PIPELINE_METHODS if m in result.methods):
        assert (rep / "timelines" / f"{stem}_{method}.png").is_file()
    assert (rep / "timelines" / f"{stem}_compare.png").is_file()
    data = json.loads((rep / "report.json").read_text())
    assert set(data["summary"]) == set(ev.DEFAULT_METHODS)
    assert data["command"] == "gesture-sim eval x.wav"
    table = (rep / "table.md").read_text()
    header = next(line for line in table.splitlines() if line.startswith("| metric"))
    for method in ev.DEFAULT_METHODS:
        assert method in header
    assert (rep / "bars.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_seed_gives_the_same_motion_and_scores(take, evaluator):
    wav, _ = take
    inp = ev.load_input(wav)
    a = evaluator.run_pipeline("random", inp, seed=3)
    b = evaluator.run_pipeline("random", inp, seed=3)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert evaluator.score(a, inp) == evaluator.score(b, inp)
    c = evaluator.run_pipeline("random", inp, seed=4)
    assert not np.array_equal(a.positions, c.positions)


# ------------------------------------------------------------------------------ pieces


def test_standing_pose_points_are_where_a_body_has_them():
    from gesture_sim.sim.humanoid import ACTUATED_JOINTS

    fk = pts.PointFK()
    p = fk.standing(np.zeros((1, len(ACTUATED_JOINTS))))[0]
    idx = {n: i for i, n in enumerate(pts.POINT_NAMES)}
    assert p[idx["pelvis"]] == pytest.approx([0.0, 0.0, 0.98], abs=1e-6)
    assert 1.4 < p[idx["head"], 2] < 1.9
    assert p[idx["head"], 2] > p[idx["neck"], 2] > p[idx["chest"], 2] > p[idx["pelvis"], 2]
    for side, sign in (("left", 1), ("right", -1)):
        assert sign * p[idx[f"{side}_hand"], 1] > 0.1          # left is +y
        assert p[idx[f"{side}_hand"], 2] < p[idx[f"{side}_elbow"], 2] < \
            p[idx[f"{side}_shoulder"], 2]                      # arms hang down


def test_heading_frame_removes_the_root_position_and_yaw():
    from scipy.spatial.transform import Rotation

    from gesture_sim.sim import humanoid as hm

    fk = pts.PointFK()
    base = np.zeros(fk.model.nq)
    base[:7] = hm.root_qpos()
    moved = base.copy()
    moved[:2] = (1.5, -0.7)
    q = Rotation.from_euler("z", 70, degrees=True).as_quat()          # (x, y, z, w)
    moved[3:7] = (q[3], q[0], q[1], q[2])
    a, b = fk.heading(np.stack([base, moved]))
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_resample_positions_interpolates_onto_the_30fps_grid():
    t = np.array([0.0, 0.1, 0.2])
    p = np.zeros((3, 1, 3))
    p[:, 0, 0] = [0.0, 1.0, 4.0]
    out = pts.resample_positions(t, p, fps=30.0)
    assert out.shape == (7, 1, 3)
    assert out[3, 0, 0] == pytest.approx(1.0)               # t = 0.1
    assert out[4, 0, 0] == pytest.approx(1.0 + 3.0 / 3.0)   # t = 0.1333: a third to 4.0


def test_target_switches_only_where_the_played_frame_jumps():
    library = SimpleNamespace(segments=[SimpleNamespace(clip=0, start=0),
                                        SimpleNamespace(clip=0, start=5),
                                        SimpleNamespace(clip=1, start=0)])
    # segment 0 frames 0..4, then its successor 1 (clip frames 5, 6: continuous), then a jump
    # to segment 2 at step 7, then a restart of segment 2 at step 9
    log = SimpleNamespace(segments=[0, 0, 0, 0, 0, 1, 1, 2, 2, 2, 2],
                          frames=[0, 1, 2, 3, 4, 0, 1, 0, 1, 0, 1],
                          step_times=[k / 30.0 for k in range(11)])
    assert ev.target_switches(library, log).tolist() == [7, 9]


def test_bc_chance_is_below_bc_for_motion_that_stops_on_the_beats():
    fps, dur = pts.EVAL_FPS, 20.0
    t = np.arange(int(dur * fps)) / fps
    onsets = np.arange(1.0, 19.0, 0.9)
    # speed dips to near zero at every onset, high in between: motion beats on the audio beats
    # (speed sampled between frames, so that central differences put each minimum on a frame)
    mid = t + 0.5 / fps
    dist = np.min(np.abs(mid[:, None] - onsets[None, :]), axis=1)
    speed = 0.1 + np.minimum(dist, 0.3)
    x = np.concatenate([[0.0], np.cumsum(speed)[:-1]]) / fps
    pos = np.zeros((len(t), 1, 3))
    pos[:, 0, 0] = x
    bc = mm.beat_consistency(onsets, fps, positions=pos).bc
    chance = ev.bc_chance(onsets, pos, [0], dur)
    assert bc > 0.95
    assert chance < bc - 0.2


def test_references_pair_by_name(tmp_path):
    a, b = tmp_path / "take_a.npz", tmp_path / "other.npz"
    a.write_bytes(b"x")
    b.write_bytes(b"x")
    assert ev.match_references(["x/take_a.wav", "y/take_b.wav"], [a]) == {0: a}
    assert ev.match_references(["only.wav"], [b]) == {0: b}       # one and one: paired
    with pytest.raises(GestureSimError, match="matches no audio"):
        ev.match_references(["x/take_a.wav", "y/take_b.wav"], [b])
    with pytest.raises(GestureSimError, match="no such motion"):
        ev.match_references(["x/take_a.wav"], [tmp_path / "missing.npz"])


def test_stored_extractor_is_the_fit_of_the_shipped_library(evaluator):
    assert evaluator.extractor_origin == "stored"
    fresh = ref.fit_extractor(evaluator.library, evaluator.fk)
    np.testing.assert_allclose(np.abs(fresh.components[:8]),
                               np.abs(evaluator.extractor.components[:8]), atol=1e-6)


# ------------------------------------------------------------------------------ command line


def test_bare_eval_with_a_file_means_eval_motion(take):
    from gesture_sim.cli import build_parser
    from gesture_sim.commands.eval import run_motion

    wav, npz = take
    args = build_parser().parse_args(["eval", str(wav), "--reference", str(npz), "--json"])
    assert args.func is run_motion
    assert args.audio == [wav] and args.reference == [npz] and args.json
    args = build_parser().parse_args(["eval", "motion", str(wav), "--seeds", "2"])
    assert args.func is run_motion and args.seeds == 2
    args = build_parser().parse_args(["eval", "inference", "--pair", "m.bvh", "a.wav"])
    assert args.func is not run_motion and args.eval_mode == "inference"


def test_unknown_method_is_a_one_line_error(take, capsys):
    from gesture_sim.cli import main

    wav, _ = take
    assert main(["eval", str(wav), "--methods", "nonsense"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gesture-sim: error:") and "nonsense" in err and "\n" not in err


def test_a_textgrids_words_reach_a_method_that_reads_words(evaluator, monkeypatch):
    """``eval --textgrid``: the grid's word tier is the input's timed words, and every pipeline
    run gets them (``chiu14`` reads them; the other methods' filters ignore them)."""
    import gesture_sim.feed as feed_mod
    from gesture_sim.audio.keywords import read_word_list

    wav = DATA / "pipeline" / "beat2_scott_0_2_2.wav"
    grid = DATA / "textgrids" / "2_scott_0_2_2.TextGrid"
    inp = ev.load_input(wav, textgrid=grid)
    assert inp.words == read_word_list(grid) and len(inp.words) > 50
    assert ev.load_input(wav).words is None
    seen = {}

    def run_file(pipe, **kw):
        seen.update(kw, method=pipe.method)
        raise RuntimeError("stopped by the test")

    monkeypatch.setattr(feed_mod, "run_file", run_file)
    with pytest.raises(RuntimeError, match="stopped"):
        evaluator.run_pipeline("chiu14", inp, seed=0)
    assert seen["method"] == "chiu14" and seen["words"] == inp.words
