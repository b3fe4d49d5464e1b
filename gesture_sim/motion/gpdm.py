"""A compact Gaussian Process Dynamical Model (GPDM) of pose frames and latent transitions.

Chiu (2014, Ch. 5) synthesises the motion between two library gestures on a learnt gesture
manifold instead of blending the two segments in joint space. This module is that manifold: a
GPDM (Wang, Fleet & Hertzmann 2006/2008) with the balanced weighting of Urtasun et al. (2006),
and a transition generator on it: the switch ramp's path with ``--transition gpdm``
(:class:`GPDMPath`, :func:`gpdm_for`).

Model (shapes: N training frames in R runs of consecutive frames, D joints, q PCA components,
d latent dimensions):

* Observations. ``Y`` (N, D) joint angles (rad, m for slides) are centred by ``mean`` (D,),
  projected on the first q principal directions ``basis`` (D, q) and divided by one scalar
  ``scale`` (rad): ``Z = (Y − mean) basis / scale``, (N, q), dimensionless.
* Latent points ``X`` (N, d), initialised by PCA of ``Z`` (first d scores, unit variance).
* Mapping GP, X → Z, shared over the q output columns::

      K_Y(x, x') = a_y exp(−g_y/2 |x − x'|²) + s_y δ(x, x')
      L_Y = q/2 ln|K_Y| + ½ tr(K_Y⁻¹ Z Zᵀ)

* Dynamics GP, x_{t−1} → x_t inside each run (inputs U = X_in, outputs V = X_out, N − R rows),
  the linear + RBF kernel of Wang et al.::

      K_X(u, u') = a_x exp(−g_x/2 |u − u'|²) + c_x uᵀu' + s_x δ(u, u')
      L_X = d/2 ln|K_X| + ½ tr(K_X⁻¹ V Vᵀ) + ½ Σ_runs |x_first|²

* MAP estimate: minimise ``L = L_Y + λ L_X + P(θ)`` over X and the log hyperparameters
  θ = ln(a_y, g_y, s_y, a_x, g_x, c_x, s_x) by L-BFGS (analytic gradients), with
  λ = q / d (balanced GPDM), weak Gaussian priors P on θ around sensible values and bounds
  on θ (:data:`THETA_BOUNDS`; noise variances s_y ≥ 1e-3, s_x ≥ 1e-4).
  Deterministic for a seed (the seed only picks the training runs).

Transition (:meth:`GPDM.transition`): the end pose y_A of segment A and the start pose y_B of
segment B are mapped to latent points x_A, x_B (nearest training latent, refined by the GP
likelihood of the pose); the n in-between latent points x_1..x_n minimise, with x_0 = x_A and
x_{n+1} = x_B fixed, the negative log-likelihood of the path under the dynamics GP plus
Chiu's manifold term (the mapping GP's predictive variance, §5.3)::

      E = β Σ_{t=1}^{n+1} [ |x_t − μ_X(x_{t−1})|² / (2σ_X²(x_{t−1})) + d/2 ln σ_X²(x_{t−1}) ]
          + w Σ_{t=1}^{n} σ_Y²(x_t) / a_y  +  λ Σ_{t=0}^{n} |x_{t+1} − x_t|²

initialised by the straight line (β = ``dynamics_weight``, default 1; w = ``manifold_weight``,
default 1; λ = ``spread_weight``, default 0). β = 0, λ > 0 is Chiu's own objective
E(x) = var_GP(x) + λ‖x_{1:n−1} − x_{2:n}‖² (§5.3); ``optimise=False`` keeps the straight line.
The poses are the mapping GP's mean, plus the residuals y_A − μ_Y(x_A) and y_B − μ_Y(x_B)
blended by a smoothstep so that both ends are met exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.linalg.lapack import dpotri
from scipy.optimize import minimize as _scipy_minimize
from threadpoolctl import threadpool_limits


def _minimize(*args, **kwargs):
    """``scipy.optimize.minimize`` on one BLAS thread: the matrices are small (N <= ~600), so
    threads only contend (about 50x slower on a loaded 2-core machine)."""
    with threadpool_limits(1):
        return _scipy_minimize(*args, **kwargs)

#: Names of the log hyperparameters in :attr:`GPDM.theta`.
THETA_NAMES = ("a_y", "g_y", "s_y", "a_x", "g_x", "c_x", "s_x")
#: Prior centres (ln) and width of the weak Gaussian priors on θ.
_THETA0 = np.log([1.0, 1.0, 1e-2, 1.0, 1.0, 0.1, 1e-3])
_THETA_SD = 3.0
#: Bounds of θ (ln): noise floors keep the MAP from collapsing onto the training frames.
THETA_BOUNDS = tuple(zip(np.log([1e-2, 1e-2, 1e-3, 1e-2, 1e-2, 1e-4, 1e-4]),
                         np.log([1e2, 1e2, 1.0, 1e2, 1e2, 1e1, 1.0]), strict=True))
FORMAT = 1


def _sqdist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.maximum(d, 0.0)


def _gp_term(K: np.ndarray, T: np.ndarray):
    """(q/2 ln|K| + ½ tr(K⁻¹TTᵀ), dL/dK, K⁻¹T, K⁻¹) for targets T (n, q)."""
    n, q = T.shape
    c = cho_factor(K, lower=True)
    Kinv, info = dpotri(c[0], lower=1)
    if info:
        raise np.linalg.LinAlgError("kernel matrix inversion failed")
    Kinv = np.tril(Kinv) + np.tril(Kinv, -1).T
    A = Kinv @ T
    logdet = 2.0 * np.log(np.diag(c[0])).sum()
    val = 0.5 * q * logdet + 0.5 * float((T * A).sum())
    G = 0.5 * (q * Kinv - A @ A.T)
    return val, G, A, Kinv


def _rbf_input_grad(G: np.ndarray, R: np.ndarray, X: np.ndarray, g: float) -> np.ndarray:
    """dL/dX of Σ G∘R where R_ij = a exp(−g/2 |x_i − x_j|²), G symmetric."""
    M = G * R
    return -2.0 * g * (M.sum(1)[:, None] * X - M @ X)


def _runs_index(runs: np.ndarray):
    ins, outs, firsts = [], [], []
    for s, e in runs:
        ins.extend(range(s, e - 1))
        outs.extend(range(s + 1, e))
        firsts.append(s)
    return np.array(ins, int), np.array(outs, int), np.array(firsts, int)


def _neg_log_posterior(X: np.ndarray, th: np.ndarray, Z: np.ndarray, idx, lam: float):
    """L and its gradients (dX, dθ)."""
    ins, outs, firsts = idx
    N, d = X.shape
    a_y, g_y, s_y, a_x, g_x, c_x, s_x = np.exp(th)
    gth = np.zeros(7)
    # Mapping GP.
    r2 = _sqdist(X, X)
    R = a_y * np.exp(-0.5 * g_y * r2)
    Ly, G, _, Kinv = _gp_term(R + s_y * np.eye(N), Z)
    gX = _rbf_input_grad(G, R, X, g_y)
    gth[0] = (G * R).sum()
    gth[1] = (G * R * (-0.5 * g_y * r2)).sum()
    gth[2] = s_y * np.trace(G)
    # Dynamics GP.
    U, V = X[ins], X[outs]
    r2u = _sqdist(U, U)
    Ru = a_x * np.exp(-0.5 * g_x * r2u)
    Lin = c_x * U @ U.T
    Lx, Gx, Av, _ = _gp_term(Ru + Lin + s_x * np.eye(len(U)), V)
    gU = _rbf_input_grad(Gx, Ru, U, g_x) + 2.0 * (Gx @ U) * c_x
    gth[3] = lam * (Gx * Ru).sum()
    gth[4] = lam * (Gx * Ru * (-0.5 * g_x * r2u)).sum()
    gth[5] = lam * (Gx * Lin).sum()
    gth[6] = lam * s_x * np.trace(Gx)
    Lf = 0.5 * float((X[firsts] ** 2).sum())
    np.add.at(gX, ins, lam * gU)
    np.add.at(gX, outs, lam * Av)
    np.add.at(gX, firsts, lam * X[firsts])
    # Priors.
    dev = (th - _THETA0) / _THETA_SD
    P = 0.5 * float((dev ** 2).sum())
    gth += dev / _THETA_SD
    return Ly + lam * (Lx + Lf) + P, gX, gth


def choose_runs(n_frames: int | list[int], n_runs: int, run_length: int,
                seed: int = 0) -> list[tuple[int, int, int]]:
    """Training runs ``(sequence, start, end)``: ``n_runs`` windows of ``run_length``
    consecutive frames, spread evenly over the sequences (lengths ``n_frames``) with seeded
    random offsets inside each stride."""
    lengths = [n_frames] if np.isscalar(n_frames) else list(n_frames)
    rng = np.random.default_rng(seed)
    total = sum(max(n - run_length, 0) + 1 for n in lengths if n >= run_length)
    if total <= 0:
        raise ValueError("every sequence is shorter than run_length")
    # Positions in the concatenation of the admissible start ranges.
    stride = total / n_runs
    picks = sorted({int(min(total - 1, k * stride + rng.uniform(0, max(stride - run_length, 1))))
                    for k in range(n_runs)})
    runs = []
    for p in picks:
        for si, n in enumerate(lengths):
            m = n - run_length + 1
            if n < run_length:
                continue
            if p < m:
                runs.append((si, p, p + run_length))
                break
            p -= m
    return runs


@dataclass
class GPDM:
    """A fitted GPDM (see the module docstring for the equations).

    Attributes:
        mean: (D,) pose mean (rad / m).
        basis: (D, q) orthonormal PCA directions.
        scale: scalar (rad): Z = (Y − mean) basis / scale.
        Z: (N, q) training targets.
        X: (N, d) latent points.
        runs: (R, 2) [start, end) rows of X that are consecutive frames.
        theta: (7,) log hyperparameters, :data:`THETA_NAMES`.
        info: fit information (objective, iterations, seconds, seed, ...).
    """

    mean: np.ndarray
    basis: np.ndarray
    scale: float
    Z: np.ndarray
    X: np.ndarray
    runs: np.ndarray
    theta: np.ndarray
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._prepare()

    # --- fitting -----------------------------------------------------------------------------

    @classmethod
    def fit(cls, sequences: list[np.ndarray], d: int = 3, n_components: int = 16,
            n_runs: int = 10, run_length: int = 32, seed: int = 0, max_iter: int = 200,
            balanced: bool = True) -> GPDM:
        """Fit on pose sequences (each (T_i, D), consecutive frames).

        ``n_runs`` windows of ``run_length`` consecutive frames are the training data
        (N = n_runs × run_length); ``n_components`` PCA components (≤ D) of the centred frames
        of all sequences; ``d`` latent dimensions; L-BFGS for ``max_iter`` iterations.
        """
        import time

        t0 = time.perf_counter()
        seqs = [np.asarray(s, dtype=float) for s in sequences]
        allf = np.concatenate(seqs)
        mean = allf.mean(0)
        _, sv, vt = np.linalg.svd(allf - mean, full_matrices=False)
        q = int(min(n_components, vt.shape[0]))
        basis = vt[:q].T
        picks = choose_runs([len(s) for s in seqs], n_runs, run_length, seed)
        Y = np.concatenate([seqs[si][a:b] for si, a, b in picks])
        runs, o = [], 0
        for _, a, b in picks:
            runs.append((o, o + b - a))
            o += b - a
        runs = np.array(runs, int)
        P = (Y - mean) @ basis
        scale = float(np.sqrt((P ** 2).sum(1).mean()))
        Z = P / scale
        # PCA initialisation of the latent points, unit variance along the first direction.
        Zc = Z - Z.mean(0)
        u, s, _ = np.linalg.svd(Zc, full_matrices=False)
        X0 = u[:, :d] * s[:d]
        X0 = X0 / X0[:, 0].std()
        idx = _runs_index(runs)
        lam = q / d if balanced else 1.0
        N = len(Z)
        th0 = _THETA0.copy()

        def f(v):
            X = v[:N * d].reshape(N, d)
            L, gX, gth = _neg_log_posterior(X, v[N * d:], Z, idx, lam)
            return L, np.concatenate([gX.ravel(), gth])

        bounds = [(None, None)] * (N * d) + list(THETA_BOUNDS)
        res = _minimize(f, np.concatenate([X0.ravel(), th0]), jac=True, method="L-BFGS-B",
                       bounds=bounds, options={"maxiter": int(max_iter)})
        X = res.x[:N * d].reshape(N, d)
        info = {"format": FORMAT, "objective": float(res.fun), "iterations": int(res.nit),
                "seconds": time.perf_counter() - t0, "seed": int(seed), "d": int(d),
                "n_components": q, "N": int(N), "lambda": float(lam),
                "explained_variance": float((sv[:q] ** 2).sum() / (sv ** 2).sum()),
                "runs": [[int(si), int(a), int(b)] for si, a, b in picks]}
        return cls(mean=mean, basis=basis, scale=scale, Z=Z, X=X, runs=runs,
                   theta=res.x[N * d:].copy(), info=info)

    # --- storage -----------------------------------------------------------------------------

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (arrays plus the info as JSON)."""
        import json

        np.savez(path, mean=self.mean, basis=self.basis, scale=np.array(self.scale), Z=self.Z,
                 X=self.X, runs=self.runs, theta=self.theta,
                 info=np.array(json.dumps(self.info)))

    @classmethod
    def load(cls, path: str | Path) -> GPDM:
        import json

        with np.load(path, allow_pickle=False) as z:
            return cls(mean=z["mean"], basis=z["basis"], scale=float(z["scale"]), Z=z["Z"],
                       X=z["X"], runs=z["runs"], theta=z["theta"],
                       info=json.loads(str(z["info"])))

    # --- prediction --------------------------------------------------------------------------

    def _prepare(self) -> None:
        self.X = np.asarray(self.X, float)
        self.Z = np.asarray(self.Z, float)
        a_y, g_y, s_y, a_x, g_x, c_x, s_x = np.exp(self.theta)
        self._hy = (a_y, g_y, s_y)
        self._hx = (a_x, g_x, c_x, s_x)
        N = len(self.X)
        Ky = a_y * np.exp(-0.5 * g_y * _sqdist(self.X, self.X)) + s_y * np.eye(N)
        self._Kyinv = cho_solve(cho_factor(Ky, lower=True), np.eye(N))
        self._Ay = self._Kyinv @ self.Z
        ins, outs, _ = _runs_index(self.runs)
        self._U, self._V = self.X[ins], self.X[outs]
        U = self._U
        Kx = a_x * np.exp(-0.5 * g_x * _sqdist(U, U)) + c_x * U @ U.T + s_x * np.eye(len(U))
        self._Kxinv = cho_solve(cho_factor(Kx, lower=True), np.eye(len(U)))
        self._Ax = self._Kxinv @ self._V

    @property
    def d(self) -> int:
        return int(self.X.shape[1])

    def to_pose(self, Z: np.ndarray) -> np.ndarray:
        """Poses (M, D) of PCA coordinates Z (M, q)."""
        return self.mean + (np.atleast_2d(Z) * self.scale) @ self.basis.T

    def to_z(self, Y: np.ndarray) -> np.ndarray:
        """PCA coordinates (M, q) of poses Y (M, D)."""
        return ((np.atleast_2d(Y) - self.mean) @ self.basis) / self.scale

    def map_mean(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mapping GP at latent points X (M, d): mean Z (M, q) and variance (M,)."""
        a, g, s = self._hy
        k = a * np.exp(-0.5 * g * _sqdist(np.atleast_2d(X), self.X))
        var = a + s - np.einsum("ij,jk,ik->i", k, self._Kyinv, k)
        return k @ self._Ay, np.maximum(var, 1e-12)

    def pose(self, X: np.ndarray) -> np.ndarray:
        """Mean poses (M, D) at latent points X (M, d)."""
        return self.to_pose(self.map_mean(X)[0])

    def dynamics(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Dynamics GP: mean next latent (M, d) and variance (M,) from X (M, d)."""
        a, g, c, s = self._hx
        X = np.atleast_2d(X)
        k = a * np.exp(-0.5 * g * _sqdist(X, self._U)) + c * X @ self._U.T
        var = a + c * (X * X).sum(1) + s - np.einsum("ij,jk,ik->i", k, self._Kxinv, k)
        return k @ self._Ax, np.maximum(var, 1e-12)

    def latent_of(self, y: np.ndarray) -> np.ndarray:
        """Latent point (d,) of one pose y (D,): nearest training latent in Z, refined by
        minimising the mapping GP's negative log-likelihood of the pose."""
        z = self.to_z(y)[0]
        x0 = self.X[np.argmin(((self.Z - z) ** 2).sum(1))]
        q = self.Z.shape[1]

        def f(x):
            m, v = self.map_mean(x[None])
            return float(((z - m[0]) ** 2).sum() / (2 * v[0]) + 0.5 * q * np.log(v[0]))

        res = _minimize(f, x0, method="L-BFGS-B", options={"maxiter": 50})
        return res.x if res.fun <= f(x0) else x0

    def _path_energy(self, flat: np.ndarray, xa: np.ndarray, xb: np.ndarray, w: float,
                     dyn: float = 1.0, spread: float = 0.0):
        """E of the module docstring and its gradient for inner points ``flat`` (n·d,):
        ``dyn`` × dynamics term + ``w`` × manifold term + ``spread`` × Σ|x_{t+1} − x_t|²."""
        d = self.d
        inner = flat.reshape(-1, d)
        P = np.vstack([xa, inner, xb])
        u, v = P[:-1], P[1:]
        a, g, c, _ = self._hx
        k_rbf = a * np.exp(-0.5 * g * _sqdist(u, self._U))
        k = k_rbf + c * u @ self._U.T
        mu = k @ self._Ax
        Kk = k @ self._Kxinv
        var = np.maximum(a + c * (u * u).sum(1) + self._hx[3] - (Kk * k).sum(1), 1e-12)
        e = v - mu
        e2 = (e * e).sum(1)
        E = dyn * float((e2 / (2 * var) + 0.5 * d * np.log(var)).sum())
        gP = np.zeros_like(P)
        gP[1:] += dyn * e / var[:, None]
        # J_t = dk/du (N', d) for each step: k_rbf_j (−g)(u − U_j) + c U_j.
        coef = 0.5 * d / var - e2 / (2 * var ** 2)
        for t in range(len(u)):
            J = (-g * k_rbf[t])[:, None] * (u[t] - self._U) + c * self._U
            dmu_e = J.T @ (self._Ax @ (e[t] / var[t]))
            dvar = 2 * c * u[t] - 2 * J.T @ Kk[t]
            gP[t] += dyn * (-dmu_e + coef[t] * dvar)
        if spread > 0:
            step = np.diff(P, axis=0)
            E += spread * float((step * step).sum())
            gP[:-1] -= 2 * spread * step
            gP[1:] += 2 * spread * step
        if w > 0:
            ay, gy, _ = self._hy
            ky = ay * np.exp(-0.5 * gy * _sqdist(inner, self.X))
            Kyk = ky @ self._Kyinv
            E += w * float((ay - (Kyk * ky).sum(1)).sum()) / ay
            for t in range(len(inner)):
                J = (-gy * ky[t])[:, None] * (inner[t] - self.X)
                gP[t + 1] += w * (-2 * J.T @ Kyk[t]) / ay
        return E, gP[1:-1].ravel()

    def latent_path(self, xa: np.ndarray, xb: np.ndarray, n_frames: int,
                    manifold_weight: float = 1.0, dynamics_weight: float = 1.0,
                    spread_weight: float = 0.0, max_iter: int = 200) -> np.ndarray:
        """The n in-between latent points (n, d) between fixed ends xa, xb (d,), minimising
        the path energy (``dynamics_weight=0, spread_weight>0``: Chiu's own E(x), §5.3)."""
        s = np.arange(1, n_frames + 1)[:, None] / (n_frames + 1)
        x0 = (1 - s) * xa + s * xb
        res = _minimize(self._path_energy, x0.ravel(),
                       args=(xa, xb, manifold_weight, dynamics_weight, spread_weight),
                       jac=True, method="L-BFGS-B", options={"maxiter": int(max_iter)})
        return res.x.reshape(n_frames, self.d)

    def transition(self, y_a: np.ndarray, y_b: np.ndarray, n_frames: int,
                   manifold_weight: float = 1.0, optimise: bool = True,
                   dynamics_weight: float = 1.0, spread_weight: float = 0.0) -> np.ndarray:
        """The ``n_frames`` poses (n, D) between pose y_a (D,) (last of A) and y_b (D,) (first
        of B), both excluded; ``optimise=False``: the straight latent line."""
        y_a, y_b = np.asarray(y_a, float), np.asarray(y_b, float)
        xa, xb = self.latent_of(y_a), self.latent_of(y_b)
        if optimise:
            path = self.latent_path(xa, xb, n_frames, manifold_weight, dynamics_weight,
                                    spread_weight)
        else:
            s = np.arange(1, n_frames + 1)[:, None] / (n_frames + 1)
            path = (1 - s) * xa + s * xb
        poses = self.pose(path)
        ra, rb = y_a - self.pose(xa[None])[0], y_b - self.pose(xb[None])[0]
        s = np.arange(1, n_frames + 1) / (n_frames + 1)
        w = (s * s * (3 - 2 * s))[:, None]
        return poses + (1 - w) * ra + w * rb


class GPDMPath:
    """A GPDM as the switch ramp's transition path
    (:data:`~gesture_sim.control.ramp.TransitionPath`): ``path(q_from, q_to, n)`` is
    :meth:`GPDM.transition` (the dynamics GP and the manifold term; offline cost about
    0.05–0.2 s a switch on one core)."""

    def __init__(self, model: GPDM, manifold_weight: float = 1.0) -> None:
        self.model = model
        self.manifold_weight = float(manifold_weight)

    def __call__(self, q_from: np.ndarray, q_to: np.ndarray, n: int) -> np.ndarray:
        return self.model.transition(q_from, q_to, int(n), self.manifold_weight)


_FITTED: dict[str, GPDM] = {}


def gpdm_for(library, seed: int = 0) -> GPDM:
    """The GPDM of a loaded :class:`~gesture_sim.motion.library.MotionLibrary`, fitted with
    :meth:`GPDM.fit`'s defaults on its co-speech clips (clips without tags; every clip when
    none) — about 3.5 s for the shipped library — and cached per process by the library's
    fingerprint and the seed. Deterministic for a seed."""
    key = f"{getattr(library, 'fingerprint', '') or id(library)}:{int(seed)}"
    model = _FITTED.get(key)
    if model is None:
        clips = [c for c in library.clips if not c.tags] or list(library.clips)
        model = GPDM.fit([np.asarray(c.qpos, dtype=float) for c in clips], seed=seed)
        _FITTED[key] = model
    return model
