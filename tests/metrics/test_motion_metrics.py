"""Motion-quality metrics on toy signals whose answers are known in closed form."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, special

from gesture_sim.errors import GestureSimError
from gesture_sim.metrics import motion as mm

SR = 16_000


# ---------------------------------------------------------------------------------- helpers


def tone_bursts(onsets: list[float], duration: float, seed: int = 0) -> np.ndarray:
    """Harmonic bursts (3 ms attack, 120 ms sustain, 30 ms release) in -60 dB noise."""
    t = np.arange(int(duration * SR)) / SR
    x = 0.001 * np.random.default_rng(seed).standard_normal(len(t))
    for o in onsets:
        m = (t >= o) & (t < o + 0.15)
        tt = t[m] - o
        env = np.minimum(1.0, np.minimum(tt / 0.003, (0.15 - tt) / 0.03))
        x[m] += env * (0.3 * np.sin(2 * np.pi * 180 * t[m]) + 0.2 * np.sin(2 * np.pi * 540 * t[m]))
    return x


def motion_from_speed(speed: np.ndarray, fps: float, n_joints: int = 1) -> np.ndarray:
    """Positions (T, J, 3) moving along x with the given per-frame speed (m/s) on every joint.

    Built so that ``np.gradient`` (central differences) returns exactly ``speed``: positions are
    the cumulative sum of speed/fps, with speed chosen smooth enough for our use.
    """
    x = np.concatenate([[0.0], np.cumsum(speed[:-1])]) / fps
    p = np.zeros((len(speed), n_joints, 3))
    p[:, :, 0] = x[:, None]
    return p


def periodic_minima_positions(period_frames: int, n_periods: int, fps: float) -> np.ndarray:
    """One joint whose speed is 1 - 0.5 cos(2 pi t / P): minima 0.5 (half the mean) at k*P."""
    t = np.arange(period_frames * n_periods + 1) / fps
    period = period_frames / fps
    # x(t) = t - 0.5 P/(2 pi) sin(2 pi t/P): speed 1 - 0.5 cos(2 pi t / P), minima at k P.
    x = t - 0.5 * period / (2 * np.pi) * np.sin(2 * np.pi * t / period)
    p = np.zeros((len(t), 1, 3))
    p[:, 0, 0] = x
    return p


# ------------------------------------------------------------------------------ 1. onsets, BC


def test_onsets_found_at_burst_starts_and_not_in_noise() -> None:
    onsets = [0.3, 0.8, 1.5, 2.1, 2.5]
    found = mm.detect_onsets(tone_bursts(onsets, 3.0), SR)
    assert len(found) == len(onsets)
    np.testing.assert_allclose(found, onsets, atol=0.02)


def test_no_onsets_in_silence_or_steady_noise() -> None:
    assert mm.detect_onsets(np.zeros(SR), SR).size == 0
    noise = 0.01 * np.random.default_rng(1).standard_normal(2 * SR)
    # Steady noise is at the loudest level, so the gate does not help; flux peaks of white noise
    # stay below delta above the local mean almost everywhere.
    assert mm.detect_onsets(noise, SR).size <= 4


def test_beat_order_scales_with_frame_rate() -> None:
    assert mm.beat_order(30) == 7
    assert mm.beat_order(60) == 14
    assert mm.beat_order(120) == 28
    assert mm.beat_order(2) == 1


def test_motion_beats_threshold_rule() -> None:
    fps = 30.0
    t = np.arange(300)
    # Minima every 30 frames; alternate minima reach 0.2 and 0.5 of a mean speed of ~1.
    depth = np.where(np.rint(t / 30) % 2 == 0, 0.8, 0.5)
    speed = 1.0 - depth * np.cos(2 * np.pi * t / 30)
    beats = mm.motion_beats(speed, fps)
    mean = speed.mean()
    # The only interior minima are at multiples of 30; those with speed/mean <= 0.3 go.
    expected = [k for k in range(30, 300, 30) if speed[k] / mean > 0.3]
    assert list(beats) == expected
    assert all((k // 30) % 2 == 1 for k in expected) and len(expected) == 5
    # A reference mean speed changes the cut: with mean 0.1 every minimum passes.
    assert len(mm.motion_beats(speed, fps, mean_speed=0.1)) == 9


def test_bc_is_one_when_motion_beats_sit_on_audio_beats() -> None:
    fps, period = 30.0, 15
    pos = periodic_minima_positions(period, 12, fps)
    beats_s = np.arange(period, 12 * period, period) / fps
    scores = mm.beat_consistency(beats_s, fps, positions=pos)
    assert scores.bc == pytest.approx(1.0, abs=1e-12)
    assert scores.beat_align == pytest.approx(1.0, abs=1e-12)
    assert scores.n_audio_beats == 11


def test_bc_from_detected_onsets_of_clicks_on_the_motion_beats() -> None:
    fps, period = 30.0, 15
    pos = periodic_minima_positions(period, 8, fps)
    times = list(np.arange(period, 8 * period, period) / fps)
    audio = tone_bursts(times, 8 * period / fps + 0.2)
    scores = mm.beat_consistency(mm.detect_onsets(audio, SR), fps, positions=pos)
    # Onsets within 20 ms of the beats: exp(-0.02^2 / (2 * 0.3^2)) > 0.997.
    assert scores.bc > 0.997


def test_kernel_score_matches_the_exact_expectation_for_uniform_beats() -> None:
    """n motion beats uniform on [0, L]: E[exp(-D^2/2s^2)] = int (d/s^2) e^(-d^2/2s^2) P(D<d)."""
    L, n, sigma = 10.0, 12, mm.BEAT_SIGMA_S
    audio = np.array([1.0, 2.5, 5.0, 7.5, 9.9])

    def expected_one(b: float) -> float:
        def p_less(d: float) -> float:
            covered = min(b + d, L) - max(b - d, 0.0)
            return 1.0 - (1.0 - covered / L) ** n

        f = lambda d: d / sigma**2 * math.exp(-(d**2) / (2 * sigma**2)) * p_less(d)  # noqa: E731
        return integrate.quad(f, 0.0, 8 * sigma, limit=200)[0]

    expected = np.mean([expected_one(b) for b in audio])
    rng = np.random.default_rng(7)
    scores = [mm.beat_kernel_score(audio, rng.uniform(0, L, n)) for _ in range(4000)]
    # Each score is in [0, 1]; with 4000 draws the standard error is below 0.005.
    assert np.mean(scores) == pytest.approx(expected, abs=0.01)
    assert 0.3 < expected < 0.8  # the chance level is far from both 0 and 1


def test_bc_of_time_shifted_audio_is_at_chance_level() -> None:
    """Motion beats on a grid of period P, audio beats placed uniformly at random: the distance
    to the nearest motion beat is uniform on [0, P/2], so E[BC] = (2/P) s sqrt(pi/2)
    erf(P / (2 sqrt(2) s))."""
    fps, period = 30.0, 18
    n_periods = 20
    pos = periodic_minima_positions(period, n_periods, fps)
    p_s, sigma = period / fps, mm.BEAT_SIGMA_S
    chance = (2 / p_s) * sigma * math.sqrt(math.pi / 2)
    chance *= special.erf(p_s / (2 * math.sqrt(2) * sigma))
    rng = np.random.default_rng(3)
    lo, hi = p_s, (n_periods - 1) * p_s  # between the first and last motion beat
    bcs = [
        mm.beat_consistency(rng.uniform(lo, hi, 15), fps, positions=pos).bc for _ in range(300)
    ]
    assert np.mean(bcs) == pytest.approx(chance, abs=0.01)
    assert chance < 0.9  # and well below the aligned value of 1


def test_bc_counts_joints_without_beats_as_zero() -> None:
    fps, period = 30.0, 15
    moving = periodic_minima_positions(period, 8, fps)
    still = np.concatenate([moving, np.zeros_like(moving)], axis=1)
    beats_s = np.arange(period, 8 * period, period) / fps
    scores = mm.beat_consistency(beats_s, fps, positions=still)
    assert scores.bc == pytest.approx(0.5)  # (1 + 0) / 2 joints
    assert scores.beat_align == pytest.approx(1.0)  # only joints with beats
    only_first = mm.beat_consistency(beats_s, fps, positions=still, joints=[0])
    assert only_first.bc == pytest.approx(1.0)


def test_beat_consistency_needs_one_motion_input() -> None:
    with pytest.raises(GestureSimError):
        mm.beat_consistency(np.array([1.0]), 30.0)


# ----------------------------------------------------------------------- 2. prosody coupling


def smooth_noise(n: int, seed: int) -> np.ndarray:
    """A smooth random envelope at 100 Hz (Gaussian-filtered noise, ~100 ms correlation)."""
    from scipy.ndimage import gaussian_filter1d

    return gaussian_filter1d(np.random.default_rng(seed).standard_normal(n), 6.0)


@pytest.mark.parametrize("lag_s", [0.2, -0.15, 0.0])
def test_coupling_finds_a_known_lag(lag_s: float) -> None:
    n = 3000  # 30 s at 100 Hz
    inten = 60.0 + 10.0 * smooth_noise(n + 200, seed=5)
    fps = 30.0
    t_motion = np.arange(int(29 * fps)) / fps
    # hand speed(t) = intensity(t - lag): the hand follows the speech by lag.
    grid = np.arange(len(inten)) * 0.01
    speed = 0.5 + 0.05 * (np.interp(t_motion - lag_s + 1.0, grid, inten) - 60.0)
    c = mm.prosody_coupling(speed, fps, inten[100 : 100 + n])
    assert c.lag_intensity_s == pytest.approx(lag_s, abs=0.011)
    assert c.r_intensity_best > 0.95
    if lag_s != 0.0:
        assert c.r_intensity < c.r_intensity_best


def test_lagged_correlation_sign_convention() -> None:
    x = smooth_noise(1000, seed=2)
    y = np.roll(x, 7)  # y[t] = x[t - 7]: y follows x by 70 ms
    lags, r = mm.lagged_correlation(x, y, 100.0, 0.5)
    assert lags[np.argmax(r)] == pytest.approx(0.07)
    assert r.max() == pytest.approx(1.0, abs=1e-9)


def test_pitch_accents_and_hit_rate() -> None:
    n = 500  # 5 s of 10 ms frames
    t = np.arange(n) * 0.01
    accents_true = [0.5, 1.5, 2.5, 3.5]
    f0 = 100.0 + sum(50.0 * np.exp(-((t - a) ** 2) / (2 * 0.03**2)) for a in accents_true)
    f0[(t > 4.2) & (t < 4.5)] = np.nan  # an unvoiced stretch
    found = mm.pitch_accents(f0)
    np.testing.assert_allclose(found, accents_true, atol=0.011)

    fps = 30.0
    tm = np.arange(int(5 * fps)) / fps
    peaks_true = [0.6, 1.4, 2.9, 3.1]  # 0.1, 0.1, 0.4, 0.4 s from the accents
    speed = 0.1 + sum(np.exp(-((tm - p) ** 2) / (2 * 0.05**2)) for p in peaks_true)
    np.testing.assert_allclose(mm.speed_peaks(speed, fps), peaks_true, atol=0.02)
    c = mm.prosody_coupling(speed, fps, np.full(n, 60.0) + t, f0)
    assert c.n_accents == 4
    assert c.accent_hit_rate == pytest.approx(0.5)
    assert 0.0 <= c.accent_hit_chance <= 1.0


def test_pitch_accents_ignore_tracker_blips() -> None:
    """A single-frame octave jump and a 30 ms voiced blip are no pitch accents; the syllables'
    own F0 peaks still are, at their times."""
    n = 500
    t = np.arange(n) * 0.01
    accents_true = [0.5, 1.5, 2.5, 3.5]
    f0 = 100.0 + sum(50.0 * np.exp(-((t - a) ** 2) / (2 * 0.05**2)) for a in accents_true)
    f0[100] = 300.0                       # one frame at 1.0 s: an octave error
    f0[(t > 2.9) & (t < 3.2)] = np.nan    # a pause ...
    f0[300:303] = 280.0                   # ... with a 30 ms voiced blip at 3.0 s in it
    np.testing.assert_allclose(mm.pitch_accents(f0), accents_true, atol=0.011)
    cleaned = mm.clean_f0(f0)
    assert np.isnan(cleaned[300:303]).all()
    assert cleaned[100] == pytest.approx(100.0, abs=1.0)


def test_accent_hit_chance_reads_timing_at_any_density() -> None:
    """Peaks on every accent of a 1 /s train hit all of them, shifted peaks 40 % (±0.2 s of a
    1 s period); a dense peak train (4 /s) hits every accent wherever it lies, so its excess over
    chance is about 0; peaks independent of the accents have no excess either."""
    dur = 60.0
    accents = np.arange(1.0, 59.0, 1.0)
    on = mm.accent_hit_chance(accents, accents.copy(), dur)
    assert mm.accent_hit_rate(accents, accents) == 1.0
    assert on == pytest.approx(0.4, abs=0.06)
    dense = np.arange(0.0, dur, 0.25)
    assert mm.accent_hit_rate(accents, dense) - mm.accent_hit_chance(accents, dense, dur) \
        == pytest.approx(0.0, abs=0.05)
    rng = np.random.default_rng(0)
    loose = np.sort(rng.uniform(0.0, dur, 80))
    assert abs(mm.accent_hit_rate(accents, loose)
               - mm.accent_hit_chance(accents, loose, dur)) < 0.15
    assert np.isnan(mm.accent_hit_chance(np.zeros(0), loose, dur))
    assert np.isnan(mm.accent_hit_chance(accents, loose, 1.5))
    assert mm.accent_hit_chance(accents, np.zeros(0), dur) == 0.0


def test_f0_derivative_envelope_units() -> None:
    # F0 rising one octave per second: 12 semitones/s; NaN where unvoiced.
    t = np.arange(100) * 0.01
    f0 = 100.0 * 2.0**t
    f0[50:60] = np.nan
    d = mm.f0_derivative_envelope(f0)
    np.testing.assert_allclose(d[2:45], 12.0, rtol=1e-9)
    assert np.all(np.isnan(d[50:60]))


# ------------------------------------------------------------------------------------ 3. FGD


def test_frechet_distance_closed_forms() -> None:
    # 1-D: (m1 - m2)^2 + (s1 - s2)^2.
    assert mm.frechet_distance([1.0], [[4.0]], [3.0], [[9.0]]) == pytest.approx(4.0 + 1.0)
    # Diagonal: |dmu|^2 + sum (sqrt a - sqrt b)^2.
    a, b = np.array([1.0, 4.0, 9.0]), np.array([4.0, 4.0, 1.0])
    mu1, mu2 = np.array([0.0, 1.0, 2.0]), np.array([1.0, 1.0, 0.0])
    expected = 1.0 + 4.0 + (1 - 2) ** 2 + 0.0 + (3 - 1) ** 2
    assert mm.frechet_distance(mu1, np.diag(a), mu2, np.diag(b)) == pytest.approx(expected)
    # Non-commuting 2x2: Tr sqrt(S1 S2) = sqrt(tr(S1 S2) + 2 sqrt(det S1 det S2)).
    s1 = np.array([[2.0, 0.8], [0.8, 1.0]])
    s2 = np.array([[1.0, -0.3], [-0.3, 3.0]])
    tr_sqrt = math.sqrt(np.trace(s1 @ s2) + 2 * math.sqrt(np.linalg.det(s1) * np.linalg.det(s2)))
    expected = np.trace(s1) + np.trace(s2) - 2 * tr_sqrt
    assert mm.frechet_distance(np.zeros(2), s1, np.zeros(2), s2) == pytest.approx(expected)
    # Singular covariances stay real and non-negative.
    z = np.zeros((3, 3))
    assert mm.frechet_distance(np.zeros(3), z, np.ones(3), z) == pytest.approx(3.0)


def test_frechet_distance_of_samples_approaches_the_gaussians_value() -> None:
    rng = np.random.default_rng(0)
    s1 = np.array([[2.0, 0.8], [0.8, 1.0]])
    s2 = np.array([[1.0, -0.3], [-0.3, 3.0]])
    a = rng.multivariate_normal([0.0, 0.0], s1, 40_000)
    b = rng.multivariate_normal([1.0, -1.0], s2, 40_000)
    tr_sqrt = math.sqrt(np.trace(s1 @ s2) + 2 * math.sqrt(np.linalg.det(s1) * np.linalg.det(s2)))
    expected = 2.0 + np.trace(s1) + np.trace(s2) - 2 * tr_sqrt
    assert mm.frechet_distance_features(a, b) == pytest.approx(expected, abs=0.08)


def random_gesture_windows(n: int, seed: int) -> np.ndarray:
    """Smooth random 3-joint motions cut into windows (n, 34, 3, 3)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, 34)[None, :, None, None]
    amp = rng.normal(0, 0.1, (n, 1, 3, 3))
    freq = rng.uniform(0.5, 2.0, (n, 1, 3, 3))
    phase = rng.uniform(0, 2 * np.pi, (n, 1, 3, 3))
    return amp * np.sin(2 * np.pi * freq * t + phase)


