"""MIMiC on the default library: build cost, graph figures, cut-point check, density truncation,
decision cost per call and variety behind the real timing layer (for BENCHMARKS.md).

    .venv/bin/python tools/mimic_bench.py [--library motion_library/default] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from gesture_sim.control.mimic import (
    MimicChooser,
    build_graph,
    exact_log_pdf,
    speed_minima,
)
from gesture_sim.control.synchrony import SpeechCue, SyncPlayer
from gesture_sim.loading import load_stack


def _us(ts: list[float]) -> dict:
    a = 1e6 * np.asarray(ts)
    return {"median_us": round(float(np.median(a)), 1),
            "p99_us": round(float(np.quantile(a, .99)), 1),
            "max_us": round(float(a.max()), 1), "calls": len(a)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--library", default="motion_library/default")
    ap.add_argument("--json")
    args = ap.parse_args()
    st = load_stack(args.library, policy=False)
    lib, model = st.control_library, st.state_model
    out: dict = {}

    builds = []
    for _ in range(3):
        t0 = time.perf_counter()
        g = build_graph(lib)
        builds.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    build_graph(lib, alpha=0.25)
    out["build_s"] = {"with_cv_median": round(float(np.median(builds)), 3),
                      "cv_s": round(g.meta["cv_s"], 3),
                      "thesis_alpha_no_cv": round(time.perf_counter() - t0, 3)}
    out["graph"] = {k: g.meta[k] for k in ("n_subsequences", "n_cut_points", "n_clusters",
                                           "pca_dims", "pca_energy", "alpha", "alpha_cv",
                                           "scott_factor", "kernels", "pool_starts_per_cluster")}
    out["graph"]["self_transition_share"] = float(np.trace(g.counts) / g.counts.sum())

    # are segment boundaries local minima of motion? pose speed (PCA units / frame)
    pca = g.pca()
    pool = np.nonzero(lib.cospeech)[0]
    ys = np.concatenate([pca.project(lib.features(int(i))) for i in pool])
    starts = np.cumsum(np.r_[0, lib.lengths[pool][:-1]])
    sp = np.r_[np.linalg.norm(ys[2:] - ys[:-2], axis=1) / 2, 0.0]
    sp = np.r_[np.linalg.norm(ys[1] - ys[0]), sp[:-1]]
    rank = np.argsort(np.argsort(sp)) / len(sp)
    mins = speed_minima(ys)
    near = [np.min(np.abs(mins - s)) <= 2 for s in starts]
    out["cut_points"] = {
        "boundary_speed_percentile_median": round(float(np.median(rank[starts])), 3),
        "boundary_speed_over_median_speed": round(float(np.median(sp[starts]) / np.median(sp)), 3),
        "boundaries_within_2_frames_of_a_speed_minimum": round(float(np.mean(near)), 3),
        "speed_minima_per_boundary": round(len(mins) / len(starts), 2),
    }

    # nearest-neighbour truncation of the run-time density (N_n = 32) vs the exact sum
    kde = g.motion_kde()
    rng = np.random.default_rng(0)
    q = g.kde_centres[rng.choice(len(g.kde_centres), 300, replace=False)].astype(float)
    q += 0.5 * kde.widths * rng.standard_normal(q.shape)
    approx = kde.log_pdf(q)
    exact = exact_log_pdf(g.kde_centres, kde.widths, q)
    err = np.abs(approx - exact)
    out["kde_truncation"] = {"median_abs_log_error": round(float(np.median(err)), 3),
                             "p90_abs_log_error": round(float(np.quantile(err, .9)), 3)}

    # decision cost per call
    ch = MimicChooser(g, lib, seed=0, model=model)
    S = model.n_states
    t_first, t_again, t_cont, t_start, t_sw = [], [], [], [], []
    for _rep, bucket in ((0, t_first), (1, t_again)):
        for a in pool:
            b = rng.dirichlet(np.ones(S))
            t0 = time.perf_counter()
            ch.decide_at(b, int(a), lib.n_interrupts, 0.0)
            bucket.append(time.perf_counter() - t0)
    for a in pool:
        b = rng.dirichlet(np.ones(S))
        t0 = time.perf_counter()
        ch.decide_at(b, int(a), 0, 0.0)
        t_cont.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ch.decide_at(b, int(a), 1, 0.0, prefer_switch=True)
        t_sw.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ch.decide_start(b, 0.0)
        t_start.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    MimicChooser(g, lib, seed=0, model=model)
    out["decision_cost"] = {"construct_ms": round(1e3 * (time.perf_counter() - t0), 2),
                            "end_first_call": _us(t_first), "end_cached": _us(t_again),
                            "interrupt_continue": _us(t_cont), "interrupt_switch": _us(t_sw),
                            "start": _us(t_start)}

    # behind the timing layer: 120 s of speech-like cues, random beliefs
    runs = {}
    for mw in (1.0, 0.0):
        for seed in (0, 1, 2):
            ch = MimicChooser(g, lib, seed=seed, model=model, motion_weight=mw)
            pl = SyncPlayer(lib, ch)
            r = np.random.default_rng(seed)
            steps = int(120 * lib.fps)
            tc, segs = 0.0, []
            for i in range(steps):
                t = i / lib.fps
                speaking = (i // 90) % 4 != 3
                cue = SpeechCue(speaking, 0.0 if speaking else (i % 90) / lib.fps,
                                [t] if speaking and r.random() < 0.1 else [], 0.0)
                t0 = time.perf_counter()
                s = pl.step(t, r.dirichlet(np.ones(S)), cue)
                tc += time.perf_counter() - t0
                segs.append(s.segment)
            dec = ch.decisions
            succ = np.mean([lib.successors[d0.segment_id] == d1.segment_id
                            for d0, d1 in zip(dec[:-1], dec[1:], strict=True)])
            ps = [d.costs["p"] for d in dec if "p" in d.costs]
            runs.setdefault(str(mw), []).append({
                "decisions": len(dec), "distinct_segments": len({x for x in segs if x >= 0}),
                "source_order_share": round(float(succ), 3),
                "median_p_chosen": round(float(np.median(ps)), 3),
                "player_step_us": round(1e6 * tc / steps, 1)})
    out["sync_runs_120s"] = runs
    text = json.dumps(out, indent=1)
    print(text)
    if args.json:
        with open(args.json, "w") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
