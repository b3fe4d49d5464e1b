"""Style words from clip names and tones fitted from styled performances."""

from __future__ import annotations

import numpy as np

from gesture_sim.control.style import default_tones, fitted_tones, style_of


def test_style_words_are_read_from_bandai_clip_names() -> None:
    assert style_of("dataset-1_bow_active_001") == "active"
    assert style_of("dataset-1_guide_not-confident_001") == "not-confident"
    assert style_of("2_scott_0_1_1") == ""


def test_fitted_tones_shift_by_the_styles_mean_difference() -> None:
    rng = np.random.default_rng(0)
    normal = rng.normal(0.0, 1.0, (20, 6))
    tired = rng.normal(0.0, 1.0, (20, 6)) + np.array([0, -1.0, -1.0, 0, 0, 0])
    active = rng.normal(0.0, 1.0, (20, 6)) + np.array([0, 1.0, 1.0, 0, 0, 0])
    params = np.concatenate([normal, tired, active])
    styles = ["normal"] * 20 + ["tired"] * 20 + ["active"] * 20
    calm, neutral, energetic = fitted_tones(params, styles)
    assert np.allclose(calm.offset, tired.mean(0) - normal.mean(0))
    assert np.allclose(energetic.offset, active.mean(0) - normal.mean(0))
    assert np.allclose(neutral.offset, 0.0)
    # too few styled segments: the default shifts
    few = fitted_tones(params[:25], styles[:25])
    assert np.allclose(few[2].offset, default_tones()[2].offset)