def test_fgd_zero_for_identical_sets_and_quadratic_in_a_shift() -> None:
    real = random_gesture_windows(200, seed=1)
    ext = mm.FGDExtractor(n_components=16).fit(real)
    other = random_gesture_windows(200, seed=2)
    assert ext.fgd(other, other) == pytest.approx(0.0, abs=1e-9)
    shift = np.zeros((1, 1, 3, 3))
    shift[..., 0] = 0.02
    d1 = mm.fgd(other + shift, other, ext)
    d2 = mm.fgd(other + 2 * shift, other, ext)
    d3 = mm.fgd(other + 3 * shift, other, ext)
    assert 0 < d1 < d2 < d3
    # Same covariance on both sides: only |dmu|^2 remains, quadratic in the shift.
    assert d2 / d1 == pytest.approx(4.0, rel=1e-6)
    assert d3 / d1 == pytest.approx(9.0, rel=1e-6)


def test_fgd_extractor_save_load_round_trip(tmp_path: Path) -> None:
    real = random_gesture_windows(50, seed=3)
    ext = mm.FGDExtractor(n_components=8).fit(real)
    path = tmp_path / "fgd.npz"
    ext.save(path)
    back = mm.FGDExtractor.load(path)
    np.testing.assert_allclose(back.transform(real), ext.transform(real))
    assert ext.transform(real).shape == (50, 8)
    with pytest.raises(GestureSimError):
        back.transform(np.zeros((4, 30, 3, 3)))
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(GestureSimError):
        mm.FGDExtractor.load(tmp_path / "bad.npz")


