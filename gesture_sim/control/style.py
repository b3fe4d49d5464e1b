"""Style ("tone") control (Gesture Controllers §8.2).

A tone m is an affine transform ``T_m(y) = A_m y + b_m`` of the kinematic parameter space that
maps the neutral state distributions onto toned ones. The cost of segment a under tone m is
``eta^m_a(i) = E ||T_m Y - y_a||`` with ``Y ~ N(mu_i, Sigma_i)``, i.e. eta computed with the
transformed Gaussians ``N(A mu_i + b, A Sigma_i A^T)``. One value function is solved per tone, and
at run time they are blended linearly with convex weights ``d`` (``V = sum_m d_m V^m``), which is
exact at the tones and an approximation between them (min does not distribute over the sum).

The default tones shift the spatial extent D, velocity V and acceleration A of every state by
``±shift`` (normalised units, i.e. library standard deviations): calm (−), neutral (0),
energetic (+). A tone can also be fitted from data with :func:`fit_tone` (Gaussian-to-Gaussian map).
The scalar style dial ``s ∈ [-1, 1]`` blends calm↔neutral for s < 0 and neutral↔energetic for
s > 0 (:func:`dial_weights`). Users set the style in [0, 1] (0 calm, 0.5 neutral, 1 energetic);
:func:`clip_style` keeps a setting in that range and :func:`dial_from_style` is the one
conversion to the controller's dial.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import sqrtm

from gesture_sim.errors import GestureSimError

#: Column indices of the kinematic parameters (T, D, V, A, C, H).
PARAM_INDEX = {"T": 0, "D": 1, "V": 2, "A": 3, "C": 4, "H": 5}


@dataclass(frozen=True)
class Tone:
    """An affine transform of the 6-D kinematic parameters: ``y -> matrix @ y + offset``."""

    name: str
    matrix: np.ndarray
    offset: np.ndarray

    def apply_gaussians(self, means: np.ndarray, covs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Transformed state Gaussians: means (S, 6) -> A mu + b, covs (S, 6, 6) -> A Σ A^T."""
        a = np.asarray(self.matrix, float)
        return means @ a.T + self.offset[None, :], np.einsum("ij,sjk,lk->sil", a, covs, a)


def shift_tone(name: str, shift: float, dims: tuple[str, ...] = ("D", "V", "A")) -> Tone:
    """A tone that adds ``shift`` to the named parameter dimensions."""
    off = np.zeros(6)
    for d in dims:
        off[PARAM_INDEX[d]] = shift
    return Tone(name=name, matrix=np.eye(6), offset=off)


def default_tones(shift: float = 0.75) -> tuple[Tone, ...]:
    """(calm, neutral, energetic): D, V and A shifted by −shift, 0 and +shift."""
    return (shift_tone("calm", -shift), shift_tone("neutral", 0.0), shift_tone("energetic", shift))


def fit_tone(name: str, neutral: np.ndarray, toned: np.ndarray, diagonal: bool = False) -> Tone:
    """The affine map taking N(mean, cov) of ``neutral`` (n, 6) parameters to that of ``toned``.

    ``A = Σ_t^{1/2} Σ_n^{-1/2}`` and ``b = μ_t − A μ_n`` (``diagonal``: per-dimension std ratio).
    """
    neutral, toned = np.asarray(neutral, float), np.asarray(toned, float)
    if len(neutral) < 7 or len(toned) < 7:
        raise GestureSimError("fitting a tone needs at least 7 segments of each kind")
    mn, mt = neutral.mean(0), toned.mean(0)
    if diagonal:
        a = np.diag(toned.std(0) / np.maximum(neutral.std(0), 1e-9))
    else:
        cn = np.cov(neutral.T) + 1e-6 * np.eye(6)
        ct = np.cov(toned.T) + 1e-6 * np.eye(6)
        a = np.real(sqrtm(ct)) @ np.linalg.inv(np.real(sqrtm(cn)))
    return Tone(name=name, matrix=a, offset=mt - a @ mn)


