"""Segmentation into gesture phases and the six kinematic parameters."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.motion.build import build_library
from gesture_sim.motion.kinematics import (
    fit_normalisation,
    interruption_frames,
    normalise,
    raw_parameters,
)
from gesture_sim.motion.segmentation import MIN_FRAMES, SegmentationSettings, segment_clip

DATA = Path(__file__).resolve().parents[1] / "data" / "motion"
FPS = 30.0


def _hold_move_hold(hold1=30, move=15, hold2=30, speed=0.6):
    """Both hands: still, then moving along +x at ``speed`` m/s, then still."""
    x = np.concatenate([np.zeros(hold1), np.arange(1, move + 1) * speed / FPS,
                        np.full(hold2, move * speed / FPS)])
    pos = np.zeros((len(x), 2, 3))
    pos[:, :, 0] = x[:, None]
    pos[:, 1, 1] = -0.3
    return pos


def test_boundaries_where_hand_speed_crosses_the_threshold():
    segs = segment_clip(_hold_move_hold(), FPS, SegmentationSettings(threshold=0.2, smooth_s=0.0))
    starts = [a for a, _ in segs]
    assert len(segs) == 3
    assert abs(starts[1] - 30) <= 1 and abs(starts[2] - 45) <= 1


def test_segments_tile_the_clip_within_length_bounds():
    rng = np.random.default_rng(0)
    pos = np.cumsum(rng.normal(0, 0.01, (600, 2, 3)), axis=0)
    s = SegmentationSettings()
    segs = segment_clip(pos, FPS, s)
    assert segs[0][0] == 0 and segs[-1][1] == 600
    assert all(a[1] == b[0] for a, b in zip(segs[:-1], segs[1:], strict=True))
    lengths = np.array([b - a for a, b in segs])
    assert lengths.min() >= MIN_FRAMES
    assert lengths.max() <= round(s.max_length_s * FPS)


def test_long_hold_is_split_and_tiny_blip_is_merged():
    pos = np.zeros((200, 2, 3))
    pos[100:103, 0, 0] = [0.005, 0.01, 0.005]  # a 3-frame twitch, 1 cm
    segs = segment_clip(pos, FPS, SegmentationSettings(max_length_s=1.5, smooth_s=0.0))
    assert all(b - a <= 45 for a, b in segs)
    assert all(b - a >= 9 for a, b in segs)  # no 3-frame segment around the twitch


def test_beat2_excerpt_median_segment_length(small_library):
    lib, _ = small_library
    lengths = np.array([s.length for s in lib.segments if s.clip == 0]) / lib.fps
    assert len(lengths) >= 6
    assert 0.3 <= np.median(lengths) <= 1.5


def test_raw_parameters_of_known_motions():
    # Both hands move along +x at 0.5 m/s for 1 s at constant height 1 m.
    n = 31
    pos = np.zeros((n, 2, 3))
    pos[:, :, 0] = (np.arange(n) * 0.5 / FPS)[:, None]
    height = np.ones((n, 2))
    t, d, v, a, c, h = raw_parameters(pos, height, FPS, [(0, n)])[0]
    assert t == pytest.approx(n / FPS)
    assert v == pytest.approx(0.5 * np.sqrt(2), rel=1e-6)       # 6-D speed of two hands
    disp = np.sqrt(2) * 0.5 * np.arange(n) / FPS
    assert d == pytest.approx(disp.mean(), rel=1e-6)
    assert h == pytest.approx(2.0)
    assert a < 0.05 and c < 0.05                                # straight, uniform
    # A circle of radius 0.2 m at 1 m/s: curvature 1/r = 5 1/m, acceleration v^2/r = 5 m/s^2.
    n = 120
    ang = np.arange(n) / FPS / 0.2
    circle = np.zeros((n, 2, 3))
    circle[:, :, 0] = 0.2 * np.cos(ang)[:, None]
    circle[:, :, 2] = 0.2 * np.sin(ang)[:, None]
    raw = raw_parameters(circle, height[:1].repeat(n, 0), FPS, [(5, n - 5)])[0]
    assert raw[5 - 1] == pytest.approx(5.0, rel=0.05)
    assert raw[4] == pytest.approx(5.0, rel=0.05)
    assert raw[3] == pytest.approx(5.0 * np.sqrt(2), rel=0.05)


def test_normalisation_centres_and_scales():
    rng = np.random.default_rng(1)
    raw = np.exp(rng.normal(0, 0.7, (200, 6)))
    norm = fit_normalisation(raw)
    z = normalise(raw, norm)
    np.testing.assert_allclose(np.median(z, axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(z.std(axis=0), 1, atol=1e-9)


@pytest.mark.parametrize("length", [4, 5, 7, 30, 45])
def test_three_uniform_interruption_frames(length):
    f = interruption_frames(length)
    assert 0 < f[0] < f[1] < f[2] < length
    assert max(abs(f[k] - length * (k + 1) / 4) for k in range(3)) <= 1


def test_calm_clips_have_lower_velocity_and_extent(retargeter):
    pairs = [("dataset-1_bye_sad_001", "dataset-1_bye_active_001"),
             ("dataset-1_bow_sad_001", "dataset-1_bow_active_001")]
    files = [DATA / f"{n}.bvh" for pair in pairs for n in pair]
    lib, _ = build_library(files, retargeter=retargeter)
    raw_by_clip = []
    for c in range(len(lib.clips)):
        segs = [(s.start, s.end) for s in lib.segments if s.clip == c]
        kp = lib.clips[c].keypoints.astype(float)
        raw = raw_parameters(kp[:, :2], kp[:, :2, 2], lib.fps, segs)
        w = np.array([b - a for a, b in segs], dtype=float)
        raw_by_clip.append((raw * w[:, None]).sum(0) / w.sum())
    for k in range(len(pairs)):
        calm, energetic = raw_by_clip[2 * k], raw_by_clip[2 * k + 1]
        assert calm[2] < energetic[2]   # velocity
        assert calm[1] < energetic[1]   # spatial extent
        assert calm[3] < energetic[3]   # acceleration