def test_fgd_features_are_standardised_pca() -> None:
    # Two flattened dimensions with very different scales are equalised by standardisation;
    # PCA of perfectly correlated dimensions leaves one component carrying all variance.
    rng = np.random.default_rng(0)
    u = rng.standard_normal(500)
    windows = np.stack([3.0 * u, 0.5 * u], axis=1)[:, None, :]  # (500, 1, 2)
    f = mm.FGDExtractor(n_components=2).fit(windows).transform(windows)
    assert np.var(f[:, 0]) == pytest.approx(2.0, rel=1e-6)  # two unit-variance dims
    assert np.var(f[:, 1]) == pytest.approx(0.0, abs=1e-12)


def test_motion_windows_shapes_and_root_relative() -> None:
    pos = np.random.default_rng(0).standard_normal((100, 4, 3))
    w = mm.motion_windows(pos, window=34, stride=17)
    assert w.shape == (4, 34, 4, 3)  # starts 0, 17, 34, 51 (68 + 34 > 100)
    np.testing.assert_allclose(w[1, 0], pos[17] - pos[17, 0])
    assert np.all(w[:, :, 0] == 0)


# ------------------------------------------------------------------------------ 4. diversity


def test_feature_diversity_known_answers() -> None:
    two = np.array([[0.0, 0.0], [2.0, 0.0]])
    assert mm.feature_diversity(two) == pytest.approx(2.0)
    s = 1.5
    triangle = np.array([[0.0, 0.0], [s, 0.0], [s / 2, s * math.sqrt(3) / 2]])
    assert mm.feature_diversity(triangle, n_pairs=300, seed=4) == pytest.approx(s)
    assert mm.feature_diversity(np.ones((10, 3))) == 0.0


