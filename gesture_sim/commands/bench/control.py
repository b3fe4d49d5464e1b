"""``gesture-sim bench control``: MDP training time and memory against library length.

Trains the gesture-controller MDP (one tone, no labels: the paper's Table 1 setting) on libraries
of increasing length and reports the time, the growth exponent (log-log fit), the ratio to the
paper's training times (Levine et al. 2010, Table 1, Core i7 2.66 GHz), the peak memory, the size
of the stored policy file and the cost of one online decision. Libraries: the real library
(``--library FOLDER``) with its segments resampled (drawn with replacement) to each target
length, or synthetic libraries with realistic segment statistics (~0.6 s median at 30 fps) when
no library is given.
"""

from __future__ import annotations

import argparse

from gesture_sim.commands import print_json

#: Table 1 of the paper: library length (s) -> MDP training time (s).
PAPER_TABLE1 = {51.0: 7.0, 160.0: 230.0, 240.0: 372.0, 352.0: 725.0, 706.0: 4110.0}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("control", help="MDP value-iteration time and memory vs library length",
                       description=__doc__.split("\n\n")[1])
    p.add_argument("--lengths", type=float, nargs="+", default=sorted(PAPER_TABLE1),
                   help="library lengths in seconds (default: the paper's Table 1 sizes)")
    p.add_argument("--library", default=None,
                   help="motion library folder whose segments are resampled (default: synthetic)")
    p.add_argument("--states", type=int, default=10, help="hidden states of the model (10)")
    p.add_argument("--decisions", type=int, default=20000, help="online decisions to time")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-memory", action="store_true",
                   help="skip the second, memory-traced training run")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def _resampled(lib, seconds: float, seed: int):
    """A ControlLibrary of about ``seconds`` built from segments of ``lib`` drawn at random."""
    import numpy as np

    from gesture_sim.control.inputs import ControlLibrary, array_fingerprint

    rng = np.random.default_rng(seed)
    target = seconds * lib.fps
    idx: list[int] = []
    total = 0
    while total < target:
        i = int(rng.integers(lib.n_segments))
        idx.append(i)
        total += int(lib.lengths[i])
    ix = np.array(idx)
    return ControlLibrary(
        lengths=lib.lengths[ix], interrupt_frames=lib.interrupt_frames[ix], params=lib.params[ix],
        d_sp=lib.d_sp[np.ix_(ix, ix)], d_in=lib.d_in[ix][:, :, ix],
        tags=tuple(lib.tags[i] for i in ix), fps=lib.fps,
        fingerprint=array_fingerprint(ix, extra=lib.fingerprint))


def run(args: argparse.Namespace) -> int:
    import os
    import resource
    import tempfile
    import time
    import tracemalloc

    import numpy as np

    from gesture_sim.control.controller import GestureController
    from gesture_sim.control.costs import ControlSettings
    from gesture_sim.control.policy import train_policy
    from gesture_sim.progress import progress
    from gesture_sim.testing.synthetic import synthetic_library, synthetic_model

    base = None
    if args.library:
        from gesture_sim.control.inputs import ControlLibrary
        from gesture_sim.motion.library import MotionLibrary
        base = ControlLibrary.from_motion_library(MotionLibrary.load(args.library))
    rows = []
    for seconds in progress(sorted(args.lengths), desc="bench control", unit="lib"):
        lib = (_resampled(base, seconds, args.seed) if base is not None
               else synthetic_library(seconds, seed=args.seed))
        model = synthetic_model(lib if base is None else base, n_states=args.states,
                                seed=args.seed)
        t0 = time.perf_counter()
        policy = train_policy(lib, model, ControlSettings())
        train_s = time.perf_counter() - t0
        peak = 0
        if not args.no_memory:          # a second, traced run: tracemalloc slows numpy down
            tracemalloc.start()
            train_policy(lib, model, ControlSettings())
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
        with tempfile.TemporaryDirectory() as tmp:
            policy.save(os.path.join(tmp, "policy.npz"))
            file_mb = os.path.getsize(os.path.join(tmp, "policy.npz")) / 1e6
        # online decisions: random decision points and beliefs
        ctl = GestureController(policy, lib)
        rng = np.random.default_rng(args.seed)
        pts = np.argwhere(np.diff(policy.offsets[0]) > 0)[:, 0]
        pick = pts[rng.integers(len(pts), size=args.decisions)]
        beliefs = rng.dirichlet(np.ones(policy.n_states), size=args.decisions)
        t1 = time.perf_counter()
        for j, b in zip(pick, beliefs, strict=True):
            seg, k = divmod(int(j), policy.n_points)
            ctl.decide_at(b, seg, k, 0.0)
        decision_us = (time.perf_counter() - t1) / args.decisions * 1e6
        paper = PAPER_TABLE1.get(float(seconds))
        rows.append({
            "library_s": seconds, "segments": lib.n_segments, "train_s": train_s,
            "solve_s": policy.meta["solve_seconds"], "table_s": policy.meta["table_seconds"],
            "iterations": policy.meta["iterations"]["neutral/-"],
            "error_bound": policy.meta["error_bound"],
            "pruned_fraction": policy.meta["pruned_fraction"],
            "entries": policy.meta["entries_after_pruning"],
            "peak_traced_mb": peak / 2**20, "policy_file_mb": file_mb,
            "decision_us": decision_us,
            "paper_s": paper, "speedup_vs_paper": (paper / train_s) if paper else None,
        })
    x = np.log([r["library_s"] for r in rows])
    y = np.log([r["train_s"] for r in rows])
    exponent = float(np.polyfit(x, y, 1)[0]) if len(rows) > 1 else float("nan")
    px = [r["library_s"] for r in rows if r["paper_s"]]
    paper_exp = (float(np.polyfit(np.log(px), np.log([PAPER_TABLE1[s] for s in px]), 1)[0])
                 if len(px) > 1 else float("nan"))
    out = {"source": args.library or "synthetic", "states": args.states, "rows": rows,
           "growth_exponent": exponent, "paper_growth_exponent": paper_exp,
           "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    if args.json:
        print_json(out)
        return 0
    print(f"MDP training vs library length ({out['source']}, {args.states} states, one core)")
    print(f"{'library':>8} {'segs':>5} {'train s':>8} {'solve s':>8} {'table s':>8} "
          f"{'pruned':>7} {'peak MB':>8} {'file MB':>7} {'decide us':>9} {'paper s':>8} "
          f"{'speedup':>8}")
    for r in rows:
        sp = f"{r['speedup_vs_paper']:.0f}x" if r["speedup_vs_paper"] else "-"
        print(f"{r['library_s']:>7.0f}s {r['segments']:>5} {r['train_s']:>8.2f} "
              f"{r['solve_s']:>8.2f} {r['table_s']:>8.2f} {r['pruned_fraction']:>7.1%} "
              f"{r['peak_traced_mb']:>8.0f} {r['policy_file_mb']:>7.2f} "
              f"{r['decision_us']:>9.1f} "
              f"{r['paper_s'] or float('nan'):>8.0f} {sp:>8}")
    print(f"growth exponent {exponent:.2f} (paper {paper_exp:.2f}); "
          f"max RSS {out['max_rss_mb']:.0f} MB")
    return 0
