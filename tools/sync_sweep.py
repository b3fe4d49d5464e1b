"""Coupling of the timing layer's settings on speech files, fast (kinematic targets).

    .venv/bin/python tools/sync_sweep.py AUDIO... [--seeds 3] [--methods controller random ...]
        [--set lead_s=0.08 --set rate_max=2.0 ...] [--physics]

Runs :func:`gesture_sim.app.evaluation.evaluate` with the kinematic targets on the standing
body (``--physics`` for the simulated body) and prints the coupling figures per method with
their seed spreads: how the timing layer's settings (:class:`SyncSettings`) were chosen.
"""

from __future__ import annotations

import argparse
import dataclasses

from gesture_sim.app.evaluation import Evaluator, evaluate
from gesture_sim.control.synchrony import SyncSettings

KEYS = ("bc_excess", "beat_align", "accent_hit_rate", "r_intensity_best", "r_f0d_best",
        "stress_hit_rate", "hellinger_speed", "mean_jerk")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("audio", nargs="+")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--methods", nargs="+",
                    default=["controller", "random", "random_sync", "mismatched"])
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--physics", action="store_true")
    ap.add_argument("--textgrid", action="append", default=[], metavar="FILE")
    args = ap.parse_args()
    values = {}
    for item in args.set:
        name, value = item.split("=", 1)
        values[name] = float(value)
    settings = dataclasses.replace(SyncSettings(), **values)
    ev = Evaluator(physics=args.physics)
    ev.pipeline_options = {"sync": settings}
    res = evaluate(args.audio, methods=args.methods, seeds=args.seeds, evaluator=ev,
                   textgrids=args.textgrid)
    summ = res.summary()
    print("settings", values or "default")
    print(f"{'method':12s}" + "".join(f"{k[:18]:>20s}" for k in KEYS))
    for m in res.methods:
        cells = []
        for k in KEYS:
            e = summ[m].get(k, {})
            mean, sd = e.get("mean", float("nan")), e.get("seed_sd", float("nan"))
            cells.append(f"{mean:9.3f} ±{sd:6.3f}  ")
        print(f"{m:12s}" + "".join(f"{c:>20s}" for c in cells))


if __name__ == "__main__":
    main()