def test_l1_diversity_known_answer() -> None:
    poses = np.zeros((10, 2, 3))
    poses[::2, 1, 2] = 0.3
    poses[1::2, 1, 2] = -0.3  # mean 0, every frame 0.3 away on one coordinate
    poses[:, 0, :] = 5.0  # constant joint adds nothing
    assert mm.l1_diversity(poses) == pytest.approx(0.3)


# ----------------------------------------------------------------------------- 5. smoothness


def test_jerk_and_acceleration_of_polynomials() -> None:
    fps = 60.0
    t = np.arange(120) / fps
    pos = np.zeros((120, 2, 3))
    c = 4.0  # x = c t^3 / 6 has jerk c, acceleration c t
    pos[:, 0, 0] = c * t**3 / 6
    pos[:, 1, 1] = 2.5 * t**2 / 2  # acceleration 2.5, jerk 0
    assert mm.mean_jerk(pos, fps) == pytest.approx(c / 2, rel=1e-6)  # mean over the 2 joints
    acc0 = c * (np.arange(118) + 1) / fps  # diff n=2 at sample k is centred on frame k + 1
    assert mm.mean_acceleration(pos, fps) == pytest.approx((acc0.mean() + 2.5) / 2, rel=1e-6)


def test_transition_jerk_of_a_velocity_kink() -> None:
    fps, s, v = 30.0, 40, 0.6
    frames = np.arange(100)
    pos = np.zeros((100, 2, 3))
    pos[:, 0, 0] = np.where(frames > s, v * (frames - s) / fps, 0.0)  # velocity step at frame s
    # Third differences of the kink: only samples k = s-2 and s-1 are non-zero, |v/fps| each,
    # i.e. v fps^2 in m/s^3 for joint 0 and 0 for the still joint 1 (mean over joints: half).
    tj = mm.transition_jerk(pos, fps, [s])
    # Boundary samples: centres k + 1.5 within +-3 of s, i.e. k = s-4 .. s+1 (6 samples).
    assert tj.boundary == pytest.approx(2 * (v * fps**2 / 2) / 6)
    assert tj.elsewhere == pytest.approx(0.0, abs=1e-9)
    assert tj.ratio > 1e6
    # A switch far from the kink sees no jerk there.
    far = mm.transition_jerk(pos, fps, [80])
    assert far.boundary == pytest.approx(0.0, abs=1e-9) and far.elsewhere > 1.0


