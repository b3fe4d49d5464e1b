"""``bench train``'s synthetic corpus: its length, its mirrors and warps, its re-paired speech,
and one tiny end-to-end run that has every stage."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.commands.bench import train as bt
from gesture_sim.contracts import Syllable
from gesture_sim.motion.retarget import KEYPOINTS, heading_frame

DATA = Path(__file__).resolve().parents[1] / "data"
JOINTS = ("pelvis_x", "left_shoulder_y", "right_shoulder_y", "left_elbow", "right_elbow", "neck")


def _source(n: int = 300, seed: int = 0, yaw: float = 0.4) -> bt.SourceClip:
    """A clip with moving hands and a turning pelvis (world frame)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 30.0
    kp = rng.normal(0.0, 0.05, (n, len(KEYPOINTS), 3)) + np.array([0.2, 0.0, 1.0])
    kp[:, 0] += np.stack([np.sin(3 * t), 0.3 + 0.1 * np.cos(2 * t), 0.1 * np.sin(5 * t)], 1)
    kp[:, 1] += np.stack([np.cos(2 * t), -0.3 + 0.2 * np.sin(t), 0.1 * np.cos(4 * t)], 1)
    ang = yaw * np.sin(0.5 * t)
    quat = np.stack([np.cos(ang / 2), np.zeros(n), np.zeros(n), np.sin(ang / 2)], 1)
    root = np.stack([0.1 * t, 0.05 * np.sin(t), np.full(n, 0.9)], 1)
    return bt.SourceClip("src", 30.0, rng.normal(size=(n, len(JOINTS))), root, quat, kp)


def _speech(seconds: float = 4.0) -> bt.Speech:
    syl = [Syllable(0.3 * i, 0.3 * i + 0.25, 0.3 * i + 0.3, 150.0, 70.0, True)
           for i in range(int(seconds / 0.3))]
    return bt.Speech(syl, seconds)


@pytest.mark.parametrize("seconds", [7.0, 30.0, 61.3])
def test_corpus_has_the_asked_length(seconds: float) -> None:
    takes = bt.synthetic_corpus([_source(), _source(200, 1)], [_speech()], JOINTS, seconds, 2)
    frames = sum(t.clip.n_frames for t in takes)
    assert abs(frames - seconds * 30.0) <= 1
    assert all(t.clip.n_frames >= 60 or len(takes) == 1 for t in takes)
    assert {t.mirrored for t in takes} == ({False, True} if len(takes) > 2 else {False})
    factors = [t.factor for t in takes]
    assert min(factors) >= bt.WARP_RANGE[0] and max(factors) <= bt.WARP_RANGE[1]


def test_mirrored_left_hand_is_the_mirrored_right_hand() -> None:
    src = _source()
    mir = bt.mirror_clip(src, JOINTS)
    h0 = heading_frame(src.root_pos, src.root_quat, src.keypoints)
    h1 = heading_frame(mir.root_pos, mir.root_quat, mir.keypoints)
    left, right = KEYPOINTS.index("left_hand"), KEYPOINTS.index("right_hand")
    np.testing.assert_allclose(h1[:, left], h0[:, right] * np.array([1.0, -1.0, 1.0]),
                               atol=1e-9)
    np.testing.assert_allclose(h1[:, right], h0[:, left] * np.array([1.0, -1.0, 1.0]),
                               atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(mir.root_quat, axis=1), 1.0)
    # joint columns swapped by name, the others unchanged
    np.testing.assert_array_equal(mir.qpos[:, 1], src.qpos[:, 2])
    np.testing.assert_array_equal(mir.qpos[:, 0], src.qpos[:, 0])
    np.testing.assert_array_equal(mir.qpos[:, 5], src.qpos[:, 5])


def test_warp_keeps_the_path_and_changes_the_duration() -> None:
    src = _source()
    slow = bt.warp_clip(src, 1.25)
    assert slow.n_frames == 375
    np.testing.assert_allclose(slow.keypoints[0], src.keypoints[0])
    np.testing.assert_allclose(slow.keypoints[-1], src.keypoints[-1])
    # the mid-frame of the warped clip is the source's mid-frame (linear time map)
    np.testing.assert_allclose(slow.keypoints[187], src.keypoints[149] * 0.5
                               + src.keypoints[150] * 0.5, atol=0.05)
    np.testing.assert_allclose(np.linalg.norm(slow.root_quat, axis=1), 1.0)


def test_repaired_speech_is_concatenated_and_cut() -> None:
    a, b = _speech(4.0), _speech(2.0)
    syl = bt.repaired_speech([a, b], 1, 7.0)          # b, a, b(cut)
    starts = np.array([s.t_start for s in syl])
    assert np.all(np.diff(starts) > 0)
    assert syl[-1].t_end <= 7.0
    assert len(syl) == len(b.syllables) + len(a.syllables) + sum(
        1 for s in b.syllables if s.t_end <= 1.0)
    assert syl[len(b.syllables)].t_start == pytest.approx(2.0)


def test_tiny_run_has_every_stage() -> None:
    motion = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
    audio = DATA / "eval" / "2_scott_0_1_1_first10s.wav"
    row = bt.measure_length([(str(motion), str(audio))], 0.5, states=3, decisions=20)
    assert set(row["stages"]) == set(bt.STAGES)
    assert abs(row["corpus_s"] - 30.0) <= 1 / 30
    assert row["segments"] > 10
    assert all(s["seconds"] >= 0 and s["peak_mb"] > 0 for s in row["stages"].values())
    assert 0 < row["decision_ms_median"] <= row["decision_ms_p99"]
    assert row["import_measured"]["scale"] == pytest.approx(3.0, rel=0.01)


def test_far_switch_cap_keeps_every_vertex_best_and_bounds_the_lists() -> None:
    from gesture_sim.control.prune import far_switches

    rng = np.random.default_rng(5)
    p_n, n, d_n = 40, 300, 6
    s = rng.uniform(0.0, 10.0, (p_n, n))
    s[rng.random((p_n, n)) < 0.1] = np.inf
    w = rng.uniform(0.0, 20.0, (n, d_n))
    w[3] = np.inf                                      # a row that is never a candidate
    keep = far_switches(s, w, per_reference=4, n_mixed=2)
    x = s[:, :, None] + w[None]                        # (P, n, D)
    best = np.argmin(np.where(np.isfinite(x), x, np.inf), axis=1)        # (P, D)
    assert keep[np.arange(p_n)[:, None], best].all()
    assert keep.sum(axis=1).max() <= (d_n + 1 + 2) * 4
    assert not keep[:, 3].any() and not keep[~np.isfinite(s)].any()
