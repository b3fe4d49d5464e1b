"""The realism discriminator and BEAT2's beat consistency on inputs whose answers are known.

Real motion: the shipped library's co-speech clip (the BEAT2 take ``2_scott_0_1_1``, 63.5 s,
posed on the standing body as ``eval motion`` poses it), the same real motion FGD uses.
"""

from __future__ import annotations

import math
import wave
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics import realism as rl

FPS = 30.0
DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def real() -> np.ndarray:
    """The library's real co-speech motion, ``(T, 12, 3)`` at 30 fps."""
    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.metrics.points import PointFK
    from gesture_sim.metrics.reference import clip_positions, cospeech_clips
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(DEFAULT_LIBRARY_DIR)
    clips = clip_positions(lib, PointFK(), cospeech_clips(lib))
    assert float(lib.fps) == FPS
    return max(clips, key=len)


@pytest.fixture(scope="module")
def layout() -> dict[str, list[int]]:
    from gesture_sim.app.evaluation import disc_layout

    return disc_layout()


def _blocks(x: np.ndarray, seconds: float = 6.0) -> list[np.ndarray]:
    n = int(seconds * FPS)
    return [x[i : i + n] for i in range(0, len(x) - n + 1, n)]


# ------------------------------------------------------------------------- discriminator


def test_real_against_other_slices_of_the_same_real_motion_is_near_chance(real, layout):
    blocks = _blocks(real)
    res = rl.discriminator_accuracy(blocks[0::2], blocks[1::2], FPS, seed=0, **layout)
    assert res.n_real >= 14 and res.n_generated >= 14 and res.n_tested >= 28
    assert abs(res.accuracy - 0.5) <= 0.12
    half = len(real) // 2
    halves = rl.discriminator_accuracy(real[:half], real[half:], FPS, seed=0, **layout)
    assert abs(halves.accuracy - 0.5) <= 0.12
    # the evaluator's floor: the same alternation of 6 s blocks (with the last, shorter block)
    assert abs(rl.real_split_accuracy([real], FPS, **layout).accuracy - 0.5) <= 0.12


def test_jittered_real_motion_is_told_from_real_motion(real, layout):
    half = len(real) // 2
    jitter = real[half:] + np.random.default_rng(0).normal(0.0, 0.005, real[half:].shape)
    res = rl.discriminator_accuracy(real[:half], jitter, FPS, seed=0, **layout)
    assert res.accuracy > 0.9


def test_real_motion_played_three_times_faster_is_told_from_real_motion(real, layout):
    half = len(real) // 2
    fast = np.concatenate([real[half:][::3], real[:half][::3]])   # every third frame: 3x
    res = rl.discriminator_accuracy(real[:half], fast, FPS, seed=0, **layout)
    assert res.accuracy > 0.9


def test_a_seed_gives_the_same_accuracy_and_the_classes_are_balanced(real, layout):
    third = len(real) // 3
    big, small = real[:2 * third], real[2 * third:] + 0.002   # 2:1 windows
    a = rl.discriminator_accuracy(big, small, FPS, seed=7, **layout)
    b = rl.discriminator_accuracy(big, small, FPS, seed=7, **layout)
    assert a == b
    assert a.n_real > 1.5 * a.n_generated
    assert a.n_tested <= 2 * a.n_generated and a.n_tested % 2 == 0   # balanced in every fold
    assert len(a.fold_accuracies) == rl.N_FOLDS
    assert 0.0 <= a.accuracy <= 1.0 and 0.0 < a.se < 0.1


def test_training_windows_never_overlap_the_held_out_ones(real, layout):
    ws = rl.window_set(real, FPS, **layout)
    folds = rl._blocks(ws, rl.N_FOLDS)
    for k in range(rl.N_FOLDS):
        test = np.flatnonzero(folds == k)
        train = rl._purged_train(ws, folds, k)
        assert len(train) > 0 and not set(train) & set(test)
        for i in train:
            assert np.all((ws.end_s[test] <= ws.start_s[i] + 1e-9)
                          | (ws.start_s[test] >= ws.end_s[i] - 1e-9))


