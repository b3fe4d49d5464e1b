"""Exact dominance pruning of the controller's candidate lists, in decomposed form (digest §6.4).

At a decision point every candidate e has a value vector ``x_e = s_e + W[row(e)]`` over the
``D = tones × hidden states`` coordinates: a scalar switch (jump) cost ``s_e`` plus a *row* of
values shared by every decision point (the value of entering a segment at frame 0, of entering a
semantic gesture at a given frame, of continuing). Candidate p *dominates* q when
``x_p <= x_q`` in every coordinate and ``x_p < x_q`` in at least one: q can then never be the argmin
of a belief-weighted, tone-blended sum and is dropped. Exact twins dominate neither (ties kept).

The check never builds the (points × candidates × D) table. With the *handicaps*
``G[p, q] = max_d (W_p − W_q)`` and ``H[p, q] = min_d (W_p − W_q)`` between rows,
p dominates q iff ``s_p + G[p, q] <= s_q`` and ``s_p + H[p, q] < s_q``. Per batch of points:

0. a bound: the candidate with the smallest ``max_d x`` strictly dominates every candidate whose
   ``min_d x`` is larger (removes, e.g., all plain switches while a semantic label is pending);
1. for each remaining candidate, the ``top`` switches of smallest handicap to it are tried
   (most dominated switches fall here); a survivor is *certified* against every switch when even
   the cheapest switch with the ``top``-th smallest handicap could not dominate it;
2. the uncertified candidates are compared with all remaining ones, the certified ones with the
   remaining semantic and continue candidates.

Every candidate removed is dominated; a dominated candidate is dominated by an undominated one
(finite strict partial order), which survives stages 0 and 1 and is among those compared in stage
2, so each survivor is undominated: the result is exactly the non-dominated set. With
float32-rounded inputs all sums are exact in float64, so the comparisons are exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def handicaps(wp: np.ndarray, wq: np.ndarray,
              chunk_elems: int = 2_000_000) -> tuple[np.ndarray, np.ndarray]:
    """Max and min coordinate differences between two sets of rows.

    Args:
        wp: (P, D) rows; wq: (Q, D) rows.
        chunk_elems: elements per block of the (P, Q) work arrays.

    Returns:
        G (P, Q) with ``G[p, q] = max_d (wp[p, d] - wq[q, d])`` and H (P, Q) with the min;
        ``+inf`` in both wherever either row is not finite.
    """
    p_n, d_n = wp.shape
    q_n = len(wq)
    fp = np.all(np.isfinite(wp), axis=1)
    fq = np.all(np.isfinite(wq), axis=1)
    a = np.where(fp[:, None], wp, 0.0)
    b = np.where(fq[:, None], wq, 0.0)
    g = np.empty((p_n, q_n))
    h = np.empty((p_n, q_n))
    step = max(1, chunk_elems // max(1, q_n))
    for lo in range(0, p_n, step):
        blk = a[lo:lo + step]
        gg = blk[:, 0, None] - b[None, :, 0]
        hh = gg.copy()
        for d in range(1, d_n):
            diff = blk[:, d, None] - b[None, :, d]
            np.maximum(gg, diff, out=gg)
            np.minimum(hh, diff, out=hh)
        g[lo:lo + step] = gg
        h[lo:lo + step] = hh
    g[~fp] = np.inf
    g[:, ~fq] = np.inf
    h[~fp] = np.inf
    h[:, ~fq] = np.inf
    return g, h


@dataclass
class PointCandidates:
    """The candidates of one label state at P decision points, in decomposed form.

    Attributes:
        w_sw: (n, D) switch rows (value of entering segment a' at frame 0); a non-finite row is
            never a candidate.
        s_sw: (P, n) switch cost of each switch at each point (``inf``: not allowed).
        w_sem: (R, D) semantic rows (value of entering a target at a given frame).
        sem_row: (P, E) index into ``w_sem`` of each semantic candidate.
        s_sem: (P, E) its jump cost (``inf``: absent).
        x_cont: (P, D) value of continuing (a non-finite row: no continue at that point).
    """

    w_sw: np.ndarray
    s_sw: np.ndarray
    w_sem: np.ndarray
    sem_row: np.ndarray
    s_sem: np.ndarray
    x_cont: np.ndarray


def _first_true(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column indices (B, m) of the True entries of each row of ``mask``, left-aligned and
    padded with 0, and their validity (B, m)."""
    bi, ci = np.nonzero(mask)
    counts = mask.sum(axis=1)
    m = int(counts.max(initial=0))
    pos = np.arange(len(bi)) - (np.cumsum(counts) - counts)[bi]
    idx = np.zeros((len(mask), m), np.int64)
    valid = np.zeros((len(mask), m), bool)
    idx[bi, pos] = ci
    valid[bi, pos] = True
    return idx, valid


def _versus_point(xc: np.ndarray, s: np.ndarray, rows: np.ndarray,
                  wt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dominance between one vector per point and that point's row candidates (value space).

    Args:
        xc: (B, D) one value vector per point (e.g. the continue).
        s: (B, C) switch costs and rows: (B, C) row indices of the candidates;
        wt: (D, Rg) the rows, transposed.

    Returns:
        (B, C) masks: ``xc`` dominates the candidate, and the candidate dominates ``xc``.
    """
    le1 = np.ones(s.shape, bool)
    lt1 = np.zeros(s.shape, bool)
    le2 = np.ones(s.shape, bool)
    lt2 = np.zeros(s.shape, bool)
    for d in range(len(wt)):
        x = s + wt[d][rows]
        c = xc[:, d, None]
        le1 &= c <= x
        lt1 |= c < x
        le2 &= x <= c
        lt2 |= x < c
    return le1 & lt1, le2 & lt2


def prune(c: PointCandidates, top: int = 24, cheap: int = 16,
          batch: int = 128) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The non-dominated candidates at every point (see the module docstring).

    Args:
        c: the candidates.
        top: switch dominators of smallest handicap tried in stage 1 per candidate;
        cheap: switches of smallest cost tried for the candidates ``top`` does not certify
            (both speed settings; the result is exact for any values).
        batch: points per vectorised block.

    Returns:
        keep_sw (P, n), keep_sem (P, E) and keep_cont (P,) boolean masks of the survivors
        (absent candidates are False).
    """
    n, d_n = c.w_sw.shape
    p_n, e_n = c.s_sem.shape
    wg = np.concatenate([c.w_sw, c.w_sem]) if len(c.w_sem) else c.w_sw
    fin_g = np.all(np.isfinite(wg), axis=1)
    wt = np.ascontiguousarray(np.where(fin_g[:, None], wg, np.inf).T)      # (D, Rg)
    g, h = handicaps(wg, wg)
    wmax = np.where(fin_g, np.max(np.where(fin_g[:, None], wg, 0.0), axis=1), np.inf)
    wmin = np.where(fin_g, np.min(np.where(fin_g[:, None], wg, 0.0), axis=1), np.inf)
    # switch dominators with the smallest handicap, per row dominated
    top = min(top, n)
    gt = g[:n].T.copy()                                           # (Rg, n): gt[q, p] = G[p, q]
    gt[np.arange(n), np.arange(n)] = np.inf        # a switch is not its own dominator
    pidx = (np.argpartition(gt, top - 1, axis=1)[:, :top] if top < n
            else np.tile(np.arange(n), (len(wg), 1)))
    gval = np.take_along_axis(gt, pidx, axis=1)
    hval = h[pidx, np.arange(len(wg))[:, None]]
    gkth = gval.max(axis=1) if top < n else np.full(len(wg), np.inf)

    keep_sw = np.zeros((p_n, n), bool)
    keep_sem = np.zeros((p_n, e_n), bool)
    keep_cont = np.zeros(p_n, bool)
    sw_rows = np.arange(n)
    for lo in range(0, p_n, batch):
        sl = slice(lo, lo + batch)
        s_sw = c.s_sw[sl]
        b_n = len(s_sw)
        rows = np.concatenate([np.broadcast_to(sw_rows, (b_n, n)), n + c.sem_row[sl]], axis=1)
        s = np.concatenate([s_sw, c.s_sem[sl]], axis=1)          # (B, C)
        present = np.isfinite(s) & fin_g[rows]
        s = np.where(present, s, np.inf)
        xc = c.x_cont[sl]
        cpres = np.all(np.isfinite(xc), axis=1)
        cmax = np.where(cpres, np.max(np.where(cpres[:, None], xc, 0.0), axis=1), np.inf)
        cmin = np.where(cpres, np.min(np.where(cpres[:, None], xc, 0.0), axis=1), np.inf)
        xmax = s + wmax[rows]
        xmin = s + wmin[rows]

        # stage 0: min over candidates of max_d x bounds everything above it
        bound = np.minimum(xmax.min(axis=1), cmax)
        alive = present & (xmin <= bound[:, None])
        calive = cpres & (cmin <= bound)

        # the continue (one per point, often strong) against the others, in value space
        c_dom, dom_c = _versus_point(np.where(calive[:, None], xc, np.inf), s, rows, wt)
        alive &= ~c_dom

        # stage 1: the `top` switches of smallest handicap (a switch p can dominate q only if
        # max_d x_p <= max_d x_q); a survivor q is *certified* against all switches when no
        # other switch can beat it either: min_p s_p + (top-th smallest handicap) > s_q
        ssw = s[:, :n]
        sw_floor = xmax[:, :n].min(axis=1)
        s_min = ssw.min(axis=1)
        check = alive & (xmax >= sw_floor[:, None])
        dom = np.zeros(alive.shape, bool)
        bi, ci = np.nonzero(check[:, :n])                           # switches still checked
        if len(bi):
            sq = ssw[bi, ci]
            sp = ssw[bi[:, None], pidx[ci]] + gval[ci]              # (m, top)
            hit = np.any(sp < sq[:, None], axis=1)
            mi, ti = np.nonzero((sp == sq[:, None]) & np.isfinite(sp))   # ties
            strict = ssw[bi[mi], pidx[ci[mi], ti]] + hval[ci[mi], ti] < sq[mi]
            hit[mi[strict]] = True
            dom[bi[hit], ci[hit]] = True
        cert = ~check | (s_min[:, None] + gkth[rows] > s)
        if e_n:
            bi, ci = np.nonzero(check[:, n:])
            ci += n
            r, sq = rows[bi, ci], s[bi, ci]
            sp = ssw[bi[:, None], pidx[r]]                          # (m, top)
            dom[bi, ci] = np.any((sp + gval[r] <= sq[:, None]) & (sp + hval[r] < sq[:, None]),
                                 axis=1)
        alive &= ~dom
        # a second try for the uncertified: the `cheap` least costly switches at the point,
        # exactly (a switch in neither list costs >= the cheap-th smallest cost and has a
        # handicap >= the top-th smallest)
        bi, ci = np.nonzero(alive & ~cert)
        if len(bi):
            t = min(cheap, n)
            ts = np.argpartition(ssw, t - 1, axis=1)[:, :t]        # (B, t)
            s_t = np.take_along_axis(ssw, ts, 1).max(axis=1)
            r, sq = rows[bi, ci], s[bi, ci]
            pp = ts[bi]                                            # (m, t)
            spp = ssw[bi[:, None], pp]
            x = spp + g[pp, r[:, None]]
            dom2 = np.any(x < sq[:, None], axis=1)
            mi, ti = np.nonzero((x == sq[:, None]) & np.isfinite(x))  # ties (itself included)
            tie = spp[mi, ti] + h[pp[mi, ti], r[mi]] < sq[mi]
            dom2[mi[tie]] = True
            alive[bi[dom2], ci[dom2]] = False
            cert[bi, ci] |= s_t[bi] + gkth[r] > sq

        # stage 2: the uncertified candidates against all others, the certified ones against
        # the semantic candidates; the others against the continue (value space)
        dead = _killed(alive, alive & ~cert, rows, s, g, h)
        if e_n:
            sem_only = alive.copy()
            sem_only[:, :n] = False
            dead |= _killed(sem_only, alive & cert, rows, s, g, h)
        alive &= ~dead
        calive &= ~np.any(dom_c & alive, axis=1)
        keep_sw[sl] = alive[:, :n]
        keep_sem[sl] = alive[:, n:]
        keep_cont[sl] = calive
    return keep_sw, keep_sem, keep_cont


def far_switches(s_sw: np.ndarray, w_sw: np.ndarray, per_reference: int = 32,
                 n_mixed: int = 13, batch: int = 64, seed: int = 0) -> np.ndarray:
    """(P, n) mask of the switch candidates kept by the far-successor cap (an approximation).

    At each point the value vector of switch q is ``x_q = s_sw[p, q] + w_sw[q]`` (D coordinates:
    tones × hidden states). A switch is kept when it is among the ``per_reference`` best in at
    least one *reference weighting*: each coordinate alone (a belief sure of one state, in one
    tone), their mean, and ``n_mixed`` fixed random convex weightings (Dirichlet(1), ``seed``).
    So every vertex of the weight simplex keeps its best switches, and the argmin for a mixed
    belief is lost only when it is in no list; the regret this causes is measured in
    BENCHMARKS.md ("Training cost"). At most ``(D + 1 + n_mixed) * per_reference``
    switches per point survive, so the exact dominance pruning afterwards costs
    O(points × per_reference²)-ish instead of growing with n² per point.

    Args:
        s_sw: (P, n) switch costs (``inf``: not allowed); w_sw: (n, D) switch rows (a
            non-finite row is never a candidate).
        per_reference: switches kept per reference weighting.
        n_mixed: random interior weightings besides the D vertices and the mean.
        batch: points per vectorised block; seed: of the random weightings.

    Returns:
        (P, n) bool, True for the kept (present) switches.
    """
    p_n, n = s_sw.shape
    keep = np.zeros((p_n, n), bool)
    fin = np.all(np.isfinite(w_sw), axis=1)
    d_n = w_sw.shape[1]
    mix = np.random.default_rng(seed).dirichlet(np.ones(d_n), size=n_mixed)          # (R, D)
    refs = np.concatenate([np.eye(d_n), np.full((1, d_n), 1.0 / d_n), mix]) @ np.where(
        fin[:, None], w_sw, 0.0).T                                                 # (D+1+R, n)
    refs[:, ~fin] = np.inf
    t = min(per_reference, n)
    for lo in range(0, p_n, batch):
        s = s_sw[lo:lo + batch]
        rows = np.arange(len(s))[:, None]
        present = np.isfinite(s) & fin[None, :]
        for ref in refs:
            x = s + ref[None, :]
            if t < n:
                idx = np.argpartition(x, t - 1, axis=1)[:, :t]
                keep[lo + rows, idx] = True
            else:
                keep[lo:lo + batch] = True
        keep[lo:lo + batch] &= present
    return keep


def _killed(dmask: np.ndarray, qmask: np.ndarray, rows: np.ndarray, s: np.ndarray,
            g: np.ndarray, h: np.ndarray, max_elems: int = 1_000_000) -> np.ndarray:
    """(B, C) mask of the candidates in ``qmask`` dominated by a candidate in ``dmask``.

    Args:
        dmask, qmask: (B, C) dominator and dominated candidates at B points.
        rows: (B, C) their rows; s: (B, C) their switch costs.
        g, h: (Rg, Rg) handicaps between the rows.
    """
    dead = np.zeros(qmask.shape, bool)
    bq, cq = np.nonzero(qmask)
    if not len(bq) or not dmask.any():
        return dead
    n_rows = len(g)
    g_flat = g.reshape(-1)
    di, dv = _first_true(dmask)                                     # (B, X) dominators
    dr = np.take_along_axis(rows, di, 1)
    ds = np.where(dv, np.take_along_axis(s, di, 1), np.inf)
    rq, sq = rows[bq, cq], s[bq, cq]
    step = max(1, max_elems // max(1, di.shape[1]))
    for lo in range(0, len(bq), step):
        b, c, r, q = bq[lo:lo + step], cq[lo:lo + step], rq[lo:lo + step], sq[lo:lo + step]
        pr, ps = dr[b], ds[b]                                       # (m, X)
        ok = dv[b] & (di[b] != c[:, None])                          # not against itself
        x = ps + np.take(g_flat, pr * n_rows + r[:, None])
        # s_p + G < s_q is strict somewhere already; s_p + G == s_q needs H (twins are kept)
        hit = np.any((x < q[:, None]) & ok, axis=1)
        mi, ti = np.nonzero((x == q[:, None]) & ok)
        strict = ps[mi, ti] + h[pr[mi, ti], r[mi]] < q[mi]
        hit[mi[strict]] = True
        dead[b[hit], c[hit]] = True
    return dead