# ------------------------------------------------------------------------------- 6. Hellinger


def test_speed_hellinger_identical_disjoint_and_partial() -> None:
    fps = 30.0
    slow = motion_from_speed(np.full(61, 1.0), fps, n_joints=2)
    fast = motion_from_speed(np.full(61, 2.5), fps, n_joints=2)
    assert mm.speed_hellinger(slow, fps, slow) == pytest.approx(0.0, abs=1e-12)
    assert mm.speed_hellinger(slow, fps, fast) == pytest.approx(1.0)
    # Half the frames at 1.01 m/s, half at 2 m/s vs all at 1.01: sqrt(1 - sqrt(1/2)).
    mixed = motion_from_speed(np.repeat([1.01, 2.0], [30, 31]), fps)
    steady = motion_from_speed(np.full(61, 1.01), fps)
    expected = math.sqrt(1 - math.sqrt(0.5))
    assert mm.speed_hellinger(mixed, fps, steady) == pytest.approx(expected)
    # Frame rates may differ: speeds are in m/s.
    slow60 = motion_from_speed(np.full(121, 1.0), 60.0, n_joints=2)
    assert mm.speed_hellinger(slow60, 60.0, slow, fps) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(GestureSimError):
        mm.speed_hellinger(slow, fps, slow[:, :1])


