"""Prosody clusters: a Gaussian mixture on the 3-D per-step prosody features (digest §3, §5.2).

Features are ``x = (log-F0 (normalised) or NaN when unvoiced, intensity (normalised),
log syllable length)``. The paper treats the F0 of an unvoiced syllable as a uniformly
distributed random variable; a uniform density over F0 is the same for every component, so
the responsibilities of an unvoiced row are those of the **marginal** Gaussians over the two
other dimensions. The mixture is fitted by **EM with missing data** on all rows (voiced and
unvoiced): in the E-step unvoiced rows use the marginal likelihood; in the M-step their F0 is
replaced by its conditional expectation given the observed dimensions, and the conditional
variance is added to the covariance, as in standard EM for Gaussians with missing values.
The CRF sees the memberships P(x ∈ C_k) (n, K).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Dimension of the prosody features and index of F0 among them.
N_FEATURES = 3
F0 = 0
_LOG2PI = np.log(2.0 * np.pi)


def _gauss_logpdf(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """log N(x; mean, cov) for rows x (n, d); cov (d, d) positive definite."""
    d = x.shape[1]
    if d == 0:
        return np.zeros(len(x))
    chol = np.linalg.cholesky(cov)
    z = np.linalg.solve(chol, (x - mean).T)
    return -0.5 * (np.sum(z * z, axis=0) + d * _LOG2PI) - np.sum(np.log(np.diag(chol)))


@dataclass
class ProsodyClusters:
    """A K-component, full-covariance Gaussian mixture over the prosody features.

    Attributes:
        weights: (K,) mixing weights.
        means: (K, 3) component means.
        covariances: (K, 3, 3) component covariances.
    """

    weights: np.ndarray
    means: np.ndarray
    covariances: np.ndarray

    @property
    def n_clusters(self) -> int:
        return int(self.weights.shape[0])

    def component_log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """``log(w_k) + log N(x; μ_k, Σ_k)`` (n, K), F0 marginalised on rows where it is NaN."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        out = np.empty((len(x), self.n_clusters))
        unvoiced = np.isnan(x[:, F0])
        obs = [d for d in range(N_FEATURES) if d != F0]
        for k in range(self.n_clusters):
            lw = np.log(self.weights[k])
            if np.any(~unvoiced):
                out[~unvoiced, k] = lw + _gauss_logpdf(
                    x[~unvoiced], self.means[k], self.covariances[k])
            if np.any(unvoiced):
                out[unvoiced, k] = lw + _gauss_logpdf(
                    x[unvoiced][:, obs], self.means[k, obs],
                    self.covariances[k][np.ix_(obs, obs)])
        return out

    def memberships(self, x: np.ndarray) -> np.ndarray:
        """Posterior memberships P(x ∈ C_k) (n, K) of feature rows x (n, 3); rows sum to 1."""
        ll = self.component_log_likelihood(x)
        ll -= ll.max(axis=1, keepdims=True)
        p = np.exp(ll)
        return p / p.sum(axis=1, keepdims=True)

    def membership(self, x: np.ndarray) -> np.ndarray:
        """Membership (K,) of one feature vector (3,) — the fast run-time path.

        Uses precisions and log-normalisers cached on first use (full and F0-marginal).
        """
        cache = self.__dict__.get("_cache")
        if cache is None:
            cache = self._build_cache()
        x = np.asarray(x, dtype=float)
        if np.isnan(x[F0]):
            prec, const, mean, idx = cache["marg"]
            d = x[idx] - mean                                     # (K, 2)
        else:
            prec, const, mean, _ = cache["full"]
            d = x - mean                                          # (K, 3)
        ll = const - 0.5 * np.einsum("ki,kij,kj->k", d, prec, d)
        ll -= ll.max()
        p = np.exp(ll)
        return p / p.sum()

    def _build_cache(self) -> dict:
        obs = np.array([d for d in range(N_FEATURES) if d != F0])
        out = {}
        for name, idx in (("full", np.arange(N_FEATURES)), ("marg", obs)):
            covs = self.covariances[:, idx][:, :, idx]
            prec = np.linalg.inv(covs)
            _, logdet = np.linalg.slogdet(covs)
            const = np.log(self.weights) - 0.5 * (logdet + len(idx) * _LOG2PI)
            out[name] = (prec, const, self.means[:, idx], idx)
        self.__dict__["_cache"] = out
        return out

    def log_likelihood(self, x: np.ndarray) -> float:
        """Mean log-likelihood per row (F0 marginalised where unvoiced)."""
        ll = self.component_log_likelihood(x)
        m = ll.max(axis=1, keepdims=True)
        return float(np.mean(m[:, 0] + np.log(np.exp(ll - m).sum(axis=1))))

    def to_arrays(self, prefix: str = "gmm_") -> dict[str, np.ndarray]:
        return {f"{prefix}weights": self.weights, f"{prefix}means": self.means,
                f"{prefix}covariances": self.covariances}

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str = "gmm_") -> ProsodyClusters:
        return cls(*(np.asarray(arrays[f"{prefix}{n}"], dtype=float)
                     for n in ("weights", "means", "covariances")))


