#!/usr/bin/env python3
"""Merge ``gesture-sim bench train --json`` outputs; print the BENCHMARKS.md table; draw the figure.

Usage (from the repository root):

    .venv/bin/python tools/train_scale_figure.py RUN.json [RUN.json ...] \\
        [--figure docs/figures/train_scale.png]

Rows of every file are merged and sorted by corpus length (e.g. one run for 5/15/30 minutes and
one for 60 minutes made side by side). The table gives, per stage, the CPU seconds of the
stage's process (one thread: the figure for one core even on a loaded machine), the wall
seconds in parentheses, and each stage's peak resident memory; then the growth exponent of each
stage's CPU time in the corpus length (log-log slope, 1 = linear).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="JSON outputs of `gesture-sim bench train`")
    parser.add_argument("--figure", default=None, help="PNG to write")
    args = parser.parse_args(argv)

    from gesture_sim.commands.bench.train import STAGES, draw_figure, growth_exponents

    rows = []
    for path in args.runs:
        with open(path, encoding="utf-8") as fh:
            rows += json.load(fh)["rows"]
    rows.sort(key=lambda r: r["corpus_s"])
    key = "cpu_seconds" if all("cpu_seconds" in r["stages"]["hmm"] for r in rows) else "seconds"
    print("| minutes | segments | states | " + " | ".join(STAGES)
          + " | total CPU s (wall) | peak MB | decision ms median / p99 |")
    print("| --- " * (len(STAGES) + 6) + "|")
    for r in rows:
        cells = [f"{r['stages'][s][key]:.1f} ({r['stages'][s]['seconds']:.1f})" for s in STAGES]
        total = sum(r["stages"][s][key] for s in STAGES)
        print(f"| {r['corpus_s'] / 60:.0f} | {r['segments']} | {r['states']} | "
              + " | ".join(cells)
              + f" | {total:.0f} ({r['total_s']:.0f}) | {r['peak_mb']:.0f} | "
              f"{r['decision_ms_median']:.3f} / {r['decision_ms_p99']:.3f} |")
    print()
    print("| minutes | " + " | ".join(f"{s} MB" for s in STAGES) + " |")
    print("| --- " * (len(STAGES) + 1) + "|")
    for r in rows:
        print(f"| {r['corpus_s'] / 60:.0f} | "
              + " | ".join(f"{r['stages'][s]['peak_mb']:.0f}" for s in STAGES) + " |")
    if len(rows) > 1:
        x = np.log([r["corpus_s"] for r in rows])
        slopes = {}
        for s in STAGES:
            y = [r["stages"][s][key] for r in rows]
            if min(y) > 0:
                slopes[s] = float(np.polyfit(x, np.log(y), 1)[0])
        print()
        print("growth exponents (" + key + "): "
              + ", ".join(f"{k} {v:.2f}" for k, v in slopes.items()))
        print("wall-time exponents: " + ", ".join(
            f"{k} {v:.2f}" for k, v in growth_exponents(rows).items()))
    if args.figure:
        draw_figure({"rows": rows}, args.figure)
        print(f"figure: {args.figure}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