# -------------------------------------------------------------------------------- 7. summary


def test_summarise_motion_on_aligned_motion() -> None:
    fps, period = 30.0, 15
    pos = periodic_minima_positions(period, 8, fps)
    pos = np.concatenate([pos, pos + 0.1], axis=1)  # two joints
    audio = tone_bursts(list(np.arange(period, 8 * period, period) / fps), 8 * period / fps)
    f0 = np.full(len(mm.intensity_envelope(audio)), np.nan)
    out = mm.summarise_motion(pos, fps, audio, f0_hz=f0, reference=pos, switch_frames=[30, 60],
                              window=20, root_joint=None)
    assert out["bc"] > 0.997
    assert out["hellinger_speed"] == pytest.approx(0.0, abs=1e-12)
    assert out["fgd"] == pytest.approx(0.0, abs=1e-9)
    assert out["fgd_ref_split"] > 0.0  # two different halves of a small set differ
    assert out["duration_s"] == pytest.approx(len(pos) / fps)
    assert {"mean_jerk", "mean_acceleration", "l1div", "beat_align", "r_intensity_best",
            "transition_jerk_ratio", "feature_diversity", "accent_hit_rate",
            "accent_hit_excess"} <= set(out)
    assert all(isinstance(v, float) for v in out.values())
    bare = mm.summarise_motion(pos, fps)
    assert "bc" not in bare and "fgd" not in bare


