"""Training, pruning, storing and querying the gesture-controller policy table.

:func:`train_policy` computes the fit costs eta for every tone, solves one value function per
(tone, label state) with :func:`gesture_sim.control.mdp.solve_values`, assembles the value table
``V(candidate, a, k, ·)`` once at the end, and prunes it (§6.4 of the digest): an entry is removed
when another entry at the same decision point is <= in every hidden state *and every tone* (and
< somewhere, ties kept at the lowest index). Such an entry can never be the argmin of a
belief-weighted, tone-blended sum, so pruning never changes a decision.

Label states: index 0 is "no label" (w⁰); each semantic label (a tag of library segments) adds a
value function in which every decision not into a matching segment pays C_sem, matching segments
are entered mid-clip at ``f_sem(a, k)`` (Appendix A iii) and the label resets to w⁰ once
satisfied (entering or continuing a matching segment).

A :class:`Policy` is stored as one ``.npz`` with the fingerprints of the library and the model it
was computed for; :meth:`Policy.load` refuses a mismatch with a clear :class:`GestureSimError`.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.control.costs import ControlSettings, expected_mismatch, successor_costs
from gesture_sim.control.inputs import ControlLibrary, StateModel
from gesture_sim.control.mdp import Pieces, SemanticEntries, Structure, ValueSolution, solve_values
from gesture_sim.control.style import Tone, default_tones
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path
from gesture_sim.progress import progress

#: Entry kinds in the table.
KIND_CONTINUE, KIND_SWITCH, KIND_SEMANTIC = 0, 1, 2
KIND_NAMES = ("continue", "switch", "semantic")
FORMAT_VERSION = 1


def nondominated(x: np.ndarray, n_refs: int = 8) -> np.ndarray:
    """Indices (sorted) of the rows of ``x`` (m, D) not dominated by another row.

    Row e' dominates e when ``x[e'] <= x[e]`` everywhere and (``x[e'] != x[e]`` or e' < e).
    Exact: a quick pass against a few reference rows (column argmins, smallest sums) removes
    most dominated rows, then the survivors are compared pairwise. Non-finite rows are dropped.
    """
    m = len(x)
    finite = np.all(np.isfinite(x), axis=1)
    idx = np.nonzero(finite)[0]
    if len(idx) <= 1:
        return idx
    xs = x[idx]
    order = np.argsort(xs.sum(axis=1), kind="stable")
    refs = np.unique(np.concatenate([np.argmin(xs, axis=0), order[:n_refs]]))
    le = np.all(xs[refs][:, None, :] <= xs[None, :, :], axis=2)          # (R, m)
    lt = np.any(xs[refs][:, None, :] < xs[None, :, :], axis=2)
    earlier = idx[refs][:, None] < idx[None, :]
    dom = le & (lt | earlier)
    dom[np.arange(len(refs)), refs] = False
    keep = ~dom.any(axis=0)
    cand = np.nonzero(keep)[0]
    y = xs[cand]
    out = np.ones(len(cand), dtype=bool)
    step = max(1, 4_000_000 // max(1, len(cand) * x.shape[1]))
    for lo in range(0, len(cand), step):
        yy = y[lo:lo + step]                                           # (c, D) dominators
        le = np.all(yy[:, None, :] <= y[None, :, :], axis=2)
        lt = np.any(yy[:, None, :] < y[None, :, :], axis=2)
        earlier = idx[cand][lo:lo + step, None] < idx[cand][None, :]
        dom = le & (lt | earlier)
        dom[np.arange(len(yy)), np.arange(lo, lo + len(yy))] = False
        out &= ~dom.any(axis=0)
    del m
    return idx[cand[out]]


@dataclass
class Policy:
    """The pruned value table and what the controller needs to use it.

    Attributes:
        labels: label states; ``labels[0] == ""`` is "no label".
        tones: tone names; values are stacked per tone and blended at run time.
        frames: (n, K+1) decision frames of each segment.
        lengths: (n,) segment lengths (frames).
        offsets: (n_labels, n*(K+1) + 1) start of each decision point's entries.
        seg, frame, kind: (E,) candidate segment, entry frame (offset) and kind of each entry.
        smooth: (E,) weighted switch cost of each entry (0 for continue).
        resets: (E,) bool, the entry satisfies the pending label (label state returns to w⁰).
        values: (E, M, S) value per tone and hidden state.
        start_values: (M, n, S) value of starting with each segment (no label).
        eta: (M, n, S) weighted fit cost per frame, per tone.
        meta: fingerprints, settings, timing and pruning figures (JSON-ready).
    """

    labels: tuple[str, ...]
    tones: tuple[str, ...]
    frames: np.ndarray
    lengths: np.ndarray
    offsets: np.ndarray
    seg: np.ndarray
    frame: np.ndarray
    kind: np.ndarray
    smooth: np.ndarray
    resets: np.ndarray
    values: np.ndarray
    start_values: np.ndarray
    eta: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        e, m, s = self.values.shape
        self._flat = np.ascontiguousarray(self.values.reshape(e, m * s))
        self._label_index = {name: i for i, name in enumerate(self.labels)}

    @property
    def n_segments(self) -> int:
        return int(len(self.lengths))

    @property
    def n_points(self) -> int:
        return int(self.frames.shape[1])

    @property
    def n_states(self) -> int:
        return int(self.values.shape[2])

    @property
    def library_fingerprint(self) -> str:
        return str(self.meta.get("library_fingerprint", ""))

    @property
    def model_fingerprint(self) -> str:
        return str(self.meta.get("model_fingerprint", ""))

    def label_index(self, label: str | None) -> int:
        """Index of a label state (0 for ``None``/""); -1 when the policy does not know it."""
        return self._label_index.get(label or "", -1)

    def entries(self, label: int, a: int, k: int) -> slice:
        """The slice of table entries at decision point (a, k) in label state ``label``."""
        j = a * self.n_points + k
        return slice(int(self.offsets[label, j]), int(self.offsets[label, j + 1]))

    def scores(self, weights: np.ndarray, label: int, a: int, k: int) -> tuple[slice, np.ndarray]:
        """Belief- and tone-weighted values of the entries at (a, k).

        Args:
            weights: (M*S,) ``kron(tone_weights, belief)``.
        """
        sl = self.entries(label, a, k)
        return sl, self._flat[sl] @ weights

    # ------------------------------------------------------------------ storage
    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the policy to ``path`` (.npz) atomically."""
        meta = dict(self.meta, labels=list(self.labels), tones=list(self.tones),
                    format_version=FORMAT_VERSION)
        with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(
                fh, frames=self.frames, lengths=self.lengths, offsets=self.offsets, seg=self.seg,
                frame=self.frame, kind=self.kind, smooth=self.smooth, resets=self.resets,
                values=self.values, start_values=self.start_values, eta=self.eta,
                meta=np.array(json.dumps(meta)))

    @classmethod
    def load(cls, path: str | os.PathLike[str], library_fingerprint: str | None = None,
             model_fingerprint: str | None = None) -> Policy:
        """Read a policy; refuse it if it was computed for another library or model."""
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise GestureSimError(f"cannot read policy {path}: {exc}") from exc
        try:
            meta = json.loads(str(arrays.pop("meta")))
        except KeyError as exc:
            raise GestureSimError(f"{path} is not a gesture-controller policy") from exc
        if meta.get("format_version") != FORMAT_VERSION:
            raise GestureSimError(f"policy {path} has format {meta.get('format_version')}, "
                                  f"expected {FORMAT_VERSION}; retrain it")
        if library_fingerprint is not None and meta["library_fingerprint"] != library_fingerprint:
            raise GestureSimError(
                f"policy {path} was trained for library {meta['library_fingerprint']}, not "
                f"{library_fingerprint}; retrain the controller for this library")
        if model_fingerprint is not None and meta["model_fingerprint"] != model_fingerprint:
            raise GestureSimError(
                f"policy {path} was trained for model {meta['model_fingerprint']}, not "
                f"{model_fingerprint}; retrain the controller for this model")
        labels, tones = tuple(meta.pop("labels")), tuple(meta.pop("tones"))
        return cls(labels=labels, tones=tones, meta=meta, **arrays)

    def check(self, library: ControlLibrary, model: StateModel | None = None) -> None:
        """Raise :class:`GestureSimError` if this policy is not for ``library``/``model``."""
        if self.library_fingerprint != library.fingerprint:
            raise GestureSimError(
                f"policy was trained for library {self.library_fingerprint}, not "
                f"{library.fingerprint}; retrain the controller for this library")
        if model is not None and self.model_fingerprint != model.fingerprint:
            raise GestureSimError(
                f"policy was trained for model {self.model_fingerprint}, not "
                f"{model.fingerprint}; retrain the controller for this model")


@dataclass
class Training:
    """Everything computed by :func:`train_policy` besides the table (for tests and offline)."""

    structure: Structure
    s_dec: np.ndarray
    eta: np.ndarray                          # (M, n, S) weighted
    pieces: list[Pieces]
    solutions: dict[tuple[int, int], ValueSolution]
    semantic: dict[int, SemanticEntries]


def _label_extras(lib: ControlLibrary, labels: tuple[str, ...], settings: ControlSettings,
                  st: Structure) -> tuple[dict[int, np.ndarray], dict[int, SemanticEntries]]:
    match: dict[int, np.ndarray] = {}
    sem: dict[int, SemanticEntries] = {}
    for li, label in enumerate(labels):
        if li == 0:
            continue
        targets = lib.segments_with_tag(label)
        if len(targets) == 0:
            raise GestureSimError(f"no library segment is tagged '{label}'")
        mask = np.zeros(lib.n_segments, bool)
        mask[targets] = True
        match[li] = mask
        sem[li] = SemanticEntries.build(lib, st, targets, settings.semantic_entry_fraction,
                                        settings.smooth_weight)
    return match, sem


def train_policy(
    library: ControlLibrary, model: StateModel, settings: ControlSettings | None = None,
    tones: tuple[Tone, ...] | None = None, labels: tuple[str, ...] | None = None,
    show_progress: bool = False, method: str = "mpi", return_training: bool = False,
) -> Policy | tuple[Policy, Training]:
    """Solve the gesture-controller MDP for a library and a state model.

    Args:
        library, model: the inputs (see :mod:`gesture_sim.control.inputs`).
        settings: costs, discount and tolerance.
        tones: style tones (default: the single neutral tone; pass
            :func:`~gesture_sim.control.style.default_tones` for calm/neutral/energetic).
        labels: semantic labels (tags of library segments); default: none.
        show_progress: a progress bar over the value functions.
        method: "mpi" or "vi" (see :func:`~gesture_sim.control.mdp.solve_values`).
        return_training: also return the intermediate :class:`Training`.
    """
    t0 = time.perf_counter()
    settings = settings or ControlSettings()
    tones = tones or (default_tones()[1],)
    labels_all = ("",) + tuple(labels or ())
    st = Structure.from_library(library)
    s_dec = successor_costs(library, settings)
    n, kp1 = st.frames.shape
    k_int = kp1 - 1
    n_states = model.n_states

    eta = np.empty((len(tones), n, n_states))
    eta_err = 0.0
    for m, tone in enumerate(tones):
        mu, cov = tone.apply_gaussians(model.means, model.covs)
        e, err = expected_mismatch(library.params, mu, cov, settings.n_samples, settings.seed)
        eta[m] = settings.fit_weight * e
        eta_err = max(eta_err, float(err.max()) * settings.fit_weight)
    pieces = [Pieces.build(st, eta[m], model.transition, settings.discount)
              for m in range(len(tones))]
    match, sem = _label_extras(library, labels_all, settings, st)

    solutions: dict[tuple[int, int], ValueSolution] = {}
    jobs = [(m, li) for li in range(len(labels_all)) for m in range(len(tones))]
    for m, li in progress(jobs, desc="value iteration", enabled=show_progress):
        pc = pieces[m]
        if li == 0:
            solutions[m, 0] = solve_values(st, pc, s_dec, settings.discount, settings.tolerance,
                                           method=method)
            continue
        base = solutions[m, 0]
        mask = match[li]
        c_sem = settings.semantic_cost
        sw_extra = np.where(mask, np.inf, c_sem)
        c_extra = np.where(mask, np.inf, c_sem)
        semv = sem[li].values(pc, eta[m], base.u)                            # (n, K+1, M, S)
        fixed = semv.min(axis=2)
        if k_int:
            fixed[:, :k_int] = np.where(mask[:, None, None],
                                        np.minimum(fixed[:, :k_int], base.cont), fixed[:, :k_int])
        solutions[m, li] = solve_values(st, pc, s_dec, settings.discount, settings.tolerance,
                                        switch_extra=sw_extra, cont_extra=c_extra, fixed=fixed,
                                        method=method, u0=base.u + c_sem)
    t_solve = time.perf_counter() - t0

    # ---------------------------------------------------------------- table
    t1 = time.perf_counter()
    tables = [_build_label_table(li, library, st, s_dec, tones, solutions, match.get(li),
                                 sem.get(li), pieces, eta, settings)
              for li in range(len(labels_all))]
    count = 0
    offsets = np.zeros((len(labels_all), n * kp1 + 1), dtype=np.int64)
    for li, tb in enumerate(tables):
        offsets[li] = tb["offsets"] + count
        count += len(tb["seg"])
    total_entries = int(sum(int(tb["before"]) for tb in tables))

    def cat(key: str) -> np.ndarray:
        return np.concatenate([tb[key] for tb in tables])

    t_table = time.perf_counter() - t1

    meta = {
        "library_fingerprint": library.fingerprint,
        "model_fingerprint": model.fingerprint,
        "settings": settings.to_dict(),
        "tone_transforms": {t.name: {"matrix": np.asarray(t.matrix).tolist(),
                                     "offset": np.asarray(t.offset).tolist()} for t in tones},
        "n_segments": n, "n_states": n_states, "library_seconds": library.duration_s,
        "fps": library.fps,
        "entries_before_pruning": total_entries, "entries_after_pruning": count,
        "pruned_fraction": float(1.0 - count / max(1, total_entries)),
        "solve_seconds": t_solve, "table_seconds": t_table,
        "iterations": {f"{tones[m].name}/{labels_all[li] or '-'}": s.iterations
                       for (m, li), s in solutions.items()},
        "error_bound": max(s.error_bound for s in solutions.values()),
        "eta_stderr_max": eta_err,
        "max_label_delay_frames": int(max(st.tau_entry.max(), st.tau_cont.max(initial=0))),
    }
    policy = Policy(
        labels=labels_all, tones=tuple(t.name for t in tones), frames=st.frames,
        lengths=library.lengths.copy(), offsets=offsets,
        seg=cat("seg").astype(np.int32), frame=cat("frame").astype(np.int32), kind=cat("kind"),
        smooth=cat("smooth"), resets=cat("resets"), values=cat("values"),
        start_values=np.stack([solutions[m, 0].w for m in range(len(tones))]), eta=eta, meta=meta)
    if return_training:
        return policy, Training(structure=st, s_dec=s_dec, eta=eta, pieces=pieces,
                                solutions=solutions, semantic=sem)
    return policy


def _dominance_index(w: np.ndarray, top: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Handicaps between switch candidates.

    ``G[p, q] = max_d (w[p, d] - w[q, d])``: candidate p dominates q at a decision point with
    switch costs s iff ``s[p] + G[p, q] <= s[q]``. Returns G (n, n) (+inf on the diagonal and
    for non-finite rows), and for every q the ``top`` smallest handicaps: indices (n, top) and
    values (n, top), ascending.
    """
    n = len(w)
    fin = np.all(np.isfinite(w), axis=1)
    g = np.full((n, n), np.inf)
    wf = np.where(fin[:, None], w, 0.0)
    step = max(1, 2_000_000 // max(1, n * w.shape[1]))
    for lo in range(0, n, step):
        g[lo:lo + step] = np.max(wf[lo:lo + step, None, :] - wf[None, :, :], axis=2)
    g[~fin, :] = np.inf
    g[:, ~fin] = np.inf
    np.fill_diagonal(g, np.inf)
    top = min(top, n)
    gt = g.T                                                        # gt[q, p] = G[p, q]
    if top < n:
        idx = np.argpartition(gt, top - 1, axis=1)[:, :top]
    else:
        idx = np.tile(np.arange(n), (n, 1))
    val = np.take_along_axis(gt, idx, axis=1)
    order = np.argsort(val, axis=1)
    return g, np.take_along_axis(idx, order, 1), np.take_along_axis(val, order, 1)


def _build_label_table(
    li: int, lib: ControlLibrary, st: Structure, s_dec: np.ndarray, tones: tuple[Tone, ...],
    solutions: dict[tuple[int, int], ValueSolution], mask: np.ndarray | None,
    se: SemanticEntries | None, pieces: list[Pieces], eta: np.ndarray, settings: ControlSettings,
    top: int = 48, batch: int = 64,
) -> dict[str, np.ndarray]:
    """The pruned entries of one label state, grouped by decision point.

    Switch entries have values ``(s + W[a']) + C`` (C = C_sem under a label, else 0); their mutual
    dominance is decided from the handicap index of :func:`_dominance_index` (exact, with a
    conservative margin ``eps``), dominance involving the few other entries (continue, semantic)
    by direct comparison. An entry is removed only if another is lower by more than ``eps`` in no
    coordinate and lower-or-equal within ``-eps`` in all, so ties are kept.
    """
    n, kp1 = st.frames.shape
    k_int = kp1 - 1
    n_t = len(tones)
    s_n = eta.shape[2]
    dim = n_t * s_n
    off = settings.semantic_cost if li else 0.0
    w = np.stack([solutions[m, li].w for m in range(n_t)], axis=1).reshape(n, dim)
    if mask is not None:
        w = np.where(mask[:, None], np.inf, w)
    g, pidx, gval = _dominance_index(w, top)

    # extra entries per point: continue, then semantic entries
    n_sem = 0 if se is None else len(se.targets)
    n_ex = 1 + n_sem
    ex_val = np.full((n, kp1, n_ex, dim), np.inf)
    ex_seg = np.zeros((n, kp1, n_ex), np.int64)
    ex_frame = np.zeros((n, kp1, n_ex), np.int64)
    ex_kind = np.zeros((n, kp1, n_ex), np.int8)
    ex_smooth = np.zeros((n, kp1, n_ex))
    ex_reset = np.zeros((n, kp1, n_ex), bool)
    if k_int:
        cont_own = np.stack([solutions[m, li].cont for m in range(n_t)], axis=2)   # (n,K,M,S)
        cv = cont_own.reshape(n, k_int, dim) + off
        if li and mask is not None:
            cont0 = np.stack([solutions[m, 0].cont for m in range(n_t)], axis=2).reshape(
                n, k_int, dim)
            cv = np.where(mask[:, None, None], cont0, cv)
            ex_reset[:, :k_int, 0] = mask[:, None]
        ex_val[:, :k_int, 0] = cv
        ex_seg[:, :, 0] = np.arange(n)[:, None]
        ex_frame[:, :k_int, 0] = st.frames[:, :k_int] + 1
        ex_kind[:, :, 0] = KIND_CONTINUE
    if n_sem:
        semv = np.stack([se.values(pieces[m], eta[m], solutions[m, 0].u) for m in range(n_t)],
                        axis=3).reshape(n, kp1, n_sem, dim)
        ex_val[:, :, 1:] = semv
        ex_seg[:, :, 1:] = se.targets[None, None]
        ex_frame[:, :, 1:] = se.frame
        ex_kind[:, :, 1:] = KIND_SEMANTIC
        ex_smooth[:, :, 1:] = se.smooth
        ex_reset[:, :, 1:] = True
    ex_val = ex_val.reshape(n * kp1, n_ex, dim)

    rows = np.nonzero(st.valid.reshape(-1))[0]
    s_flat = s_dec.reshape(n * kp1, n)
    finite_w = w[np.isfinite(w)]
    scale = float(np.max(np.abs(finite_w))) if finite_w.size else 1.0
    eps = 1e-9 * (1.0 + scale + off)
    keep_sw_rows, keep_sw_cols, keep_ex_rows, keep_ex_cols = [], [], [], []
    before = 0
    for lo in range(0, len(rows), batch):
        r = rows[lo:lo + batch]
        s_rows = s_flat[r]                                                # (B, n)
        ok = np.isfinite(s_rows) & np.all(np.isfinite(w), axis=1)[None, :]
        # switches dominated by switches: top handicaps first
        best = np.min(s_rows[:, pidx] + gval[None], axis=2)               # (B, n)
        dom = best <= s_rows - eps
        s_min = np.min(np.where(ok, s_rows, np.inf), axis=1, keepdims=True)
        undecided = ok & ~dom & (s_min + gval[None, :, -1] <= s_rows - eps)
        bu, qu = np.nonzero(undecided)
        for j in range(0, len(bu), 256):
            b, q = bu[j:j + 256], qu[j:j + 256]
            full = np.min(s_rows[b] + g[:, q].T, axis=1)
            dom[b, q] = full <= s_rows[b, q] - eps
        # extras vs switches (both ways) and among themselves
        xv = ex_val[r]                                                    # (B, E, D)
        ex_ok = np.all(np.isfinite(xv), axis=2)
        sw = (s_rows[:, :, None] + w[None]) + off                         # (B, n, D)
        sw = np.where(ok[:, :, None], sw, np.inf)
        dom |= np.any(np.all(xv[:, :, None, :] <= sw[:, None, :, :] - eps, axis=3)
                      & ex_ok[:, :, None], axis=1)
        ex_dom = np.any(np.all(sw[:, None, :, :] <= xv[:, :, None, :] - eps, axis=3), axis=2)
        ex_dom |= np.any(np.all(xv[:, None, :, :] <= xv[:, :, None, :] - eps, axis=3)
                         & ex_ok[:, None, :], axis=2)
        keep_sw = ok & ~dom
        keep_ex = ex_ok & ~ex_dom
        before += int(ok.sum() + ex_ok.sum())
        b1, c1 = np.nonzero(keep_sw)
        keep_sw_rows.append(r[b1])
        keep_sw_cols.append(c1)
        b2, c2 = np.nonzero(keep_ex)
        keep_ex_rows.append(r[b2])
        keep_ex_cols.append(c2)
    sr, sc = np.concatenate(keep_sw_rows), np.concatenate(keep_sw_cols)
    er, ec = np.concatenate(keep_ex_rows), np.concatenate(keep_ex_cols)
    a_s, k_s = np.divmod(sr, kp1)
    sw_vals = (s_flat[sr, sc][:, None] + w[sc]) + off
    a_e, k_e = np.divmod(er, kp1)
    key = np.concatenate([sr * (n + n_ex) + sc, er * (n + n_ex) + n + ec])
    order = np.argsort(key, kind="stable")
    point = np.concatenate([sr, er])[order]
    out = {
        "seg": np.concatenate([sc, ex_seg[a_e, k_e, ec]])[order],
        "frame": np.concatenate([np.zeros(len(sc), np.int64), ex_frame[a_e, k_e, ec]])[order],
        "kind": np.concatenate([np.full(len(sc), KIND_SWITCH, np.int8),
                                ex_kind[a_e, k_e, ec]])[order],
        "smooth": np.concatenate([s_flat[sr, sc], ex_smooth[a_e, k_e, ec]])[order],
        "resets": np.concatenate([np.zeros(len(sc), bool), ex_reset[a_e, k_e, ec]])[order],
        "values": np.concatenate([sw_vals, ex_val[er, ec]])[order].reshape(-1, n_t, s_n),
        "offsets": np.searchsorted(point, np.arange(n * kp1 + 1), side="left"),
        "before": np.int64(before),
    }
    return out
