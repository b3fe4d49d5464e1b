"""The Levine et al. 2009 baseline: a syllable-driven HMM with start/continuation states.

Follows the thesis (digest §2.3, §4–5), adapted to this project's run-time interface:

* **Motion clusters = the kinematic HMM's states.** Each training segment is labelled with the
  HMM state holding most of its posterior mass, so the baseline's belief is over the *same* S
  hidden states as the CRF and the control layer's η_a(i) (Gaussian kinematic summaries
  N(μ_i, Σ_i)) applies unchanged. (The thesis clusters segments by Ward's method instead.)
* **Hidden states**: a start state s_i and a continuation state c_i per cluster (2S states);
  the belief over HMM states is ``α(s_i) + α(c_i)``.
* **Observations**: the thesis's discrete features (Table 3.1) — inflection up / down (binary,
  ±1 sd of the F0 change from the previous voiced syllable, since the syllable stream carries
  no pitch contour), intensity {silent, standard, high ≥ mean + 0.5 sd}, length {short ≤
  mean − sd/2, medium, long ≥ mean + sd} — coded as in
  :class:`gesture_sim.inference.normalize.Levine09Observation` (36 symbols). Statistics are seeded
  from training and updated online (Welford). One observation per emitted syllable; during a
  pause, a silent medium-length observation every ``silence_chunk_s`` (the thesis truncates long
  silences into medium chunks), so the observation stream is causal.
* **Training by counting** (with a pseudo-count): each observation is paired with the state
  active at the time of the *next* observation ("the state active at the end of the next
  syllable"); T over (s_i, c_i) and O = P(symbol | state). Continuation ``f_i(τ)`` is a
  decreasing logistic in the elapsed fraction τ fitted by gradient descent (logistic
  regression, reading (b) of the digest).
* **Run time**: forward probabilities with the expected elapsed fraction τ̄ (Eqs. 5.1–5.3,
  weighted-mean form), updated at each observation and held between them. The thesis's
  "direct probabilities" γ, the sampling of the displayed state from α ⊙ γ, the segment choice
  and early/late termination are :mod:`gesture_sim.inference.levine09_synthesis`; this module
  gives it the per-step transition matrix (:meth:`Levine09Model.step_transitions`, with
  continuations that can be forbidden) and the filter's snapshot/restore for the rollback.
* **Body sections** (thesis §2.2, "three distinct HMMs"): this model is the arms (whole-body)
  section; a model may carry ``sections`` — head and lower body, each its own segmentation,
  clustering and Levine09Model counted on the same syllable observations
  (:mod:`gesture_sim.inference.levine09_sections`), stored under ``l09_<section>_`` prefixes.
  A model without them (every model before sections existed) loads and runs as before.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit

from gesture_sim.contracts import Syllable
from gesture_sim.inference.normalize import levine09_code, levine09_stat
from gesture_sim.units import semitones

N_SYMBOLS = 36


class Discretiser:
    """Online Levine 2009 observation symbols from syllables (Table 3.1, no pitch contour).

    Args:
        stats: ``{"change": (mean, sd), "intensity": ..., "length": ...}`` seed statistics
            (F0 change in semitones, intensity in dB, length in s).
        high_sigma: high-intensity threshold in sd (0.5 as in the thesis prose).
    """

    def __init__(self, stats: dict[str, Sequence[float]], high_sigma: float = 0.5) -> None:
        self.stats = {k: tuple(float(x) for x in v) for k, v in stats.items()}
        self.high_sigma = high_sigma
        self.reset()

    def reset(self) -> None:
        self.run = {k: levine09_stat(*v) for k, v in self.stats.items()}
        self.prev_f0: float | None = None

    def observe(self, s: Syllable) -> int:
        """Symbol of a newly emitted syllable (statistics updated with it first)."""
        change = None
        if s.f0_hz is not None and self.prev_f0 is not None:
            change = semitones(s.f0_hz, self.prev_f0)
            self.run["change"].update(change)
        if math.isfinite(s.intensity_db):
            self.run["intensity"].update(s.intensity_db)
        self.run["length"].update(s.length)
        if s.f0_hz is not None:
            self.prev_f0 = s.f0_hz
        c = self.run["change"]
        up = int(change is not None and change - c.mean >= c.sd)
        down = int(change is not None and change - c.mean <= -c.sd)
        i = self.run["intensity"]
        high = s.intensity_db - i.mean >= self.high_sigma * i.sd
        ln = self.run["length"]
        d = s.length - ln.mean
        length = 0 if d <= -ln.sd / 2 else (2 if d >= ln.sd else 1)
        return levine09_code(up, down, 2 if high else 1, length)

    @staticmethod
    def silence() -> int:
        """Symbol of a silent medium-length chunk."""
        return levine09_code(0, 0, 0, 1)

    @staticmethod
    def fit_stats(syllables: Sequence[Syllable]) -> dict[str, tuple[float, float]]:
        """Whole-set seed statistics of a training syllable list."""
        changes, prev = [], None
        for s in syllables:
            if s.f0_hz is not None:
                if prev is not None:
                    changes.append(semitones(s.f0_hz, prev))
                prev = s.f0_hz
        inten = [s.intensity_db for s in syllables if math.isfinite(s.intensity_db)]
        lengths = [s.length for s in syllables]

        def ms(a: list[float], default: tuple[float, float]) -> tuple[float, float]:
            return (float(np.mean(a)), float(max(np.std(a), 1e-3))) if len(a) >= 2 else default

        return {"change": ms(changes, (0.0, 2.0)), "intensity": ms(inten, (70.0, 6.0)),
                "length": ms(lengths, (0.2, 0.1))}


class ObservationStream:
    """Causal observation events for a stream of control steps.

    ``advance(t, syllables)`` (syllables emitted since the previous call) returns the list of
    symbols that occur at this step: one per syllable, or a silent symbol when no syllable has
    been emitted for ``silence_chunk_s`` since the last observation.
    """

    def __init__(self, discretiser: Discretiser, silence_chunk_s: float) -> None:
        self.discretiser = discretiser
        self.silence_chunk_s = silence_chunk_s
        self.t_last = 0.0

    def reset(self) -> None:
        self.discretiser.reset()
        self.t_last = 0.0

    def advance(self, t: float, syllables: Sequence[Syllable] = ()) -> list[int]:
        codes = [self.discretiser.observe(s) for s in syllables]
        if codes:
            self.t_last = t
        elif t - self.t_last >= self.silence_chunk_s:
            codes = [Discretiser.silence()]
            self.t_last = t
        return codes


@dataclass
class Levine09Model:
    """Parameters of the baseline (S clusters → 2S states: s_i = i, c_i = S + i).

    Attributes:
        trans: (2S, 2S) counted transitions; rows of c_i exclude c_i → c_i (the motion ends).
        emit: (2S, 36) observation probabilities P(symbol | state).
        logistic: (S, 2) continuation ``f_i(τ) = sigmoid(a_i - b_i τ)``, b_i ≥ 0.
        mean_length_s: (S,) mean duration of the segments in each cluster (s).
        stats: seed statistics of the discretiser.
        silence_chunk_s: silent observation interval (s).
        sections: the other body sections' models, ``{name: SectionModel}``
            (:class:`gesture_sim.inference.levine09_sections.SectionModel`: "head", "lower"),
            or None (one stream, as before sections existed).
    """

    trans: np.ndarray
    emit: np.ndarray
    logistic: np.ndarray
    mean_length_s: np.ndarray
    stats: dict[str, tuple[float, float]]
    silence_chunk_s: float
    sections: dict[str, Any] | None = field(default=None, compare=False)

    @property
    def n_clusters(self) -> int:
        return int(self.mean_length_s.shape[0])

    def continuation(self, tau: np.ndarray) -> np.ndarray:
        """f_i(τ_i) (S,) for elapsed fractions τ (S,)."""
        a, b = self.logistic[:, 0], self.logistic[:, 1]
        return expit(a - b * tau)

    def step_transitions(self, tau_p: np.ndarray, forbid: Collection[int] = ()) -> np.ndarray:
        """P(A_t | A_{t-1}) (2S, 2S) at an observation (thesis Eq. 4.1 / 5.1), rows = previous.

        Args:
            tau_p: (S,) elapsed fractions τ' of each cluster's motion at this observation.
            forbid: clusters i whose continuation c_i is ruled out (late termination: "if
                A_{t-1} = c_i or s_i, A_t ≠ c_i"); the rows that led there are renormalised.
        """
        s = self.n_clusters
        f = self.continuation(np.asarray(tau_p, dtype=float))
        p = self.trans.copy()
        p[s:, :] *= (1.0 - f)[:, None]
        p[s + np.arange(s), s + np.arange(s)] = f
        if len(forbid):
            cols = s + np.asarray(sorted(set(int(i) for i in forbid)), dtype=int)
            p[:, cols] = 0.0
            total = p.sum(axis=1, keepdims=True)
            p = np.where(total > 0, p / np.where(total > 0, total, 1.0), 0.0)
        return p

    def new_filter(self) -> Levine09Filter:
        return Levine09Filter(self)

    def to_arrays(self, prefix: str = "l09_") -> dict[str, np.ndarray]:
        out = {f"{prefix}trans": self.trans, f"{prefix}emit": self.emit,
               f"{prefix}logistic": self.logistic, f"{prefix}mean_length_s": self.mean_length_s}
        for name, sec in (self.sections or {}).items():
            out |= sec.to_arrays(f"{prefix}{name}_")
        return out

    def meta(self) -> dict:
        out = {"stats": {k: list(v) for k, v in self.stats.items()},
               "silence_chunk_s": self.silence_chunk_s}
        if self.sections:                # absent (not null) without sections: old files match
            out["sections"] = {name: sec.meta() for name, sec in self.sections.items()}
        return out

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict, prefix: str = "l09_") -> Levine09Model:
        """The model stored by :meth:`to_arrays` / :meth:`meta`, without its body sections.

        A stored model's sections (``meta["sections"]``) are read by
        :func:`gesture_sim.inference.levine09_sections.load_levine09`, which calls this.
        """
        return cls(
            *(np.asarray(arrays[f"{prefix}{n}"], dtype=float)
              for n in ("trans", "emit", "logistic", "mean_length_s")),
            stats={k: (float(v[0]), float(v[1])) for k, v in meta["stats"].items()},
            silence_chunk_s=float(meta["silence_chunk_s"]),
        )


class Levine09Filter:
    """Forward probabilities with expected elapsed fraction (thesis Eqs. 5.1–5.3).

    Run-time interface shared with the CRF filter: ``step(t, syllables)`` once per control step
    with the syllables emitted since the previous step; returns the belief (S,) over the HMM
    states (``α(s_i) + α(c_i)``), summing to 1. ``alpha`` (2S,) is the full forward vector.
    """

    def __init__(self, model: Levine09Model) -> None:
        self.model = model
        self.stream = ObservationStream(Discretiser(model.stats), model.silence_chunk_s)
        self.reset()

    @property
    def n_states(self) -> int:
        return self.model.n_clusters

    def reset(self) -> None:
        s = self.model.n_clusters
        self.alpha = np.concatenate([np.full(s, 1.0 / s), np.zeros(s)])
        self.tau = np.zeros(s)
        self.t_obs = 0.0
        self.stream.reset()

    @property
    def belief(self) -> np.ndarray:
        s = self.model.n_clusters
        b = self.alpha[:s] + self.alpha[s:]
        return b / b.sum()

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(α, τ̄, time of the last observation), copied: the state a rollback restores."""
        return self.alpha.copy(), self.tau.copy(), self.t_obs

    def restore(self, snap: tuple[np.ndarray, np.ndarray, float]) -> None:
        """Return to a :meth:`snapshot` (the observation stream is not rewound)."""
        self.alpha, self.tau, self.t_obs = snap[0].copy(), snap[1].copy(), float(snap[2])

    def observe(self, t: float, code: int, forbid: Collection[int] = ()) -> None:
        """Forward update for one observation symbol at time t (s).

        ``forbid``: clusters whose continuation state is ruled out at this observation (the
        late-termination redo); empty for the ordinary update.
        """
        m = self.model
        s = m.n_clusters
        dtau = max(t - self.t_obs, 0.0) / m.mean_length_s
        tau_p = self.tau + dtau
        a_s, a_c = self.alpha[:s], self.alpha[s:]
        # Transition matrix for this step (2S, 2S): rows = previous state.
        p = m.step_transitions(tau_p, forbid)
        new = (self.alpha @ p) * m.emit[:, code]
        total = new.sum()
        if not total > 0:
            new = np.full(2 * s, 1.0 / (2 * s))
            total = 1.0
        w_c = a_c * p[s + np.arange(s), s + np.arange(s)]
        w_s = a_s * p[np.arange(s), s + np.arange(s)]
        denom = w_c + w_s
        self.tau = np.where(denom > 1e-300, (w_c * tau_p + w_s * dtau) / np.maximum(
            denom, 1e-300), 0.0)
        self.alpha = new / total
        self.t_obs = t

    def step(self, t: float, syllables: Sequence[Syllable] = ()) -> np.ndarray:
        """One control step at time t (s); returns the belief (S,)."""
        for code in self.stream.advance(t, syllables):
            self.observe(t, code)
        return self.belief


def _fit_logistic(tau: np.ndarray, cont: np.ndarray, l2: float = 0.1) -> np.ndarray:
    """(a, b) of P(continue | τ) = sigmoid(a - b τ), b = exp(β) > 0, by gradient descent."""
    if len(tau) == 0:
        return np.array([0.0, 1.0])

    def fun(theta: np.ndarray) -> tuple[float, np.ndarray]:
        a, beta = theta
        b = np.exp(beta)
        z = a - b * tau
        p = expit(z)
        nll = -np.sum(cont * np.log(p + 1e-12) + (1 - cont) * np.log(1 - p + 1e-12))
        r = p - cont                       # d nll / dz
        grad = np.array([np.sum(r) + l2 * a, np.sum(r * -tau) * b + l2 * beta])
        return float(nll + 0.5 * l2 * (a * a + beta * beta)), grad

    res = minimize(fun, np.zeros(2), jac=True, method="L-BFGS-B")
    return np.array([res.x[0], float(np.exp(res.x[1]))])


def train_levine09(
    syllable_lists: Sequence[Sequence[Syllable]], segment_lists: Sequence[np.ndarray],
    label_lists: Sequence[np.ndarray], n_clusters: int, motion_fps: Sequence[float],
    rate_hz: float,
    durations_s: Sequence[float], silence_chunk_s: float = 0.5, pseudo_count: float = 0.5,
    stats: dict[str, Sequence[float]] | None = None,
) -> Levine09Model:
    """Count the baseline's parameters over one or more takes.

    Args:
        syllable_lists: per take, the tracker's syllables (in emission order).
        segment_lists: per take, (m, 2) segment frame ranges.
        label_lists: per take, (m,) cluster (= HMM state) of each segment.
        n_clusters: S.
        motion_fps: per take, the motion frame rate (Hz).
        rate_hz: control step rate (Hz); observation times are quantised to steps as at run time.
        durations_s: per take, the duration used (s).
        stats: the discretiser's seed statistics; None: fitted on these syllables (a body
            section passes the arms model's, so that all sections see the same symbols).
    """
    s = n_clusters
    if stats is None:
        stats = Discretiser.fit_stats([x for sl in syllable_lists for x in sl])
    else:
        stats = {k: (float(v[0]), float(v[1])) for k, v in stats.items()}
    trans_counts = np.full((2 * s, 2 * s), pseudo_count)
    emit_counts = np.full((2 * s, N_SYMBOLS), pseudo_count)
    lengths: list[list[float]] = [[] for _ in range(s)]
    taus: list[list[float]] = [[] for _ in range(s)]
    conts: list[list[float]] = [[] for _ in range(s)]
    for syls, segs, labels, dur, fps in zip(syllable_lists, segment_lists, label_lists,
                                            durations_s, motion_fps, strict=True):
        segs = np.asarray(segs, dtype=int)
        for (a, b), lab in zip(segs, labels, strict=True):
            lengths[int(lab)].append((b - a) / fps)
        stream = ObservationStream(Discretiser(stats), silence_chunk_s)
        events: list[tuple[float, int]] = []
        order = sorted(syls, key=lambda x: x.t_emitted)
        k = 0
        for step in range(int(dur * rate_hz)):
            t = step / rate_hz
            new = []
            while k < len(order) and order[k].t_emitted <= t + 1e-9:
                new.append(order[k])
                k += 1
            events.extend((t, c) for c in stream.advance(t, new))
        # Pair each event with the segment active just before the next event.
        times = np.array([e[0] for e in events])
        if len(times) < 2:
            continue
        t_pair = np.append(times[1:], times[-1] + 1.0 / rate_hz) - 0.5 / rate_hz
        frames = np.floor(t_pair * fps).astype(int)
        seg_idx = np.clip(np.searchsorted(segs[:, 1], frames, side="right"), 0, len(segs) - 1)
        prev_state = None
        prev_seg = -1
        for e, (seg, fr) in enumerate(zip(seg_idx, frames, strict=True)):
            lab = int(labels[seg])
            state = lab if seg != prev_seg else s + lab
            emit_counts[state, events[e][1]] += 1
            if prev_state is not None and not (state == prev_state and state >= s):
                trans_counts[prev_state, state] += 1
            a, b = segs[seg]
            tau = (fr - a) / max(b - a, 1)
            if e + 1 < len(seg_idx):
                taus[lab].append(tau)
                conts[lab].append(float(seg_idx[e + 1] == seg))
            prev_state, prev_seg = state, seg
    # Allowed transitions: from s_i to c_i and any s_j; from c_i to any s_j (c_i -> c_i via f_i).
    mask = np.zeros((2 * s, 2 * s), dtype=bool)
    mask[:, :s] = True
    mask[np.arange(s), s + np.arange(s)] = True
    trans = np.where(mask, trans_counts, 0.0)
    trans /= trans.sum(axis=1, keepdims=True)
    emit = emit_counts / emit_counts.sum(axis=1, keepdims=True)
    logistic = np.array([_fit_logistic(np.array(taus[i]), np.array(conts[i])) for i in range(s)])
    all_len = [x for sub in lengths for x in sub]
    fallback = float(np.mean(all_len)) if all_len else 0.5
    mean_len = np.array([np.mean(v) if v else fallback for v in lengths])
    return Levine09Model(trans, emit, logistic, mean_len, stats, silence_chunk_s)
