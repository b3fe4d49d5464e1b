"""Per-file coupling cells of the timing layer's settings (kinematic, fast).

    .venv/bin/python tools/sync_cells.py AUDIO... [--textgrid F ...] [--seeds 3]
        [--set NAME=VALUE ...] [--physics]

For each file and each of BC − chance, accent hits and r(speed, intensity): the controller's
margin over random selection and over mismatched audio, against the larger seed spread of the
pair (the issue-11 cell test of `tools/seed_cells.py`), and how many of the cells pass; then
the means over files (with accent hits − chance and stress hits).
"""

from __future__ import annotations

import argparse
import dataclasses

from seed_cells import cells

from gesture_sim.app.evaluation import Evaluator, evaluate
from gesture_sim.control.synchrony import SyncSettings
from gesture_sim.metrics.summary import DECISIVE_KEYS


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("audio", nargs="+")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--physics", action="store_true")
    ap.add_argument("--textgrid", action="append", default=[], metavar="FILE")
    args = ap.parse_args()
    values = {k: float(v) for k, v in (item.split("=", 1) for item in args.set)}
    ev = Evaluator(physics=args.physics)
    ev.pipeline_options = {"sync": dataclasses.replace(SyncSettings(), **values)}
    methods = ["controller", "random", "mismatched"]
    res = evaluate(args.audio, methods=methods, seeds=args.seeds, evaluator=ev,
                   textgrids=args.textgrid)
    print("settings", values or "default")
    passed, total, _, lines = cells(res.rows)
    print("\n".join(lines))
    summ = res.summary()
    print(f"cells passed {passed}/{total}")
    for m in methods:
        keys = (*DECISIVE_KEYS, "accent_hit_rate", "stress_hit_excess")
        print(f"{m:11s} " + " ".join(f"{k}={summ[m][k]['mean']:.3f}±{summ[m][k]['seed_sd']:.3f}"
                                     for k in keys if k in summ[m]))


if __name__ == "__main__":
    main()