def _em_once(
    x: np.ndarray, k: int, rng: np.random.Generator, max_iter: int, tol: float, reg: float,
) -> tuple[ProsodyClusters, float]:
    n = len(x)
    unvoiced = np.isnan(x[:, F0])
    obs = [d for d in range(N_FEATURES) if d != F0]
    filled = x.copy()
    voiced_f0 = x[~unvoiced, F0]
    filled[unvoiced, F0] = voiced_f0.mean() if len(voiced_f0) else 0.0
    # k-means++-style seeding on the filled data, then EM.
    centres = [filled[rng.integers(n)]]
    for _ in range(1, k):
        d2 = np.min([np.sum((filled - c) ** 2, axis=1) for c in centres], axis=0)
        total = d2.sum()
        pick = rng.choice(n, p=d2 / total) if total > 0 else rng.integers(n)
        centres.append(filled[pick])
    spread = np.cov(filled.T) + reg * np.eye(N_FEATURES)
    model = ProsodyClusters(np.full(k, 1.0 / k), np.array(centres), np.repeat(spread[None], k, 0))
    prev = -np.inf
    ll = prev
    for _ in range(max_iter):
        comp = model.component_log_likelihood(x)
        m = comp.max(axis=1, keepdims=True)
        ll = float(np.mean(m[:, 0] + np.log(np.exp(comp - m).sum(axis=1))))
        resp = np.exp(comp - m)
        resp /= resp.sum(axis=1, keepdims=True)
        if ll - prev < tol * max(1.0, abs(ll)):
            break
        prev = ll
        nk = resp.sum(axis=0) + 1e-10
        weights = nk / n
        means = np.empty((k, N_FEATURES))
        covs = np.empty((k, N_FEATURES, N_FEATURES))
        for j in range(k):
            mu, cov = model.means[j], model.covariances[j]
            xj = filled.copy()
            extra_var = np.zeros(n)
            if np.any(unvoiced):
                # E[f0 | x_obs] and Var[f0 | x_obs] under component j.
                c_oo = cov[np.ix_(obs, obs)]
                c_fo = cov[F0, obs]
                gain = np.linalg.solve(c_oo, c_fo)
                xo = x[unvoiced][:, obs]
                xj[unvoiced, F0] = mu[F0] + (xo - mu[obs]) @ gain
                extra_var[unvoiced] = cov[F0, F0] - c_fo @ gain
            r = resp[:, j]
            mean_j = r @ xj / nk[j]
            diff = xj - mean_j
            cov_j = (r[:, None] * diff).T @ diff / nk[j]
            cov_j[F0, F0] += r @ extra_var / nk[j]
            means[j] = mean_j
            covs[j] = cov_j + reg * np.eye(N_FEATURES)
        model = ProsodyClusters(weights, means, covs)
    return model, ll


def fit_clusters(
    x: np.ndarray, n_clusters: int = 8, n_init: int = 3, seed: int = 0, max_iter: int = 200,
    tol: float = 1e-6, reg: float = 1e-3,
) -> ProsodyClusters:
    """Fit the mixture by EM with missing F0 (several seeds, best likelihood kept).

    Args:
        x: (n, 3) prosody features; F0 NaN where unvoiced. Rows with other NaNs are an error.
        n_clusters: K.
        n_init: restarts from different seeds.
        reg: added to each covariance's diagonal (identical rows, e.g. silence, would otherwise
            collapse a component onto a point).
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != N_FEATURES:
        raise ValueError(f"prosody features must be (n, 3), got {x.shape}")
    if np.any(np.isnan(np.delete(x, F0, axis=1))):
        raise ValueError("only the F0 column may be NaN")
    if len(x) < n_clusters:
        raise ValueError(f"{len(x)} rows cannot support {n_clusters} clusters")
    rng = np.random.default_rng(seed)
    best, best_ll = None, -np.inf
    for _ in range(n_init):
        model, ll = _em_once(x, n_clusters, rng, max_iter, tol, reg)
        if ll > best_ll:
            best, best_ll = model, ll
    assert best is not None
    return best
