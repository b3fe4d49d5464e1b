"""Decomposed dominance pruning against a brute-force check of every pair of candidates."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.control.prune import PointCandidates, handicaps, prune


def f32(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, np.float32).astype(float)


def random_candidates(rng: np.random.Generator, n: int = 14, d: int = 4, p: int = 37,
                      r: int = 9, e: int = 4) -> PointCandidates:
    """Candidates with a lot of dominance (few coordinates, spread switch costs), absent ones,
    a non-finite switch row, and exact twins (a semantic row equal to a switch row, same cost)."""
    w_sw = f32(rng.normal(size=(n, d)))
    w_sw[3] = np.inf                                       # a segment that is never a candidate
    s_sw = f32(rng.uniform(0.0, 3.0, (p, n)))
    s_sw[rng.random((p, n)) < 0.1] = np.inf
    w_sem = f32(rng.normal(size=(r, d)) - 0.5)
    sem_row = rng.integers(0, r, (p, e))
    s_sem = f32(rng.uniform(0.0, 3.0, (p, e)))
    s_sem[rng.random((p, e)) < 0.2] = np.inf
    x_cont = f32(rng.normal(size=(p, d)) + 1.0)
    x_cont[rng.random(p) < 0.3] = np.inf
    # twins: semantic row 0 equals switch row 5, at the same cost on the first points
    w_sem[0] = w_sw[5]
    sem_row[:5, 0] = 0
    s_sem[:5, 0] = s_sw[:5, 5] = 0.25
    w_sw[8] = w_sw[7]                                      # twin switches on some points
    s_sw[5:12, 8] = s_sw[5:12, 7]
    return PointCandidates(w_sw=w_sw, s_sw=s_sw, w_sem=w_sem, sem_row=sem_row, s_sem=s_sem,
                           x_cont=x_cont)


def brute_force(c: PointCandidates) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep masks by comparing every pair of candidates at every point in value space."""
    p_n, n = c.s_sw.shape
    e_n = c.s_sem.shape[1]
    keep_sw = np.zeros((p_n, n), bool)
    keep_sem = np.zeros((p_n, e_n), bool)
    keep_cont = np.zeros(p_n, bool)
    for i in range(p_n):
        xs, where = [], []
        for a in range(n):
            xs.append(c.s_sw[i, a] + c.w_sw[a])
            where.append((keep_sw, (i, a)))
        for j in range(e_n):
            xs.append(c.s_sem[i, j] + c.w_sem[c.sem_row[i, j]])
            where.append((keep_sem, (i, j)))
        xs.append(c.x_cont[i])
        where.append((keep_cont, (i,)))
        for q, (xq, (arr, idx)) in enumerate(zip(xs, where, strict=True)):
            if not np.all(np.isfinite(xq)):
                continue
            arr[idx] = not any(np.all(np.isfinite(xp)) and np.all(xp <= xq) and np.any(xp < xq)
                               for p, xp in enumerate(xs) if p != q)
    return keep_sw, keep_sem, keep_cont


def test_handicaps_are_max_and_min_differences() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(7, 3))
    b[2, 1] = np.nan
    g, h = handicaps(a, b, chunk_elems=8)                   # several blocks
    for p in range(5):
        for q in range(7):
            diff = a[p] - b[q]
            if q == 2:
                assert g[p, q] == np.inf and h[p, q] == np.inf
            else:
                assert g[p, q] == diff.max() and h[p, q] == diff.min()


@pytest.mark.parametrize(("top", "cheap"), [(1, 1), (3, 2), (14, 14)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_prune_equals_brute_force(top: int, cheap: int, seed: int) -> None:
    c = random_candidates(np.random.default_rng(seed))
    got = prune(c, top=top, cheap=cheap, batch=8)
    ref = brute_force(c)
    for mine, want in zip(got, ref, strict=True):
        np.testing.assert_array_equal(mine, want)
    keep_sw, keep_sem, _ = got
    # twins (same values) share their fate: ties are kept
    np.testing.assert_array_equal(keep_sw[:5, 5], keep_sem[:5, 0])
    np.testing.assert_array_equal(keep_sw[5:12, 7], keep_sw[5:12, 8])
    # the fixture is not trivial: both kinds of outcome occur for every kind of candidate
    n_present = np.isfinite(c.s_sw).sum() - np.isfinite(c.s_sw[:, 3]).sum()
    assert 0 < keep_sw.sum() < n_present
    assert 0 < keep_sem.sum() < np.isfinite(c.s_sem).sum()


def test_exact_twins_are_both_kept() -> None:
    # two candidates with the same values and nothing better: neither dominates the other
    w = f32(np.array([[1.0, 2.0], [1.0, 2.0], [3.0, 3.0]]))
    c = PointCandidates(w_sw=w, s_sw=f32(np.array([[0.5, 0.5, 0.1]])), w_sem=np.zeros((0, 2)),
                        sem_row=np.zeros((1, 0), np.int64), s_sem=np.zeros((1, 0)),
                        x_cont=np.array([[1.5, 2.6]]))
    keep_sw, _, keep_cont = prune(c)
    assert keep_sw.tolist() == [[True, True, False]]       # (3.1, 3.1) is dominated
    assert not keep_cont[0]                                # (1.5, 2.6) by the twins (1.5, 2.5)
    c.x_cont = np.array([[1.5, 2.5]])                      # a third twin
    keep_sw, _, keep_cont = prune(c)
    assert keep_sw.tolist() == [[True, True, False]] and keep_cont[0]