def test_window_features_are_finite_and_scale_free_where_promised(real, layout):
    f, starts = rl.window_features(real, FPS, **layout)
    assert f.shape == (len(starts), len(rl.FEATURE_NAMES) + len(layout["joints"]))
    assert np.all(np.isfinite(f))
    assert np.array_equal(starts, np.arange(len(starts)) * int(rl.HOP_S * FPS))
    # twice the size: only the log speed and the curvature change (by log 2 each)
    g, _ = rl.window_features(2.0 * real, FPS, **layout)
    changed = [n for i, n in enumerate(rl.FEATURE_NAMES) if not np.allclose(f[:, i], g[:, i])]
    assert changed == ["log_speed", "log_curvature"]
    assert np.allclose(g[:, 0] - f[:, 0], math.log(2.0), atol=0.05)


def test_too_little_motion_gives_no_accuracy_and_bad_input_one_line_errors(real, layout):
    res = rl.discriminator_accuracy(real, real[: int(10 * FPS)], FPS, **layout)
    assert math.isnan(res.accuracy) and res.n_tested == 0 and res.n_generated < rl.MIN_WINDOWS
    with pytest.raises(GestureSimError, match="needs fps and hands"):
        rl.discriminator_accuracy(real, real)
    with pytest.raises(GestureSimError, match="two hand joints"):
        rl.window_features(real, FPS, hands=[10])
    with pytest.raises(GestureSimError, match="not one of the motion's 12 joints"):
        rl.window_features(real, FPS, hands=[10, 12])


# ------------------------------------------------------------------------- BEAT2 BC


def dips(n_frames: int, frames: list[int], depths: list[float], half: int = 7) -> np.ndarray:
    """Speed 1.0 with V-shaped dips down to ``depths`` at ``frames`` (±``half`` frames)."""
    s = np.ones(n_frames)
    for f, d in zip(frames, depths, strict=True):
        for k in range(-half, half + 1):
            if 0 <= f + k < n_frames:
                s[f + k] = min(s[f + k], d + (1.0 - d) * abs(k) / (half + 1))
    return s


def kernel(d: float, sigma: float = 0.3) -> float:
    return math.exp(-d * d / (2 * sigma * sigma))


def test_bc_beat2_known_answer_on_planted_speed_minima():
    """Minima at 1-s steps; BEAT2 keeps those inside [2 s, T - 2 s] above 0.10 of the mean
    speed and scores each audio beat in that stretch by its nearest motion beat."""
    n = 301                                            # 10 s + 1 frame: stretch 2 .. 8.03 s
    minima = list(range(30, 300, 30))                  # 1, 2, ..., 9 s
    strong = dips(n, minima, [0.5] * len(minima))       # kept: 0.5 > 0.10
    faint = dips(n, minima, [0.05] * len(minima))       # dropped: 0.05 < 0.10
    middle = dips(n, minima, [0.2] * len(minima))       # kept here (0.2 > 0.10), not by 0.3
    speeds = np.stack([strong, faint, middle], axis=1)
    audio = np.array([1.0, 2.5, 3.1, 4.0, 5.3, 7.9, 9.0])   # 1.0 and 9.0 fall outside
    res = rl.bc_beat2(audio, FPS, speeds=speeds, mean_speed=1.0)
    # motion beats 3..7 s (2 s is the stretch's first frame and 8 s its last; 9 s is past it)
    per_joint = np.mean([kernel(0.5), kernel(0.1), kernel(0.0), kernel(0.3), kernel(0.9)])
    assert res.n_audio_beats == 5 and res.n_frames == 301 - 120
    assert res.bc == pytest.approx((per_joint + 0.0 + per_joint) / 3, abs=1e-12)
    assert res.motion_beats_per_s == pytest.approx(np.mean([5, 0, 5]) / (181 / FPS))
    # the project's BC keeps only minima above 0.3 of the mean: the 0.2 joint has none
    own = mm.beat_consistency(audio, FPS, speeds=speeds, joints=[2], mean_speed=np.ones(3))
    assert own.bc == 0.0
    # the reference speed counts: a dataset three times faster drops the 0.2 minima too
    fast = rl.bc_beat2(audio, FPS, speeds=speeds, mean_speed=np.array([1.0, 1.0, 3.0]))
    assert fast.bc == pytest.approx(per_joint / 3, abs=1e-12)