def test_bad_input_is_a_user_error() -> None:
    with pytest.raises(GestureSimError):
        mm.mean_jerk(np.zeros((10, 3)), 30.0)
    with pytest.raises(GestureSimError):
        mm.mean_jerk(np.zeros((10, 2, 3)), 0.0)
    with pytest.raises(GestureSimError):
        mm.mean_jerk(np.zeros((3, 2, 3)), 30.0)


def test_stress_hits_less_chance_read_timing_not_peak_density() -> None:
    """Hand-speed bumps on 40 irregular stressed vowels hit every one of them and earn most of
    that over chance; bumps every 0.25 s hit every stress too, wherever it lies, and earn
    nothing over chance; with no stresses inside the motion the figures are NaN."""
    from gesture_sim.metrics.inputs import stress_timing
    from gesture_sim.metrics.points import EVAL_FPS

    dur = 60.0
    t = np.arange(0.0, dur, 1.0 / EVAL_FPS)
    rng = np.random.default_rng(3)
    stress = np.sort(rng.choice(np.arange(1.0, 59.0, 0.7), 40, replace=False))

    def bumps(times: np.ndarray) -> np.ndarray:
        return np.exp(-0.5 * ((t[:, None] - times[None, :]) / 0.05) ** 2).sum(axis=1)

    on = stress_timing(stress, bumps(stress), dur)
    assert on["stress_hit_rate"] == 1.0
    assert on["stress_hit_excess"] > 0.5
    dense = stress_timing(stress, bumps(np.arange(0.1, dur, 0.25)), dur)
    assert dense["stress_hit_rate"] == 1.0
    assert abs(dense["stress_hit_excess"]) < 0.05
    assert np.isnan(stress_timing(np.array([70.0]), bumps(stress), dur)["stress_hit_excess"])


def test_head_peaks_on_accents_less_chance_reads_the_timing_not_the_density() -> None:
    """A head that moves on every accent scores well over chance; one that moves every 0.25 s
    hits every accent too, raw, but not over chance (its share is what any timing would get)."""
    from gesture_sim.metrics.inputs import head_timing

    dur = 60.0
    t = np.arange(0.0, dur, 0.01)
    rng = np.random.default_rng(5)
    accents = np.sort(rng.choice(np.arange(1.0, 59.0, 0.9), 30, replace=False))

    def speed(times: np.ndarray) -> np.ndarray:       # rad/s bumps, well over the prominence
        return 2.0 * np.exp(-0.5 * ((t[:, None] - times[None, :]) / 0.04) ** 2).sum(axis=1)

    on = head_timing(accents, t, speed(accents + 0.05), dur)
    assert on["head_accent_hits"] == 1.0
    assert on["head_accent_excess"] > 0.5
    dense = head_timing(accents, t, speed(np.arange(0.1, dur, 0.25)), dur)
    assert dense["head_accent_hits"] == 1.0
    assert abs(dense["head_accent_excess"]) < 0.05
    assert head_timing(accents, t, np.zeros_like(t), dur)["head_accent_excess"] == 0.0
