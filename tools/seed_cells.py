"""The issue-11 cell test on a saved `gesture-sim eval motion --report DIR` report, for all its
seeds and for subsets of them (how much a 3-seed verdict depends on which three seeds).

    .venv/bin/python tools/seed_cells.py DIR/report.json [--subset 3] [--subset 5]

For each file and each of BC − chance, accent hits and r(speed, intensity): the controller's
margin over random selection and over mismatched audio, against the larger seed spread (sample
SD) of the pair, ✓ when the margin exceeds it — the same test as `tools/sync_cells.py`. Then,
for consecutive blocks of ``--subset`` seeds (0–2, 3–5, …), how many comparisons and cells pass.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

CELLS = ("bc_excess", "accent_hit_rate", "r_intensity_best")
METHODS = ("controller", "random", "mismatched")


def cells(rows: list[dict], seeds: list[int]) -> tuple[int, int, int, list[str]]:
    """(comparisons passed, comparisons, cells passed, one markdown row per file)."""
    passed = total = cells_ok = 0
    lines = []
    for audio in sorted({r["audio"] for r in rows}):
        parts_all = []
        for k in CELLS:
            v = {m: np.array([r["metrics"].get(k, np.nan) for r in rows
                              if r["audio"] == audio and r["method"] == m and r["seed"] in seeds])
                 for m in METHODS}
            c = float(np.nanmean(v["controller"]))
            ok_cell, parts = True, []
            for base in ("random", "mismatched"):
                margin = c - float(np.nanmean(v[base]))
                spread = max(np.nanstd(v["controller"], ddof=1), np.nanstd(v[base], ddof=1))
                ok = bool(margin > spread)
                passed += ok
                total += 1
                ok_cell &= ok
                parts.append(f"{margin:+.3f} [{spread:.3f}] {'✓' if ok else '✗'}")
            cells_ok += ok_cell
            parts_all.append(f"{c:.3f}: " + " / ".join(parts))
        lines.append(f"| {audio} | " + " | ".join(parts_all) + " |")
    return passed, total, cells_ok, lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report", help="report.json of gesture-sim eval motion --report")
    ap.add_argument("--subset", type=int, action="append", default=[],
                    help="also test consecutive blocks of this many seeds (repeatable)")
    args = ap.parse_args()
    rows = json.loads(open(args.report, encoding="utf-8").read())["rows"]
    seeds = sorted({int(r["seed"]) for r in rows})
    p, t, c, lines = cells(rows, seeds)
    print(f"seeds {seeds[0]}-{seeds[-1]}: comparisons {p}/{t}, cells {c}/{t // 2}")
    print("\n".join(lines))
    for size in args.subset:
        for i in range(0, len(seeds) - size + 1, size):
            sub = seeds[i:i + size]
            p, t, c, _ = cells(rows, sub)
            print(f"seeds {sub[0]}-{sub[-1]}: comparisons {p}/{t}, cells {c}/{t // 2}")


if __name__ == "__main__":
    main()