#: Bandai Namco style names (Kobayashi et al. 2023) read as the paper's calm / energetic tones.
CALM_STYLES = ("tired", "sad", "old", "not-confident")
ENERGETIC_STYLES = ("active", "angry", "happy", "proud")
NEUTRAL_STYLES = ("normal",)


def style_of(name: str) -> str:
    """The style word in a clip name such as ``dataset-1_bow_active_001`` ('' if none)."""
    for part in name.lower().split("_"):
        if part in CALM_STYLES + ENERGETIC_STYLES + NEUTRAL_STYLES:
            return part
    return ""


def fitted_tones(params: np.ndarray, styles: tuple[str, ...] | list[str],
                 shift: float = 0.75) -> tuple[Tone, ...]:
    """(calm, neutral, energetic) fitted from the same gestures performed in several styles
    (Gesture Controllers §8.2 fits its tones from styled data): the shift of the mean kinematic
    parameters ``params`` (n, 6) from the segments of neutral-style clips to those of calm-style
    and energetic-style clips (``styles``: the style word of each segment's clip,
    :func:`style_of`). A shift, not the full affine map of :func:`fit_tone`: the tones are
    applied to the co-speech states, whose parameters lie elsewhere than the emblems', and a
    fitted scale would move them by the emblems' offset (measured: the diagonal fit shrank the
    co-speech extent under *both* tones). Falls back to :func:`default_tones` with ``shift``
    when fewer than 7 segments of a kind exist."""
    styles = list(styles)
    p = np.asarray(params, dtype=float)
    pick = lambda names: p[[i for i, s in enumerate(styles) if s in names]]  # noqa: E731
    neutral, calm, energetic = pick(NEUTRAL_STYLES), pick(CALM_STYLES), pick(ENERGETIC_STYLES)
    if min(len(neutral), len(calm), len(energetic)) < 7:
        return default_tones(shift)
    eye = np.eye(6)
    return (Tone("calm", eye, calm.mean(0) - neutral.mean(0)), shift_tone("neutral", 0.0),
            Tone("energetic", eye, energetic.mean(0) - neutral.mean(0)))


def clip_style(style: float) -> float:
    """A user style setting clipped to [0, 1] (0 calm, 0.5 neutral, 1 energetic)."""
    return min(max(float(style), 0.0), 1.0)


def dial_from_style(style: float, offset: float = 0.0) -> float:
    """The controller's style dial in [-1, 1] for a user setting ``style`` in [0, 1]
    (``2 style - 1``: 0.5 gives 0), moved by ``offset`` (dial units, e.g. from the voice) and
    clipped to [-1, 1]."""
    return min(max(2.0 * float(style) - 1.0 + offset, -1.0), 1.0)


def dial_weights(dial: float, tone_names: tuple[str, ...]) -> np.ndarray:
    """Convex weights over ``tone_names`` for a style dial in [-1, 1].

    With the tones (calm, neutral, energetic) present: s < 0 blends calm (−s) and neutral (1+s),
    s > 0 blends neutral (1−s) and energetic (s). With one tone, its weight is 1. Otherwise the
    dial runs linearly along the tone list from the first (−1) to the last (+1).
    """
    if not -1.0 <= dial <= 1.0:
        raise GestureSimError(f"style dial must be in [-1, 1], got {dial}")
    m = len(tone_names)
    w = np.zeros(m)
    if m == 1:
        w[0] = 1.0
        return w
    names = list(tone_names)
    if {"calm", "neutral", "energetic"} <= set(names):
        c, n, e = names.index("calm"), names.index("neutral"), names.index("energetic")
        if dial < 0:
            w[c], w[n] = -dial, 1 + dial
        else:
            w[n], w[e] = 1 - dial, dial
        return w
    pos = (dial + 1) / 2 * (m - 1)
    lo = int(np.floor(pos))
    hi = min(lo + 1, m - 1)
    w[lo] += 1 - (pos - lo)
    w[hi] += pos - lo
    return w
