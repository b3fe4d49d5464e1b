"""Costs of the control layer (Gesture Controllers §7.1, §8): kinematic fit and smoothness.

Per frame the controller pays the *fit* cost ``w_fit * b . eta_a`` of the playing segment ``a``
under the belief ``b``, and at every switch the *smoothness* cost ``w_smooth * S``:

* ``eta_a(i) = E_{y ~ N(mu_i, Sigma_i)} ||y - y_a||`` (Euclidean norm in the 6-D normalised
  kinematic parameter space) — the expected mismatch of segment ``a`` if the hidden state is ``i``.
  There is no closed form; it is computed by quasi-Monte Carlo with a fixed set of scrambled Sobol
  points (4096 by default), vectorised over all segments and states with one matrix product per
  state. :func:`expected_mismatch` also returns the plain Monte Carlo standard error
  ``std / sqrt(n)`` of every entry, an upper estimate of the error (QMC does better; the measured
  error against 2^20 samples is ~1e-3 relative, see tests/control/test_costs.py).
* ``S(a, k -> a')``: D_sp at the last frame (k = K), D_in (+ an optional extra penalty) at an
  interruption frame k < K, infinite for a' = a (restarting the same segment is not a candidate)
  and at interruption frames that coincide with the last frame.

The weight between fit and smoothness is a setting (:class:`ControlSettings`): the paper sums
both unweighted (``w_fit = w_smooth = 1``), which is the default. Since the fit is paid every
frame (~18 frames per segment at 30 fps) and the smoothness once per switch, ``w_smooth``
around 1-5 trades kinematic fit for smoother successions.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.special import ndtri
from scipy.stats import qmc

from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.errors import GestureSimError


@dataclass(frozen=True)
class ControlSettings:
    """Settings of the control layer (documented defaults; all costs are dimensionless).

    Attributes:
        discount: λ, discount per frame (0 < λ < 1); 0.95 at 30 fps halves a cost's weight
            in ~0.45 s.
        fit_weight: w_fit, multiplies eta (per frame).
        smooth_weight: w_smooth, multiplies D_sp / D_in (per switch).
        extra_interrupt_penalty: added to D_in on top of the library's own penalty.
        semantic_cost: C_sem, paid per decision while a semantic label is pending and the
            chosen segment does not match it (0 for matching segments).
        semantic_entry_fraction: a semantic gesture may be entered mid-clip only before this
            fraction of its length (f_sem < fraction * length).
        tolerance: value iteration stops when the value function is provably within this
            (absolute, cost units) of the fixed point: λ/(1-λ) * Bellman residual <= tolerance.
        n_samples: quasi-Monte Carlo points for eta (rounded up to a power of two).
        seed: seed of the scrambled Sobol sequence.
    """

    discount: float = 0.95
    fit_weight: float = 1.0
    smooth_weight: float = 1.0
    extra_interrupt_penalty: float = 0.0
    semantic_cost: float = 1000.0
    semantic_entry_fraction: float = 0.5
    tolerance: float = 1e-6
    n_samples: int = 4096
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 < self.discount < 1.0:
            raise GestureSimError(f"discount must be in (0, 1), got {self.discount}")
        if self.fit_weight < 0 or self.smooth_weight < 0:
            raise GestureSimError("cost weights must be non-negative")
        if not 0.0 < self.semantic_entry_fraction <= 1.0:
            raise GestureSimError("semantic_entry_fraction must be in (0, 1]")

    def to_dict(self) -> dict:
        return asdict(self)


def normal_samples(n_samples: int, dim: int = 6, seed: int = 0) -> np.ndarray:
    """(2^m, dim) standard-normal quasi-random points (scrambled Sobol, inverse CDF), 2^m >= n."""
    m = max(1, int(np.ceil(np.log2(max(n_samples, 2)))))
    u = qmc.Sobol(d=dim, scramble=True, seed=seed).random_base2(m)
    return ndtri(np.clip(u, 1e-12, 1 - 1e-12))


def _sqrt_psd(cov: np.ndarray) -> np.ndarray:
    """A matrix L with L L^T = cov for a symmetric positive semi-definite (6, 6) cov."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    if w.min() < -1e-8 * max(1.0, w.max()):
        raise GestureSimError("a state covariance is not positive semi-definite")
    return v * np.sqrt(np.maximum(w, 0.0))


def expected_mismatch(
    params: np.ndarray, means: np.ndarray, covs: np.ndarray, n_samples: int = 4096, seed: int = 0,
    samples: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """eta[a, i] = E_{y ~ N(means[i], covs[i])} ||y - params[a]|| and its standard error.

    Args:
        params: (n, d) segment parameters y_a.
        means: (S, d) state means; covs: (S, d, d) state covariances.
        n_samples: quasi-random points (rounded up to a power of two).
        seed: Sobol scrambling seed.
        samples: optional (m, d) standard-normal points to use instead (e.g. plain Monte Carlo).

    Returns:
        eta (n, S) and stderr (n, S), the plain-MC standard error ``std / sqrt(m)`` per entry.
    """
    params = np.asarray(params, dtype=float)
    means = np.asarray(means, dtype=float)
    d = params.shape[1]
    z = normal_samples(n_samples, d, seed) if samples is None else np.asarray(samples, float)
    m = len(z)
    n, s = len(params), len(means)
    eta = np.empty((n, s))
    err = np.empty((n, s))
    for i in range(s):
        y = z @ _sqrt_psd(covs[i]).T                      # (m, d) zero-mean draws of state i
        off = means[i][None, :] - params                  # (n, d): mu_i - y_a
        yy = (y * y).sum(1)
        for lo in range(0, n, 512):
            o = off[lo:lo + 512]
            sq = (o * o).sum(1)[:, None] + 2.0 * o @ y.T + yy[None, :]
            dist = np.sqrt(np.maximum(sq, 0.0))            # (chunk, m)
            eta[lo:lo + 512, i] = dist.mean(axis=1)
            err[lo:lo + 512, i] = dist.std(axis=1) / np.sqrt(m)
    return eta, err


def successor_costs(lib: ControlLibrary, settings: ControlSettings) -> np.ndarray:
    """(n, K + 1, n) weighted switch costs ``w_smooth * S(a, k -> a')`` at every decision point.

    ``[:, k < K, :]`` = D_in (+ extra penalty) at interruption frame k; ``[:, K, :]`` = D_sp at
    the last frame; ``+inf`` where the switch is not allowed (a' = a, or an interruption frame
    that coincides with the last frame).
    """
    n, k = lib.n_segments, lib.n_interrupts
    out = np.empty((n, k + 1, n))
    out[:, :k, :] = lib.d_in + settings.extra_interrupt_penalty
    out[:, k, :] = lib.d_sp
    out *= settings.smooth_weight
    out[np.arange(n), :, np.arange(n)] = np.inf
    out[:, :k, :][~lib.valid_interrupts()] = np.inf
    return out


def frame_distances(lib: ControlLibrary, src: np.ndarray, dst: int, max_frame: int) -> np.ndarray:
    """Pose-distance cost of jumping from given frames into frames ``0..max_frame-1`` of ``dst``.

    Args:
        src: (m, d) pose features of the frames jumped from.
        dst: target segment index.
        max_frame: number of candidate entry frames of ``dst`` (>= 1).

    Returns:
        (m, max_frame): ``pose_scale * ||src - feat(dst, f)|| + interrupt_penalty``.
    """
    feat = lib.features(dst)[:max_frame]
    diff = src[:, None, :] - feat[None]
    return lib.pose_scale * np.linalg.norm(diff, axis=-1) + lib.interrupt_penalty
