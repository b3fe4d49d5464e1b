"""Value iteration against brute force, pruning, and policy storage."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.control.costs import ControlSettings
from gesture_sim.control.inputs import ControlLibrary, array_fingerprint
from gesture_sim.control.mdp import Pieces, Structure, solve_values
from gesture_sim.control.policy import (
    KIND_CONTINUE,
    KIND_SEMANTIC,
    KIND_SWITCH,
    Policy,
    nondominated,
    train_policy,
)
from gesture_sim.control.style import default_tones
from gesture_sim.errors import GestureSimError


def tiny_library(rng: np.random.Generator) -> ControlLibrary:
    lengths = np.array([4, 5, 6])
    inter = np.array([[2], [3], [2]])
    n = 3
    d_sp = rng.uniform(0.5, 3.0, (n, n))
    d_in = rng.uniform(0.5, 3.0, (n, 1, n))
    return ControlLibrary(lengths=lengths, interrupt_frames=inter, params=rng.normal(size=(n, 6)),
                          d_sp=d_sp, d_in=d_in, tags=((), (), ()), fps=30.0,
                          fingerprint=array_fingerprint(d_sp))


def brute_force_values(lib: ControlLibrary, eta: np.ndarray, s_dec: np.ndarray,
                       trans: np.ndarray, lam: float) -> np.ndarray:
    """min over all deterministic stationary policies of the exact per-frame policy value.

    The chain runs frame by frame over (segment, frame, hidden state); each policy is evaluated
    by solving its linear system. Returns (n, K+1, S) at the decision points.
    """
    n, s_n = eta.shape
    frames = lib.decision_frames()
    kp1 = frames.shape[1]
    base = np.concatenate([[0], np.cumsum(lib.lengths)[:-1]])
    size = int(lib.lengths.sum()) * s_n

    def row(a: int, i: int, sc: float, nxt_a: int, nxt_f: int) -> tuple[float, np.ndarray]:
        m_row = np.zeros(size)
        col = (base[nxt_a] + nxt_f) * s_n
        m_row[col:col + s_n] = lam * trans[i]
        return sc + lam * trans[i] @ eta[nxt_a], m_row

    m0 = np.zeros((size, size))
    r0 = np.zeros(size)
    drows, options = [], []          # decision rows and, per row, (r, M row) of each action
    for a in range(n):
        for f in range(int(lib.lengths[a])):
            ks = np.nonzero(frames[a] == f)[0]
            for i in range(s_n):
                idx = (base[a] + f) * s_n + i
                if len(ks) == 0:
                    r0[idx], m0[idx] = row(a, i, 0.0, a, f + 1)
                    continue
                k = int(ks[-1])
                acts = [row(a, i, 0.0, a, f + 1)] if k < kp1 - 1 else []
                acts += [row(a, i, s_dec[a, k, b], b, 0) for b in range(n) if b != a]
                drows.append(idx)
                options.append(acts)
    choices = np.array(list(itertools.product(*[range(len(o)) for o in options])))
    best = np.full(size, np.inf)
    for lo in range(0, len(choices), 8192):
        ch = choices[lo:lo + 8192]
        m = np.repeat(m0[None], len(ch), axis=0)
        r = np.repeat(r0[None], len(ch), axis=0)
        for d, idx in enumerate(drows):
            r[:, idx] = np.array([o[0] for o in options[d]])[ch[:, d]]
            m[:, idx] = np.stack([o[1] for o in options[d]])[ch[:, d]]
        j = np.linalg.solve(np.eye(size)[None] - m, r[..., None])[..., 0]
        best = np.minimum(best, j.min(axis=0))
    out = np.empty((n, kp1, s_n))
    for a in range(n):
        for k in range(kp1):
            out[a, k] = best[(base[a] + frames[a, k]) * s_n + np.arange(s_n)]
    return out


@pytest.mark.parametrize("method", ["vi", "mpi"])
def test_value_iteration_equals_brute_force(method: str) -> None:
    # 3 segments x 2 decision points x 2 hidden states: 3^6 * 2^6 = 46656 policies
    rng = np.random.default_rng(7)
    lib = tiny_library(rng)
    eta = rng.uniform(0.0, 2.0, (3, 2))
    trans = np.array([[0.8, 0.2], [0.3, 0.7]])
    lam = 0.8
    s_dec = np.concatenate([lib.d_in, lib.d_sp[:, None, :]], axis=1)
    s_dec[np.arange(3), :, np.arange(3)] = np.inf
    st = Structure.from_library(lib)
    sol = solve_values(st, Pieces.build(st, eta, trans, lam), s_dec, lam, tolerance=1e-9,
                       method=method)
    assert sol.error_bound <= 1e-9
    np.testing.assert_allclose(sol.u, brute_force_values(lib, eta, s_dec, trans, lam), atol=1e-7)


def test_mpi_and_vi_agree_within_tolerance(small_lib, small_model) -> None:
    st = ControlSettings(tolerance=1e-6)
    _, tr = train_policy(small_lib, small_model, st, return_training=True)
    sol = tr.solutions[0, 0]
    vi = solve_values(tr.structure, tr.pieces[0], tr.s_dec, st.discount, 1e-6, method="vi")
    assert sol.error_bound <= 1e-6 and vi.error_bound <= 1e-6
    assert np.max(np.abs(vi.u - sol.u)) <= 2e-6
    assert vi.iterations > 3 * sol.iterations            # the acceleration does something


@pytest.fixture(scope="module")
def trained(small_lib, small_model):
    return train_policy(small_lib, small_model, ControlSettings(), tones=default_tones(),
                        labels=("wave",), return_training=True)


def _all_candidates(policy, tr, li: int, a: int, k: int) -> tuple[list, np.ndarray]:
    """Every candidate at (a, k) in label state li, unpruned, straight from the value functions
    (float32-rounded parts, as stored): [(kind, seg, frame)], values (m, M*S)."""
    n, kp1 = policy.n_segments, policy.n_points
    n_t = len(policy.tones)
    c_sem = ControlSettings().semantic_cost if li else 0.0
    targets = tr.semantic[li].targets if li else np.zeros(0, int)

    def f32(x):
        return np.asarray(x, np.float32).astype(float)

    def stack(key, m_li):
        return np.concatenate([getattr(tr.solutions[m, m_li], key) for m in range(n_t)], -1)

    w = np.concatenate([tr.solutions[m, li].w for m in range(n_t)], axis=1)      # (n, M*S)
    ids, vals = [], []
    for x in range(n):
        if x != a and np.isfinite(tr.s_dec[a, k, x]) and x not in targets:
            ids.append((KIND_SWITCH, x, 0))
            vals.append(f32(tr.s_dec[a, k, x]) + f32(w[x] + c_sem))
    if k < kp1 - 1:
        matching = a in targets
        cont = stack("cont", 0 if matching else li)[a, k] + (0.0 if matching else c_sem)
        ids.append((KIND_CONTINUE, a, int(tr.structure.frames[a, k]) + 1))
        vals.append(f32(cont))
    if li:
        se = tr.semantic[li]
        for j, b in enumerate(targets):
            if not np.isfinite(se.smooth[a, k, j]):
                continue
            tau, kh = se.tau[a, k, j], se.next_point[a, k, j]
            row = np.concatenate([
                tr.pieces[m].g[tau] @ tr.eta[m][b]
                + tr.pieces[m].d[tau] @ tr.solutions[m, 0].u[b, kh] for m in range(n_t)])
            ids.append((KIND_SEMANTIC, int(b), int(se.frame[a, k, j])))
            vals.append(f32(se.smooth[a, k, j]) + f32(row))
    return ids, np.array(vals)


def test_table_is_exactly_the_nondominated_set(trained) -> None:
    policy, tr = trained
    kept_total = 0
    for li in range(len(policy.labels)):
        for a in range(policy.n_segments):
            for k in range(policy.n_points):
                sl = policy.entries(li, a, k)
                if not tr.structure.valid[a, k]:
                    assert sl.stop == sl.start
                    continue
                stored = policy.entry_values(li, a, k).reshape(sl.stop - sl.start, -1)
                assert len(nondominated(stored)) == len(stored)
                # brute force over every candidate: the stored ones are exactly the survivors
                ids, vals = _all_candidates(policy, tr, li, a, k)
                keep = nondominated(vals)
                got = list(zip(policy.kind[sl].tolist(), policy.seg[sl].tolist(),
                               policy.frame[sl].tolist(), strict=True))
                assert sorted(got) == sorted(ids[i] for i in keep)
                ref = {ids[i]: vals[i] for i in keep}
                np.testing.assert_allclose(stored, np.array([ref[e] for e in got]), rtol=1e-6)
                kept_total += len(keep)
    assert kept_total == policy.n_entries
    assert 0.3 < policy.meta["pruned_fraction"] < 1.0


def test_pruning_never_changes_the_chosen_action(trained, small_lib) -> None:
    policy, tr = trained
    rng = np.random.default_rng(11)
    n, kp1 = policy.n_segments, policy.n_points
    n_t = len(policy.tones)
    checked = 0

    def f32(x):
        return np.asarray(x, np.float32).astype(float)

    for _ in range(400):
        a, k = int(rng.integers(n)), int(rng.integers(kp1))
        if not tr.structure.valid[a, k]:
            continue
        b = rng.dirichlet(np.ones(policy.n_states) * 0.5)
        d = rng.dirichlet(np.ones(n_t))
        # every candidate, unpruned, straight from the value functions
        # every candidate, unpruned, straight from the value functions (float32-rounded parts,
        # as the controller uses them)
        full = [(sum(d[m] * (f32(tr.s_dec[a, k, x]) + f32(tr.solutions[m, 0].w[x])) @ b
                     for m in range(n_t)), KIND_SWITCH, x) for x in range(n) if x != a]
        if k < kp1 - 1:
            full.append((sum(d[m] * (f32(tr.solutions[m, 0].cont[a, k]) @ b)
                             for m in range(n_t)), KIND_CONTINUE, a))
        best = min(full, key=lambda e: e[0])
        sl, scores = policy.scores(np.kron(d, b), 0, a, k)
        j = int(np.argmin(scores))
        assert (int(policy.kind[sl][j]), int(policy.seg[sl][j])) == (best[1], best[2])
        assert scores[j] == pytest.approx(best[0], abs=1e-9)
        checked += 1
    assert checked > 200


def test_store_load_round_trip_and_fingerprint_refusal(trained, small_lib, small_model,
                                                       tmp_path: Path) -> None:
    policy, _ = trained
    path = tmp_path / "policy.npz"
    policy.save(path)
    back = Policy.load(path, library_fingerprint=small_lib.fingerprint,
                       model_fingerprint=small_model.fingerprint)
    for key in ("values", "offsets", "cand", "smooth", "row_seg", "row_frame", "row_kind",
                "row_resets", "start_values", "eta"):
        np.testing.assert_array_equal(getattr(back, key), getattr(policy, key))
    assert back.labels == policy.labels and back.tones == policy.tones
    # compact storage: float32 values and switch costs, int16 row indices
    with np.load(path) as z:
        assert z["values"].dtype == np.float32 and z["smooth"].dtype == np.float32
        assert z["cand"].dtype == np.int16
        assert "meta" in z.files and len(z["cand"]) == policy.n_entries
    # decisions of the loaded policy are the trained policy's
    rng = np.random.default_rng(0)
    for _ in range(50):
        a, k = int(rng.integers(policy.n_segments)), int(rng.integers(policy.n_points))
        wts = np.kron(rng.dirichlet(np.ones(len(policy.tones))),
                      rng.dirichlet(np.ones(policy.n_states)))
        for li in range(len(policy.labels)):
            np.testing.assert_array_equal(back.scores(wts, li, a, k)[1],
                                          policy.scores(wts, li, a, k)[1])
    with pytest.raises(GestureSimError, match="library"):
        Policy.load(path, library_fingerprint="0123456789abcdef")
    with pytest.raises(GestureSimError, match="model"):
        Policy.load(path, model_fingerprint="0123456789abcdef")
    other = ControlLibrary(**{**small_lib.__dict__, "fingerprint": "ffffffffffffffff"})
    with pytest.raises(GestureSimError, match="retrain"):
        back.check(other)


def test_policy_of_another_format_version_is_refused(trained, tmp_path: Path) -> None:
    policy, _ = trained
    path = tmp_path / "policy.npz"
    policy.save(path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays.pop("meta")))
    meta["format_version"] = 1                      # e.g. a file of the old, undecomposed table
    old = tmp_path / "old.npz"
    np.savez(old, meta=np.array(json.dumps(meta)), **arrays)
    with pytest.raises(GestureSimError, match="format 1, expected 3; retrain"):
        Policy.load(old)
    garbage = tmp_path / "garbage.npz"
    np.savez(garbage, values=np.zeros(3))
    with pytest.raises(GestureSimError, match="not a gesture-controller policy"):
        Policy.load(garbage)


def test_scores_are_the_belief_weighted_entry_values(trained) -> None:
    policy, _ = trained
    rng = np.random.default_rng(4)
    for _ in range(30):
        li = int(rng.integers(len(policy.labels)))
        a, k = int(rng.integers(policy.n_segments)), int(rng.integers(policy.n_points))
        d = rng.dirichlet(np.ones(len(policy.tones)))
        b = rng.dirichlet(np.ones(policy.n_states))
        sl, scores = policy.scores(np.kron(d, b), li, a, k)
        ref = np.einsum("emi,m,i->e", policy.entry_values(li, a, k), d, b)
        np.testing.assert_allclose(scores, ref, rtol=1e-12, atol=1e-9)
        assert len(scores) == sl.stop - sl.start
