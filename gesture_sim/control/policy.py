"""Training, pruning, storing and querying the gesture-controller policy.

:func:`train_policy` computes the fit costs eta for every tone, solves one value function per
(tone, label state) with :func:`gesture_sim.control.mdp.solve_values`, and builds the candidate
lists of every decision point in *decomposed* form. The value of a candidate e at the decision
point (a, k) in label state l is

    V(e | a, k, ·) = smooth(e) + W_l[row(e)]           (a vector over tones × hidden states)

where ``smooth(e)`` is its switch (jump) cost, the only part that depends on (a, k), and the
*row* is shared by all decision points: entering segment a' at frame 0 (``W + C_sem``), entering a
semantic gesture at a given frame (Appendix A iii), or continuing segment a from point k. So the
policy stores per label state its value rows (float32), and per decision point only the surviving
candidates' row indices and switch costs (float32). At decision time the scores are
``smooth[sl] + W[rows] @ weights``: a gather and a small matrix-vector product.

Pruning (§6.4 of the digest, :mod:`gesture_sim.control.prune`): a candidate is dropped when
another candidate at the same decision point is <= in every hidden state *and every tone* and <
in at least one (exact twins are kept). Such a candidate can never be the argmin of a
belief-weighted, tone-blended sum, so pruning never changes a decision. The check runs on the
float32-rounded values the controller uses, so it is exact for them. Above
:data:`EXACT_PRUNING_SEGMENTS` segments the non-dominated lists grow with n at every point
(O(n²) entries, O(n³) pruning work); there the switches are first capped to the best few per
reference weighting (:func:`~gesture_sim.control.prune.far_switches`), which can change a
decision (measured: BENCHMARKS.md, "Training cost").

Label states: index 0 is "no label" (w⁰); each semantic label (a tag of library segments) adds a
value function in which every decision not into a matching segment pays C_sem, matching segments
are entered mid-clip at ``f_sem(a, k)`` (Appendix A iii) and the label resets to w⁰ once
satisfied (entering or continuing a matching segment).

A :class:`Policy` is stored as one ``.npz`` (format version 2) with the fingerprints of the
library and the model it was computed for; :meth:`Policy.load` refuses a mismatch, or a file of
another format version, with a clear :class:`GestureSimError`.
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
from gesture_sim.control.prune import PointCandidates, far_switches, prune
from gesture_sim.control.style import Tone, default_tones
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path
from gesture_sim.progress import progress

#: Candidate kinds.
KIND_CONTINUE, KIND_SWITCH, KIND_SEMANTIC = 0, 1, 2
KIND_NAMES = ("continue", "switch", "semantic")
#: Version of the stored format (1: full float64 value table per entry; 2: decomposed rows).
FORMAT_VERSION = 3  # 3: unlabelled switches only into co-speech segments
#: Up to this many segments the candidate lists are pruned exactly (dominance only); above it
#: the far switches are capped first (:func:`~gesture_sim.control.prune.far_switches`), an
#: approximation whose regret BENCHMARKS.md measures ("Training cost"). The shipped library
#: (497 segments) is far below it, so its policy is exact.
EXACT_PRUNING_SEGMENTS = 1000
#: Switches kept per reference weighting by the cap (32 weightings at 6 states and 3 tones).
SWITCHES_PER_REFERENCE = 32
#: Arrays stored in a policy file besides ``meta``.
_ARRAYS = ("frames", "lengths", "offsets", "cand", "smooth", "values", "row_seg", "row_frame",
           "row_kind", "row_resets", "row_offsets", "start_values", "eta")


def nondominated(x: np.ndarray, n_refs: int = 8) -> np.ndarray:
    """Indices (sorted) of the rows of ``x`` (m, D) not dominated by another row.

    Row e' dominates e when ``x[e'] <= x[e]`` everywhere and (``x[e'] != x[e]`` or e' < e).
    Exact: a quick pass against a few reference rows (column argmins, smallest sums) removes
    most dominated rows, then the survivors are compared pairwise. Non-finite rows are dropped.
    (A brute-force reference for the decomposed pruning of :mod:`gesture_sim.control.prune`.)
    """
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
    return idx[cand[out]]


@dataclass
class Policy:
    """The pruned candidate lists, their value rows, and what the controller needs to use them.

    Shapes: n segments, K+1 decision points per segment, L label states, M tones, S hidden
    states, R value rows (all label states), E surviving candidates (all label states).

    Attributes:
        labels: label states; ``labels[0] == ""`` is "no label".
        tones: tone names; values are stacked per tone and blended at run time.
        frames: (n, K+1) decision frames of each segment.
        lengths: (n,) segment lengths (frames).
        offsets: (L, n*(K+1) + 1) start of each decision point's candidates in ``cand``.
        cand: (E,) int32, the value row (index into ``values``) of each candidate.
        smooth: (E,) float32, weighted switch cost of each candidate (0 for continue).
        values: (R, M, S) float32 value rows (per tone and hidden state, dimensionless cost).
        row_seg, row_frame, row_kind, row_resets: (R,) the segment a row enters, its entry frame
            (offset from the segment start), its kind (``KIND_*``), and whether it satisfies the
            pending label (label state returns to w⁰).
        row_offsets: (L+1,) the rows of each label state: ``row_offsets[l]:row_offsets[l+1]``.
        start_values: (M, n, S) value of starting with each segment (no label).
        eta: (M, n, S) weighted fit cost per frame, per tone.
        meta: fingerprints, settings, timing and pruning figures (JSON-ready).
    """

    labels: tuple[str, ...]
    tones: tuple[str, ...]
    frames: np.ndarray
    lengths: np.ndarray
    offsets: np.ndarray
    cand: np.ndarray
    smooth: np.ndarray
    values: np.ndarray
    row_seg: np.ndarray
    row_frame: np.ndarray
    row_kind: np.ndarray
    row_resets: np.ndarray
    row_offsets: np.ndarray
    start_values: np.ndarray
    eta: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        r, m, s = self.values.shape
        # float64 copies for decision time (exact: the stored numbers are float32)
        self._flat = self.values.reshape(r, m * s).astype(np.float64)
        self._smooth = self.smooth.astype(np.float64)
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
    def n_entries(self) -> int:
        return int(len(self.cand))

    # per-candidate views (gathers through the rows)
    @property
    def seg(self) -> np.ndarray:
        """(E,) segment each candidate plays."""
        return self.row_seg[self.cand]

    @property
    def frame(self) -> np.ndarray:
        """(E,) entry frame (offset) of each candidate."""
        return self.row_frame[self.cand]

    @property
    def kind(self) -> np.ndarray:
        """(E,) kind (``KIND_*``) of each candidate."""
        return self.row_kind[self.cand]

    @property
    def resets(self) -> np.ndarray:
        """(E,) whether each candidate satisfies the pending label."""
        return self.row_resets[self.cand]

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
        """The slice of candidates at decision point (a, k) in label state ``label``."""
        j = a * self.n_points + k
        return slice(int(self.offsets[label, j]), int(self.offsets[label, j + 1]))

    def entry_values(self, label: int, a: int, k: int) -> np.ndarray:
        """(m, M, S) float64 values ``smooth + W[row]`` of the candidates at (a, k)."""
        sl = self.entries(label, a, k)
        return (self.smooth[sl].astype(float)[:, None, None]
                + self.values[self.cand[sl]].astype(float))

    def scores(self, weights: np.ndarray, label: int, a: int, k: int) -> tuple[slice, np.ndarray]:
        """Belief- and tone-weighted values of the candidates at (a, k).

        Args:
            weights: (M*S,) ``kron(tone_weights, belief)``, convex (sums to 1).

        Returns:
            the candidates' slice and their (m,) float64 scores
            ``smooth + W[rows] @ weights``.
        """
        j = a * self.n_points + k
        sl = slice(int(self.offsets[label, j]), int(self.offsets[label, j + 1]))
        return sl, self._smooth[sl] + self._flat[self.cand[sl]] @ weights

    # ------------------------------------------------------------------ storage
    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the policy to ``path`` (.npz, compressed) atomically.

        Candidate rows are stored relative to their label state's first row, as int16 where
        every label state has fewer than 32768 rows.
        """
        meta = dict(self.meta, labels=list(self.labels), tones=list(self.tones),
                    format_version=FORMAT_VERSION)
        arrays = {k: getattr(self, k) for k in _ARRAYS}
        counts = np.diff(self.offsets[:, [0, -1]], axis=1)[:, 0]
        local = self.cand - np.repeat(self.row_offsets[:-1], counts)
        arrays["cand"] = local.astype(np.int16 if np.diff(self.row_offsets).max(initial=0)
                                      < 2**15 else np.int32)
        with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str], library_fingerprint: str | None = None,
             model_fingerprint: str | None = None) -> Policy:
        """:meth:`_load`, with any decoding failure (a truncated npz, bad JSON, missing keys)
        turned into one GestureSimError naming the file."""
        import zipfile

        try:
            return cls._load(path, library_fingerprint, model_fingerprint)
        except GestureSimError:
            raise
        except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, IndexError,
                TypeError, AttributeError) as exc:
            raise GestureSimError(
                f"{path}: damaged controller policy ({type(exc).__name__}); delete it and it is "
                "retrained on the next run") from exc

    @classmethod
    def _load(cls, path: str | os.PathLike[str], library_fingerprint: str | None = None,
              model_fingerprint: str | None = None) -> Policy:
        """Read a policy; refuse it if it was computed for another library or model, or if it
        has another format version."""
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise GestureSimError(f"cannot read policy {path}: {exc}") from exc
        try:
            meta = json.loads(str(arrays.pop("meta")))
        except (KeyError, ValueError) as exc:
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
        missing = [k for k in _ARRAYS if k not in arrays]
        if missing:
            raise GestureSimError(f"policy {path} lacks {', '.join(missing)}; retrain it")
        offsets, row_offsets = arrays["offsets"], arrays["row_offsets"]
        counts = np.diff(offsets[:, [0, -1]], axis=1)[:, 0]
        arrays["cand"] = (arrays["cand"].astype(np.int32)
                          + np.repeat(row_offsets[:-1], counts).astype(np.int32))
        labels, tones = tuple(meta.pop("labels")), tuple(meta.pop("tones"))
        return cls(labels=labels, tones=tones, meta=meta, **{k: arrays[k] for k in _ARRAYS})

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
    t_succ = time.perf_counter()
    s_dec = successor_costs(library, settings)
    t_succ = time.perf_counter() - t_succ
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
    # Without a label the controller switches only into co-speech segments; a label state
    # reaches its own segments through semantic entries and otherwise co-speech ones.
    allowed = np.asarray(library.cospeech, dtype=bool)
    open_sw = np.where(allowed, 0.0, np.inf)

    solutions: dict[tuple[int, int], ValueSolution] = {}
    sem_rows: dict[tuple[int, int], np.ndarray] = {}
    jobs = [(m, li) for li in range(len(labels_all)) for m in range(len(tones))]
    for m, li in progress(jobs, desc="value iteration", enabled=show_progress):
        pc = pieces[m]
        if li == 0:
            solutions[m, 0] = solve_values(st, pc, s_dec, settings.discount, settings.tolerance,
                                           switch_extra=open_sw, method=method)
            continue
        base = solutions[m, 0]
        mask = match[li]
        c_sem = settings.semantic_cost
        sw_extra = np.where(mask, np.inf, c_sem + open_sw)
        c_extra = np.where(mask, np.inf, c_sem)
        se = sem[li]
        sem_rows[m, li] = se.row_values(pc, eta[m], base.u)                  # (R, S)
        fixed = (se.smooth[..., None] + sem_rows[m, li][se.row]).min(axis=2)  # (n, K+1, S)
        if k_int:
            fixed[:, :k_int] = np.where(mask[:, None, None],
                                        np.minimum(fixed[:, :k_int], base.cont), fixed[:, :k_int])
        solutions[m, li] = solve_values(st, pc, s_dec, settings.discount, settings.tolerance,
                                        switch_extra=sw_extra, cont_extra=c_extra, fixed=fixed,
                                        method=method, u0=base.u + c_sem)
    t_solve = time.perf_counter() - t0

    # ---------------------------------------------------------------- table
    t1 = time.perf_counter()
    tables = [_label_table(li, st, s_dec, len(tones), solutions, match.get(li), sem.get(li),
                           sem_rows, settings.semantic_cost if li else 0.0, allowed)
              for li in range(len(labels_all))]
    offsets = np.zeros((len(labels_all), n * kp1 + 1), dtype=np.int64)
    row_offsets = np.zeros(len(labels_all) + 1, dtype=np.int64)
    count = 0
    for li, tb in enumerate(tables):
        offsets[li] = tb.offsets + count
        count += len(tb.cand)
        row_offsets[li + 1] = row_offsets[li] + len(tb.values)
    total_entries = int(sum(tb.before for tb in tables))
    cand = np.concatenate([tb.cand + row_offsets[li] for li, tb in enumerate(tables)])

    def cat(key: str) -> np.ndarray:
        return np.concatenate([getattr(tb, key) for tb in tables])

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
        "switch_cap": (SWITCHES_PER_REFERENCE if n > EXACT_PRUNING_SEGMENTS else None),
        "successor_kept_fraction": float(sum(tb.switches_capped for tb in tables)
                                         / max(1, sum(tb.switches for tb in tables))),
        "value_rows": int(row_offsets[-1]),
        "solve_seconds": t_solve, "table_seconds": t_table, "successor_seconds": t_succ,
        "iterations": {f"{tones[m].name}/{labels_all[li] or '-'}": s.iterations
                       for (m, li), s in solutions.items()},
        "error_bound": max(s.error_bound for s in solutions.values()),
        "eta_stderr_max": eta_err,
        "cospeech_segments": int(allowed.sum()),
        "max_label_delay_frames": int(max(st.tau_entry.max(), st.tau_cont.max(initial=0))),
    }
    policy = Policy(
        labels=labels_all, tones=tuple(t.name for t in tones), frames=st.frames,
        lengths=library.lengths.copy(), offsets=offsets, cand=cand.astype(np.int32),
        smooth=cat("smooth"), values=cat("values"), row_seg=cat("row_seg"),
        row_frame=cat("row_frame"), row_kind=cat("row_kind"), row_resets=cat("row_resets"),
        row_offsets=row_offsets,
        start_values=np.stack([solutions[m, 0].w for m in range(len(tones))]), eta=eta, meta=meta)
    if return_training:
        return policy, Training(structure=st, s_dec=s_dec, eta=eta, pieces=pieces,
                                solutions=solutions, semantic=sem)
    return policy


