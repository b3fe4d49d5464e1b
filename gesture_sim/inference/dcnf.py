"""The Deep Conditional Neural Field of Chiu (2014, ch. 4; digest §4) over the HMM's states.

A second learned inference layer beside the remapped CRF, on the same per-step inputs and the
same targets (the kinematic HMM's fixed posterior), so the control layer can use it unchanged:

* **Inputs** (:class:`DCNFInputs`): at each step the held syllable features of
  :mod:`~gesture_sim.inference.features` (F0 z, intensity z, log length), a voicing flag, a
  silence flag, the F0 and intensity slopes (change from the previous voiced / spoken syllable;
  0 after a pause) and the K prosody-cluster memberships the CRF sees: ``D = 7 + K`` numbers,
  standardised with training statistics, over a causal window of W steps (``n, W, D``).
* **Network**: sigmoid layers ``a_l = σ([a_{l-1}, 1] w_l)`` from the flattened window to M
  sigmoid output features f (Chiu Eq. 4.2), node potentials ``u_t(i) = Σ_m θ_mi f_m + b_i``.
  Dropout (inverted, rate p, masks re-sampled every pass) on the hidden layers while training.
* **Chain**: first-order weights α (S, S) on ``(q_{t-1}, q_t)`` and second-order weights β
  (S, S, S) on ``(q_{t-1}, q_t, q_{t+1})`` (Chiu Eq. 4.1). Exact inference runs on the chain of
  state *pairs* (S² states, transitions ``(i, j) → (j, k)`` only), with the routine of
  :mod:`~gesture_sim.inference.chain`.
* **Training** (remapped, as the CRF): maximise the expected conditional log-likelihood
  ``E_target[log P(Q | X)]`` under the HMM posterior (marginals γ, summed pair ξ and triple
  marginals, all exact for the HMM's Markov posterior) minus L2, jointly over network and chain
  (gradient: target minus model expectations, back-propagated through the network with the
  dropped activations). Adam with a decaying step, deterministic per seed; the iterate with
  the best score on a validation part is kept (Chiu selects on held-out speakers).
* **Run time** (:class:`DCNFFilter`): the causal forward recursion over state pairs, one
  step at a time (the thesis decodes offline with Viterbi); the belief over ``q_t`` sums the
  pair message over ``q_{t-1}``. Cost per step: one network pass and an S³ update.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.inference.chain import forward_backward
from gesture_sim.inference.crf import window_features

#: Version of the DCNF block inside a model file; a model with another major is refused.
DCNF_FORMAT = "1.0"
#: Per-step input layout before the K memberships (see :class:`DCNFInputs`).
BASE_FEATURES = ("voiced", "f0", "intensity", "log_length", "silent", "f0_slope",
                 "intensity_slope")
N_BASE = len(BASE_FEATURES)


# --- per-step inputs ----------------------------------------------------------------------------


class DCNFInputs:
    """Causal per-step DCNF input (D = 7 + K,) from the per-step syllable features (3,).

    ``push(x, membership)`` is called once per step with the step's feature vector x (3,) (as
    :meth:`~gesture_sim.inference.features.StepInputs.at` returns it) and its cluster
    membership (K,). A new syllable is recognised by its feature vector changing; its slopes
    are its F0 (intensity) minus those of the previous voiced (spoken) syllable since the last
    pause, held with the syllable; the silence vector resets them.
    """

    def __init__(self, silence: np.ndarray) -> None:
        self.silence = np.asarray(silence, dtype=float)
        self.reset()

    def reset(self) -> None:
        self._prev = self.silence.copy()
        self._last_f0: float | None = None
        self._last_int: float | None = None
        self._slopes = np.zeros(2)

    def push(self, x: np.ndarray, membership: np.ndarray) -> np.ndarray:
        """The input (D,) of one step."""
        x = np.asarray(x, dtype=float)
        silent = bool(np.array_equal(x, self.silence, equal_nan=True))
        voiced = bool(np.isfinite(x[0]))
        if silent:
            self._last_f0 = self._last_int = None
            self._slopes[:] = 0.0
        elif not np.array_equal(x, self._prev, equal_nan=True):
            self._slopes[0] = (x[0] - self._last_f0 if voiced and self._last_f0 is not None
                               else 0.0)
            self._slopes[1] = x[1] - self._last_int if self._last_int is not None else 0.0
            if voiced:
                self._last_f0 = float(x[0])
            self._last_int = float(x[1])
        self._prev = x.copy()
        base = np.array([float(voiced), x[0] if voiced else 0.0, x[1], x[2], float(silent),
                         self._slopes[0], self._slopes[1]])
        return np.concatenate([base, np.asarray(membership, dtype=float)])


def dcnf_inputs(x: np.ndarray, memberships: np.ndarray, silence: np.ndarray) -> np.ndarray:
    """Inputs (n, D) of a whole recording through the causal :class:`DCNFInputs`.

    Args:
        x: (n, 3) per-step syllable features (F0 NaN when unvoiced or silent).
        memberships: (n, K) cluster memberships of those rows.
        silence: (3,) the silence vector of the step settings.
    """
    inp = DCNFInputs(silence)
    return np.array([inp.push(xi, mi) for xi, mi in zip(x, memberships, strict=True)]).reshape(
        len(x), N_BASE + memberships.shape[1])


def pad_input(silence: np.ndarray, pad_membership: np.ndarray) -> np.ndarray:
    """The input (D,) of a step before the stream starts (silence)."""
    return DCNFInputs(silence).push(silence, pad_membership)


# --- the model ----------------------------------------------------------------------------------


def _sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))


@dataclass
class DCNF:
    """Weights of a DCNF.

    Attributes:
        layers: network weights, layer l (in_l + 1, out_l), the last row the bias; the first
            layer's input is the flattened window (W * D), the last layer's output the M node
            features f.
        theta: (M, S) node weights; ``bias`` (S,) node bias.
        trans: (S, S) first-order chain weights α, rows = previous state.
        trans2: (S, S, S) second-order weights β on ``(q_{t-1}, q_t, q_{t+1})``, or ``None``
            for a first-order chain.
        in_mean, in_std: (D,) input standardisation (training statistics).
        window: W, steps in the causal input window (the current one and W-1 before).
        dropout: the dropout rate used in training (recorded; none at run time).
    """

    layers: list[np.ndarray]
    theta: np.ndarray
    bias: np.ndarray
    trans: np.ndarray
    trans2: np.ndarray | None
    in_mean: np.ndarray
    in_std: np.ndarray
    window: int
    dropout: float = 0.0

    @property
    def n_states(self) -> int:
        return int(self.trans.shape[0])

    @property
    def n_inputs(self) -> int:
        """D, numbers per step."""
        return int(self.in_mean.shape[0])

    @property
    def order(self) -> int:
        return 1 if self.trans2 is None else 2

    @property
    def hidden(self) -> list[int]:
        """Sizes of the layers (hidden ones, then M)."""
        return [int(w.shape[1]) for w in self.layers]

    # --- parameters as one flat vector (training, gradient checks) ---

    def parameters(self) -> list[np.ndarray]:
        out = [*self.layers, self.theta, self.bias, self.trans]
        return out + ([self.trans2] if self.trans2 is not None else [])

    def flat(self) -> np.ndarray:
        return np.concatenate([p.ravel() for p in self.parameters()])

    def with_flat(self, vec: np.ndarray) -> DCNF:
        """A copy with the parameters taken from ``vec`` (the layout of :meth:`flat`)."""
        parts, i = [], 0
        for p in self.parameters():
            parts.append(np.asarray(vec[i:i + p.size], dtype=float).reshape(p.shape).copy())
            i += p.size
        nl = len(self.layers)
        return DCNF(parts[:nl], parts[nl], parts[nl + 1], parts[nl + 2],
                    parts[nl + 3] if self.trans2 is not None else None, self.in_mean,
                    self.in_std, self.window, self.dropout)

    # --- network ---

    def standardise(self, inputs: np.ndarray) -> np.ndarray:
        """Standardised inputs, same shape as ``inputs`` (..., D)."""
        return (inputs - self.in_mean) / self.in_std

    def windows(self, inputs: np.ndarray, pad: np.ndarray) -> np.ndarray:
        """Flattened standardised causal windows (n, W * D) of inputs (n, D); pad (D,)."""
        z = self.standardise(np.asarray(inputs, dtype=float))
        zp = self.standardise(np.asarray(pad, dtype=float))
        return window_features(z, self.window, zp).reshape(len(z), -1)

    def node_features(self, a0: np.ndarray, masks: Sequence[np.ndarray] | None = None,
                      ) -> list[np.ndarray]:
        """Activations of every layer for windows a0 (n, W*D): ``[a0, a_1, ..., f]``.

        ``masks`` (one per hidden layer, (n, out_l), already divided by 1 - p) applies
        dropout; the list then holds the dropped activations.
        """
        acts = [a0]
        a = a0
        for li, w in enumerate(self.layers):
            a = _sigmoid(a @ w[:-1] + w[-1])
            if masks is not None and li < len(self.layers) - 1:
                a = a * masks[li]
            acts.append(a)
        return acts

    def unary(self, a0: np.ndarray) -> np.ndarray:
        """Node potentials (n, S) of windows a0 (n, W*D), no dropout."""
        return self.node_features(a0)[-1] @ self.theta + self.bias

    # --- chain ---

    def posteriors(self, unary: np.ndarray) -> ChainStats:
        """Exact marginals of the chain with node potentials ``unary`` (n, S)."""
        return chain_stats(unary, self.trans, self.trans2)

    def expected_log_likelihood(self, a0: np.ndarray, target: ChainStats) -> float:
        """``E_target[log P(Q | X)]`` (a sum over steps) for windows a0 (n, W*D)."""
        unary = self.unary(a0)
        return _score(target, unary, self.trans, self.trans2) - self.posteriors(unary).log_z

    def transition_matrix(self) -> np.ndarray:
        """Row-stochastic (S, S) ``∝ exp(α_ij)`` (the first-order part; a one-step prior)."""
        z = self.trans - self.trans.max(axis=1, keepdims=True)
        p = np.exp(z)
        return p / p.sum(axis=1, keepdims=True)

    def new_filter(self, pad: np.ndarray) -> DCNFFilter:
        """An online forward filter; ``pad`` (D,) is the raw input before the stream starts."""
        return DCNFFilter(self, pad)

    # --- storage ---

    def meta(self) -> dict:
        """JSON-ready description of the shapes (stored in model.json, checked on load)."""
        return {"format": DCNF_FORMAT, "window": self.window, "order": self.order,
                "layers": self.hidden, "n_inputs": self.n_inputs, "n_states": self.n_states,
                "dropout": self.dropout, "inputs": [*BASE_FEATURES, "memberships"]}

    def to_arrays(self, prefix: str = "dcnf_") -> dict[str, np.ndarray]:
        out = {f"{prefix}layer{i}": w for i, w in enumerate(self.layers)}
        out |= {f"{prefix}theta": self.theta, f"{prefix}bias": self.bias,
                f"{prefix}trans": self.trans, f"{prefix}in_mean": self.in_mean,
                f"{prefix}in_std": self.in_std}
        if self.trans2 is not None:
            out[f"{prefix}trans2"] = self.trans2
        return out

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict, prefix: str = "dcnf_") -> DCNF:
        """Rebuild from :meth:`to_arrays` + :meth:`meta`; ``ValueError`` when they disagree."""
        major = str(meta.get("format", "0")).split(".")[0]
        if major != DCNF_FORMAT.split(".")[0]:
            raise ValueError(f"DCNF format {meta.get('format')}, this version reads "
                             f"{DCNF_FORMAT}")
        try:
            layers = [np.asarray(arrays[f"{prefix}layer{i}"], dtype=float)
                      for i in range(len(meta["layers"]))]
            get = {n: np.asarray(arrays[f"{prefix}{n}"], dtype=float)
                   for n in ("theta", "bias", "trans", "in_mean", "in_std")}
            trans2 = (np.asarray(arrays[f"{prefix}trans2"], dtype=float)
                      if int(meta["order"]) == 2 else None)
        except KeyError as exc:
            raise ValueError(f"DCNF array {exc} missing") from exc
        model = cls(layers, get["theta"], get["bias"], get["trans"], trans2, get["in_mean"],
                    get["in_std"], int(meta["window"]), float(meta.get("dropout", 0.0)))
        model.check(int(meta["n_states"]), int(meta["n_inputs"]))
        return model

    def check(self, n_states: int, n_inputs: int) -> None:
        """``ValueError`` unless every array fits S = n_states and D = n_inputs."""
        s, d = n_states, n_inputs
        expect_in = self.window * d
        problems = []
        if self.in_mean.shape != (d,) or self.in_std.shape != (d,):
            problems.append(f"input statistics for {self.in_mean.shape} inputs, not {d}")
        for i, w in enumerate(self.layers):
            if w.ndim != 2 or w.shape[0] != expect_in + 1:
                problems.append(f"layer {i} has {w.shape}, expected ({expect_in + 1}, ·)")
                break
            expect_in = w.shape[1]
        if self.theta.shape != (expect_in, s) or self.bias.shape != (s,):
            problems.append(f"node weights {self.theta.shape}, expected ({expect_in}, {s})")
        if self.trans.shape != (s, s):
            problems.append(f"transitions {self.trans.shape}, expected ({s}, {s})")
        if self.trans2 is not None and self.trans2.shape != (s, s, s):
            problems.append(f"2nd-order transitions {self.trans2.shape}, expected {(s,) * 3}")
        if problems:
            raise ValueError("; ".join(problems))


# --- exact inference on first- and second-order chains -----------------------------------------


@dataclass
class ChainStats:
    """Sufficient statistics of a distribution over state paths (model or target).

    Attributes:
        log_z: log partition function (0 for a target).
        gamma: (n, S) marginals.
        xi: (S, S) summed pair marginals over t >= 1, ``[i, j]`` for ``(q_{t-1}, q_t)``.
        xi3: (S, S, S) summed triple marginals over ``(q_{t-1}, q_t, q_{t+1})``, or ``None``.
    """

    log_z: float
    gamma: np.ndarray
    xi: np.ndarray
    xi3: np.ndarray | None = None


def _pair_chain(unary: np.ndarray, trans: np.ndarray, trans2: np.ndarray,
                log_init: np.ndarray | None = None) -> ChainStats:
    """Second-order chain as a first-order chain over pairs ``(q_{t-1}, q_t)``, t = 1..n-1."""
    n, s = unary.shape
    pu = (unary[1:, None, :] + trans[None]).reshape(n - 1, s, s)
    first = unary[0] if log_init is None else unary[0] + log_init
    pu[0] += first[:, None]
    big = np.full((s, s, s, s), -np.inf)
    j = np.arange(s)
    big[:, j, j, :] = trans2                                   # [i, j, j, k] = β_ijk
    post = forward_backward(np.zeros(s * s), big.reshape(s * s, s * s), pu.reshape(n - 1, -1))
    pg = post.gamma.reshape(n - 1, s, s)
    gamma = np.empty((n, s))
    gamma[0] = pg[0].sum(axis=1)
    gamma[1:] = pg.sum(axis=1)
    x4 = post.xi_sum.reshape(s, s, s, s)
    xi3 = x4[:, j, j, :]                                       # [i, j, k]
    return ChainStats(post.log_z, gamma, pg.sum(axis=0), np.ascontiguousarray(xi3))


def chain_stats(unary: np.ndarray, trans: np.ndarray, trans2: np.ndarray | None,
                log_init: np.ndarray | None = None) -> ChainStats:
    """Exact log Z and marginals of a first- (``trans2 = None``) or second-order chain.

    Args:
        unary: (n, S) node potentials (finite).
        trans: (S, S) pair potentials; trans2: (S, S, S) triple potentials or ``None``.
        log_init: (S,) potential of the first state (zeros when ``None``).
    """
    unary = np.asarray(unary, dtype=float)
    n, s = unary.shape
    init = np.zeros(s) if log_init is None else np.asarray(log_init, dtype=float)
    if trans2 is None or n < 2:
        post = forward_backward(init, trans, unary)
        xi3 = None if trans2 is None else np.zeros((s, s, s))
        return ChainStats(post.log_z, post.gamma, post.xi_sum, xi3)
    return _pair_chain(unary, trans, trans2, log_init)


def hmm_targets(hmm, y: np.ndarray, floor: float = -700.0) -> ChainStats:
    """The HMM posterior over state paths of motion y (n, 6), with triple marginals.

    The HMM is first order, so its posterior is a Markov chain whose triple marginals follow
    from the same pair-chain recursion with zero second-order potentials.
    """
    li, lt = hmm._logs()
    emis = hmm.emission_log_likelihood(y)
    s = hmm.n_states
    stats = chain_stats(emis, np.maximum(lt, floor), np.zeros((s, s, s)),
                        log_init=np.maximum(li, floor))
    return ChainStats(0.0, stats.gamma, stats.xi, stats.xi3)


def _score(target: ChainStats, unary: np.ndarray, trans: np.ndarray,
           trans2: np.ndarray | None) -> float:
    """``E_target[score(Q)]`` (the unnormalised log potential)."""
    v = float(np.sum(target.gamma * unary) + np.sum(target.xi * trans))
    if trans2 is not None:
        v += float(np.sum(target.xi3 * trans2))
    return v


# --- objective, gradient, training --------------------------------------------------------------


def objective_and_gradient(
    model: DCNF, vec: np.ndarray, a0s: Sequence[np.ndarray], targets: Sequence[ChainStats],
    l2: np.ndarray, masks: Sequence[Sequence[np.ndarray]] | None = None,
) -> tuple[float, np.ndarray]:
    """Negative regularised expected conditional log-likelihood and its gradient.

    ``f = -Σ_seq E_target[log P(Q | X)] + ½ Σ_j l2_j vec_j²`` (a sum over steps).

    Args:
        model: gives the shapes (its own weights are ignored; ``vec`` is used).
        vec: flat parameters (layout of :meth:`DCNF.flat`).
        a0s: per sequence, flattened standardised windows (n, W*D).
        targets: per sequence, target path statistics (γ, ξ, and ξ3 for a 2nd-order model).
        l2: (P,) penalty per parameter.
        masks: per sequence, the dropout masks of :meth:`DCNF.node_features` (``None``: none).
    """
    m = model.with_flat(vec)
    nl = len(m.layers)
    g_layers = [np.zeros_like(w) for w in m.layers]
    g_theta = np.zeros_like(m.theta)
    g_bias = np.zeros_like(m.bias)
    g_trans = np.zeros_like(m.trans)
    g_trans2 = None if m.trans2 is None else np.zeros_like(m.trans2)
    value = 0.0
    for si, (a0, tgt) in enumerate(zip(a0s, targets, strict=True)):
        acts = m.node_features(a0, None if masks is None else masks[si])
        f = acts[-1]
        unary = f @ m.theta + m.bias
        post = m.posteriors(unary)
        value += _score(tgt, unary, m.trans, m.trans2) - post.log_z
        du = tgt.gamma - post.gamma                         # d value / d unary (n, S)
        g_theta += f.T @ du
        g_bias += du.sum(axis=0)
        g_trans += tgt.xi - post.xi
        if g_trans2 is not None:
            g_trans2 += tgt.xi3 - post.xi3
        da = du @ m.theta.T                                 # d value / d f
        for li in range(nl - 1, -1, -1):
            a = acts[li + 1]
            if masks is not None and li < nl - 1:
                mk = masks[si][li]
                # a = σ(z) * mask: d a / d z = σ'(z) * mask = a * (1 - a / mask) where mask > 0
                sig = np.divide(a, mk, out=np.zeros_like(a), where=mk > 0)
                dz = da * sig * (1.0 - sig) * mk
            else:
                dz = da * a * (1.0 - a)
            prev = acts[li]
            g_layers[li][:-1] += prev.T @ dz
            g_layers[li][-1] += dz.sum(axis=0)
            if li > 0:
                da = dz @ m.layers[li][:-1].T
    grads = [*g_layers, g_theta, g_bias, g_trans] + ([g_trans2] if g_trans2 is not None else [])
    grad = np.concatenate([g.ravel() for g in grads])
    fval = -value + 0.5 * float(np.sum(l2 * vec * vec))
    return fval, -grad + l2 * vec


def penalty_vector(model: DCNF, l2: float, l2_trans: float) -> np.ndarray:
    """L2 weight per parameter: ``l2`` on the network and node weights, ``l2_trans`` on α, β."""
    parts = [np.full(p.size, l2) for p in [*model.layers, model.theta, model.bias]]
    parts += [np.full(model.trans.size, l2_trans)]
    if model.trans2 is not None:
        parts.append(np.full(model.trans2.size, l2_trans))
    return np.concatenate(parts)


@dataclass
class DCNFTrainingInfo:
    """What the optimiser did."""

    n_steps: int
    iterations: int
    best_iteration: int
    objective_per_step: float
    valid_loglik_per_step: float | None
    seconds: float
    history: list[float] = field(default_factory=list)


@dataclass
class DCNFSettings:
    """Hyperparameters (Chiu gives none; these are chosen for ~1 minute of training data).

    Attributes:
        window: W input steps; hidden: sizes of the sigmoid layers, the last being M.
        order: 2 (Chiu's second-order chain) or 1.
        dropout: rate p on the hidden layers (not on the inputs nor on f).
        l2, l2_trans: L2 on network/node weights and on the chain weights (per step of data).
        iterations: Adam steps (full batch); lr: initial step, decayed as lr / (1 + k / decay).
        eval_every: iterations between validation scores (best iterate kept).
        seed: initialisation and dropout masks.
    """

    window: int = 4
    hidden: tuple[int, ...] = (32, 16)
    order: int = 2
    dropout: float = 0.2
    l2: float = 1e-3
    l2_trans: float = 1e-5
    iterations: int = 300
    lr: float = 0.02
    decay: float = 150.0
    eval_every: int = 10
    seed: int = 0


def init_dcnf(n_inputs: int, n_states: int, settings: DCNFSettings, in_mean: np.ndarray,
              in_std: np.ndarray, targets: Sequence[ChainStats] = ()) -> DCNF:
    """Random network (scaled normal, seeded), zero node weights and β; α from the targets.

    α starts at the log of the targets' pair frequencies (the transitions-only fit), so the
    optimiser spends its steps on the prosody part.
    """
    rng = np.random.default_rng(settings.seed)
    sizes = [settings.window * n_inputs, *settings.hidden]
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        w = np.zeros((a + 1, b))
        w[:-1] = rng.normal(0.0, 1.0 / np.sqrt(max(a, 1)), size=(a, b))
        layers.append(w)
    s = n_states
    trans = np.zeros((s, s))
    if targets:
        counts = sum(t.xi for t in targets) + 1.0
        trans = np.log(counts / counts.sum(axis=1, keepdims=True))
    trans2 = np.zeros((s, s, s)) if settings.order == 2 else None
    return DCNF(layers, np.zeros((sizes[-1], s)), np.zeros(s), trans, trans2,
                np.asarray(in_mean, dtype=float), np.asarray(in_std, dtype=float),
                settings.window, settings.dropout)


def input_statistics(inputs: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std (D,) over all steps (std 1 where a feature is constant)."""
    allx = np.concatenate(list(inputs))
    mean = allx.mean(axis=0)
    std = allx.std(axis=0)
    return mean, np.where(std > 1e-6, std, 1.0)


def fit_dcnf(
    inputs: Sequence[np.ndarray], targets: Sequence[ChainStats], pad: np.ndarray,
    settings: DCNFSettings | None = None,
    valid: tuple[Sequence[np.ndarray], Sequence[ChainStats]] | None = None,
) -> tuple[DCNF, DCNFTrainingInfo]:
    """Train a DCNF against fixed target path distributions (one entry per sequence).

    Args:
        inputs: per sequence, raw DCNF inputs (n, D) (:func:`dcnf_inputs`).
        targets: per sequence, :func:`hmm_targets` of its motion.
        pad: (D,) raw input before a stream starts (:func:`pad_input`).
        settings: hyperparameters.
        valid: (inputs, targets) scored every ``eval_every`` steps; the best iterate is kept
            (without it, the last one).
    """
    cfg = settings or DCNFSettings()
    s = targets[0].gamma.shape[1]
    mean, std = input_statistics(inputs)
    model = init_dcnf(inputs[0].shape[1], s, cfg, mean, std, targets)
    a0s = [model.windows(x, pad) for x in inputs]
    va0 = [model.windows(x, pad) for x in valid[0]] if valid else []
    n_total = int(sum(len(a) for a in a0s))
    n_valid = int(sum(len(a) for a in va0))
    l2 = penalty_vector(model, cfg.l2, cfg.l2_trans) * n_total
    rng = np.random.default_rng(cfg.seed + 1)
    vec = model.flat()
    m1 = np.zeros_like(vec)
    m2 = np.zeros_like(vec)
    b1, b2, eps = 0.9, 0.999, 1e-8
    keep = 1.0 - cfg.dropout
    n_hidden = len(model.layers) - 1

    def valid_score(v: np.ndarray) -> float:
        mm = model.with_flat(v)
        return sum(mm.expected_log_likelihood(a, t) for a, t in
                   zip(va0, valid[1], strict=True)) / n_valid

    best_vec, best_it, best_valid = vec.copy(), 0, -np.inf
    history: list[float] = []
    t0 = time.perf_counter()
    fval = np.nan
    for it in range(1, cfg.iterations + 1):
        masks = None
        if cfg.dropout > 0 and n_hidden > 0:
            masks = [[(rng.random((len(a), model.layers[li].shape[1])) < keep) / keep
                      for li in range(n_hidden)] for a in a0s]
        fval, g = objective_and_gradient(model, vec, a0s, targets, l2, masks)
        g /= n_total
        history.append(fval / n_total)
        m1 = b1 * m1 + (1 - b1) * g
        m2 = b2 * m2 + (1 - b2) * g * g
        lr = cfg.lr / (1.0 + it / cfg.decay)
        vec = vec - lr * (m1 / (1 - b1 ** it)) / (np.sqrt(m2 / (1 - b2 ** it)) + eps)
        if va0 and (it % cfg.eval_every == 0 or it == cfg.iterations):
            sc = valid_score(vec)
            if sc > best_valid:
                best_vec, best_it, best_valid = vec.copy(), it, sc
    if not va0:
        best_vec, best_it = vec, cfg.iterations
    info = DCNFTrainingInfo(
        n_steps=n_total, iterations=cfg.iterations, best_iteration=best_it,
        objective_per_step=float(history[-1]) if history else float("nan"),
        valid_loglik_per_step=float(best_valid) if va0 else None,
        seconds=time.perf_counter() - t0, history=history)
    return model.with_flat(best_vec), info


# --- run time -----------------------------------------------------------------------------------


class DCNFFilter:
    """Online forward filtering of a :class:`DCNF`, one control step at a time.

    ``step(x)`` takes the raw input of the current step (D,) and returns the belief (S,) over
    ``q_t`` given the inputs so far (sums to 1). Second order: the message over pairs is
    ``log α_t(j, k) = logsumexp_i(log α_{t-1}(i, j) + β_ijk) + α_jk + u_t(k)``, the belief
    ``Σ_j α_t(j, k)``; the first step uses ``u_0`` alone and the second adds ``α``.
    """

    def __init__(self, dcnf: DCNF, pad: np.ndarray) -> None:
        self.dcnf = dcnf
        self.pad = dcnf.standardise(np.asarray(pad, dtype=float))
        self._w = [np.ascontiguousarray(w[:-1]) for w in dcnf.layers]
        self._b = [w[-1].copy() for w in dcnf.layers]
        self._history = np.broadcast_to(self.pad, (max(dcnf.window, 1), len(self.pad))).copy()
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next step is the first of a stream."""
        self._history[:] = self.pad
        self._log_alpha: np.ndarray | None = None     # (S,) after step 0, then (S, S) (order 2)
        self._belief = np.full(self.dcnf.n_states, 1.0 / self.dcnf.n_states)

    @property
    def n_states(self) -> int:
        return self.dcnf.n_states

    @property
    def belief(self) -> np.ndarray:
        """The current belief (S,); uniform before the first step."""
        return self._belief.copy()

    def unary(self, x: np.ndarray) -> np.ndarray:
        """Shift the window by the raw input x (D,) and return its node potentials (S,)."""
        d = self.dcnf
        if d.window > 0:
            self._history[1:] = self._history[:-1]
            self._history[0] = d.standardise(np.asarray(x, dtype=float))
            a = self._history[: d.window].reshape(-1)
        else:
            a = np.zeros(0)
        for w, b in zip(self._w, self._b, strict=True):
            a = _sigmoid(a @ w + b)
        return a @ d.theta + d.bias

    def step(self, x: np.ndarray) -> np.ndarray:
        """Advance one step with the raw input x (D,); returns the belief (S,)."""
        d = self.dcnf
        lu = self.unary(x)
        la = self._log_alpha
        if la is None:
            la = lu
        elif d.trans2 is None:
            la = _lse(la[:, None] + d.trans, axis=0) + lu
        elif la.ndim == 1:
            la = la[:, None] + d.trans + lu[None, :]
        else:
            la = _lse(la[:, :, None] + d.trans2, axis=0) + d.trans + lu[None, :]
        la = la - _lse(la.reshape(-1), axis=0)
        self._log_alpha = la
        b = np.exp(la) if la.ndim == 1 else np.exp(la).sum(axis=0)
        self._belief = b / b.sum()
        return self._belief.copy()


def _lse(x: np.ndarray, axis: int) -> np.ndarray:
    """log-sum-exp along ``axis`` (finite inputs)."""
    m = np.max(x, axis=axis, keepdims=True)
    return np.squeeze(m, axis=axis) + np.log(np.sum(np.exp(x - m), axis=axis))



def fit_dcnf_selected(
    inputs: Sequence[np.ndarray], ys: Sequence[np.ndarray], hmm, pad: np.ndarray,
    settings: DCNFSettings | None = None, valid_fraction: float = 0.25,
) -> tuple[DCNF, DCNFTrainingInfo]:
    """Choose the number of Adam steps on a validation split, then refit on everything.

    Targets are the HMM posterior (:func:`hmm_targets`) of each part's motion ``ys`` (n, 6).
    The last ``valid_fraction`` of each sequence is held out for the first fit, whose best
    iterate gives the step count; the second fit sees all of ``inputs`` for that many steps,
    with the same seed. ``info.seconds`` covers both fits.
    """
    from dataclasses import replace

    cfg = settings or DCNFSettings()
    tr_x, va_x, tr_t, va_t = [], [], [], []
    for x, y in zip(inputs, ys, strict=True):
        cut = int(round(len(x) * (1.0 - valid_fraction)))
        tr_x.append(x[:cut])
        va_x.append(x[cut:])
        tr_t.append(hmm_targets(hmm, y[:cut]))
        va_t.append(hmm_targets(hmm, y[cut:]))
    t0 = time.perf_counter()
    _, first = fit_dcnf(tr_x, tr_t, pad, cfg, valid=(va_x, va_t))
    model, info = fit_dcnf(inputs, [hmm_targets(hmm, y) for y in ys], pad,
                           replace(cfg, iterations=max(first.best_iteration, 1)))
    info.valid_loglik_per_step = first.valid_loglik_per_step
    info.seconds = time.perf_counter() - t0
    return model, info