def test_bc_beat2_from_positions_and_the_original_index_slip():
    # positions: one joint whose speed is 1 - 0.5 cos(2 pi t): minima at whole seconds
    t = np.arange(int(10 * FPS) + 1) / FPS
    p = np.zeros((len(t), 1, 3))
    p[:, 0, 0] = t - 0.5 / (2 * np.pi) * np.sin(2 * np.pi * t)
    res = rl.bc_beat2(np.array([3.0, 4.2]), FPS, positions=p)
    assert res.bc == pytest.approx((1.0 + kernel(0.2)) / 2, abs=1e-9)
    # the original tests the threshold 2 s before the minimum (index within the stretch
    # against the whole motion): a minimum at 3 s is dropped when 1 s is near rest
    s = dips(301, [30, 90, 150], [0.05, 0.5, 0.5])[:, None]
    audio = np.array([3.0, 5.0])
    assert rl.bc_beat2(audio, FPS, speeds=s, mean_speed=1.0).bc == pytest.approx(1.0)
    slip = rl.bc_beat2(audio, FPS, speeds=s, mean_speed=1.0, mask_at_slice_index=True)
    assert slip.bc == pytest.approx((kernel(2.0) + 1.0) / 2, abs=1e-12)


def test_bc_beat2_without_beats_or_time_is_nan_and_bad_input_one_line_errors():
    s = dips(301, [90], [0.5])[:, None]
    assert math.isnan(rl.bc_beat2(np.array([0.5, 9.5]), FPS, speeds=s).bc)   # none inside
    assert math.isnan(rl.bc_beat2(np.array([1.0]), FPS, speeds=s[:100]).bc)  # 3.3 s < 4 s
    assert rl.bc_beat2(np.array([3.0]), FPS, speeds=np.ones((301, 1))).bc == 0.0
    with pytest.raises(GestureSimError, match="exactly one of positions or speeds"):
        rl.bc_beat2(np.array([3.0]), FPS)
    with pytest.raises(GestureSimError, match="mean speed must be positive"):
        rl.bc_beat2(np.array([3.0]), FPS, speeds=s, mean_speed=0.0)


# ------------------------------------------------------------------------- in eval motion


def test_eval_scores_a_long_run_with_both_figures_and_shows_them(real, tmp_path):
    from gesture_sim.app import evaluation as ev

    wav = tmp_path / "speech.wav"   # the 10 s fixture twice: 20 s of real speech
    with wave.open(str(DATA / "eval" / "2_scott_0_1_1_first10s.wav")) as src:
        params, frames = src.getparams(), src.readframes(src.getnframes())
    with wave.open(str(wav), "wb") as dst:
        dst.setparams(params)
        dst.writeframes(frames + frames)
    evaluator = ev.Evaluator()
    inp = ev.load_input(wav)
    run = ev.MotionRun("real", inp.name, 0, real[: int(20 * FPS)] + 0.001, None, {})
    out = evaluator.score(run, inp)
    assert 0.0 <= out["disc_accuracy"] <= 1.0 and out["disc_windows"] >= rl.MIN_WINDOWS
    assert 0.0 <= out["bc_beat2"] <= 1.0
    rows = [{"audio": inp.name, "method": "real", "seed": 0, "metrics": out}]
    result = ev.EvalResult(rows=rows, inputs=[], methods=["real"], seeds=[0],
                           reference=evaluator.reference_figures())
    table = ev.format_table(result, markdown=False)
    assert "discriminator acc." in table and "BC (BEAT2 tools)" in table
    assert 0.0 <= result.reference["disc_accuracy_split"] <= 1.0
    assert "disc_accuracy" in result.to_dict()["summary"]["real"]