@dataclass
class _LabelTable:
    """The candidate lists of one label state (rows local to the label state)."""

    offsets: np.ndarray          # (n*(K+1) + 1,)
    cand: np.ndarray             # (E,) local row index
    smooth: np.ndarray           # (E,) float32
    values: np.ndarray           # (R, M, S) float32
    row_seg: np.ndarray
    row_frame: np.ndarray
    row_kind: np.ndarray
    row_resets: np.ndarray
    before: int                  # candidates before pruning
    switches: int = 0            # switch candidates before pruning
    switches_capped: int = 0     # ... left by the far-switch cap (= switches when exact)


def _label_table(
    li: int, st: Structure, s_dec: np.ndarray, n_tones: int,
    solutions: dict[tuple[int, int], ValueSolution], mask: np.ndarray | None,
    se: SemanticEntries | None, sem_rows: dict[tuple[int, int], np.ndarray], off: float,
    allowed: np.ndarray | None = None,
) -> _LabelTable:
    """Value rows and pruned candidate lists of label state ``li``.

    Rows, before compaction: ``n`` switch rows (``W + off``; none into segments matching the
    label), ``n*K`` continue rows (``cont + off``, or the label-free continue for a matching
    segment, which satisfies the label), then the semantic (target, entry frame) rows. All values
    are rounded to float32 first; pruning and the controller use the same rounded numbers.
    Rows no surviving candidate uses are dropped.
    """
    n, kp1 = st.frames.shape
    k_int = kp1 - 1
    s_n = solutions[0, li].w.shape[1]
    dim = n_tones * s_n

    def f32(x: np.ndarray) -> np.ndarray:
        return np.asarray(x, np.float32).astype(float)

    w = np.stack([solutions[m, li].w for m in range(n_tones)], axis=1).reshape(n, dim) + off
    if mask is not None:
        w = np.where(mask[:, None], np.inf, w)
    if allowed is not None:                      # no unlabelled switch into an emblem
        w = np.where(allowed[:, None], w, np.inf)
    w = f32(w)
    cont = np.full((n, k_int, dim), np.inf)
    resets_c = np.zeros((n, k_int), bool)
    if k_int:
        cont = np.stack([solutions[m, li].cont for m in range(n_tones)], axis=2).reshape(
            n, k_int, dim) + off
        if mask is not None:
            cont0 = np.stack([solutions[m, 0].cont for m in range(n_tones)], axis=2).reshape(
                n, k_int, dim)
            cont = np.where(mask[:, None, None], cont0, cont)
            resets_c[:] = mask[:, None]
        cont = f32(cont)
    n_sem = 0 if se is None else len(se.targets)
    r_sem = 0 if se is None else se.n_rows
    w_sem = (f32(np.stack([sem_rows[m, li] for m in range(n_tones)], axis=1).reshape(r_sem, dim))
             if se is not None else np.zeros((0, dim)))

    pts = np.nonzero(st.valid.reshape(-1))[0]                        # valid decision points
    a_p, k_p = np.divmod(pts, kp1)
    s_sw = f32(s_dec.reshape(n * kp1, n)[pts])
    x_cont = np.full((len(pts), dim), np.inf)
    has_c = k_p < k_int
    x_cont[has_c] = cont[a_p[has_c], k_p[has_c]]
    if n_sem:
        sem_row = se.row.reshape(n * kp1, n_sem)[pts]
        s_sem = f32(se.smooth.reshape(n * kp1, n_sem)[pts])
    else:
        sem_row = np.zeros((len(pts), 0), np.int64)
        s_sem = np.zeros((len(pts), 0))
    before_sw = int((np.isfinite(s_sw) & np.all(np.isfinite(w), axis=1)[None]).sum())
    kept_sw = before_sw
    if n > EXACT_PRUNING_SEGMENTS:           # large library: cap the far switches first
        keep = far_switches(s_sw, w, SWITCHES_PER_REFERENCE)
        s_sw = np.where(keep, s_sw, np.inf)
        kept_sw = int(keep.sum())
    cands = PointCandidates(w_sw=w, s_sw=s_sw, w_sem=w_sem, sem_row=sem_row, s_sem=s_sem,
                            x_cont=x_cont)
    before = int(before_sw + np.all(np.isfinite(x_cont), axis=1).sum()
                 + (np.isfinite(s_sem) & np.all(np.isfinite(w_sem), axis=1)[sem_row]).sum())
    keep_sw, keep_sem, keep_cont = prune(cands)

    # surviving candidates as (point, row, smooth); rows: switch, continue, semantic
    p1, c1 = np.nonzero(keep_sw)
    p2 = np.nonzero(keep_cont)[0]
    p3, c3 = np.nonzero(keep_sem)
    point = np.concatenate([pts[p1], pts[p2], pts[p3]])
    row = np.concatenate([c1, n + a_p[p2] * k_int + k_p[p2], n + n * k_int + sem_row[p3, c3]])
    smooth = np.concatenate([s_sw[p1, c1], np.zeros(len(p2)), s_sem[p3, c3]])
    order = np.lexsort((row, point))
    point, row, smooth = point[order], row[order], smooth[order]

    # all rows, then keep the used ones
    all_vals = np.concatenate([w, cont.reshape(n * k_int, dim), w_sem])
    seg_all = np.concatenate([np.arange(n), np.repeat(np.arange(n), k_int),
                              se.targets[se.row_target] if se is not None else []])
    frame_all = np.concatenate([np.zeros(n, np.int64), (st.frames[:, :k_int] + 1).reshape(-1),
                                se.row_frame if se is not None else []])
    kind_all = np.concatenate([np.full(n, KIND_SWITCH), np.full(n * k_int, KIND_CONTINUE),
                               np.full(r_sem, KIND_SEMANTIC)])
    reset_all = np.concatenate([np.zeros(n, bool), resets_c.reshape(-1), np.ones(r_sem, bool)])
    used, local = np.unique(row, return_inverse=True)
    return _LabelTable(
        offsets=np.searchsorted(point, np.arange(n * kp1 + 1), side="left"),
        cand=local.astype(np.int64), smooth=smooth.astype(np.float32),
        values=all_vals[used].astype(np.float32).reshape(len(used), n_tones, s_n),
        row_seg=seg_all[used].astype(np.int32), row_frame=frame_all[used].astype(np.int32),
        row_kind=kind_all[used].astype(np.int8), row_resets=reset_all[used], before=before,
        switches=before_sw, switches_capped=kept_sw)
