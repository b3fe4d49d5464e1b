"""The per-file coupling test on a saved `gesture-sim eval motion --report DIR` report, for all
its seeds and for blocks of them (how much a 3-seed verdict depends on which three seeds).

    .venv/bin/python tools/seed_cells.py DIR/report.json [--subset 3] [--subset 5]

For each file and each of BC − chance, accent hits and r(speed, intensity): the controller's
margin over random selection and over mismatched audio, against the larger seed spread of the
pair, ✓ when the margin exceeds it (`eval`'s verdict rule,
:func:`gesture_sim.metrics.summary.coupling_verdicts`, on that file's rows alone). Then, for
consecutive blocks of ``--subset`` seeds (0–2, 3–5, …), how many comparisons and cells pass.
:func:`cells` is also the test of `tools/sync_cells.py`.
"""

from __future__ import annotations

import argparse
import json

from gesture_sim.metrics.summary import DECISIVE_KEYS, coupling_verdicts, summarise_rows

METHODS = ("controller", "random", "mismatched")
BASELINES = ("random", "mismatched")


def cells(rows: list[dict], method: str = "controller") -> tuple[int, int, int, list[str]]:
    """(comparisons passed, comparisons, cells passed, one markdown row per file) of ``method``
    on :data:`DECISIVE_KEYS`, each file judged on its own rows."""
    passed = total = cells_ok = 0
    lines = []
    for audio in sorted({r["audio"] for r in rows}):
        summary = summarise_rows([r for r in rows if r["audio"] == audio], METHODS)
        figures = coupling_verdicts(summary, BASELINES)[method]["figures"]
        parts_all = []
        for key in DECISIVE_KEYS:
            row = figures[key]
            parts = []
            for b in BASELINES:
                passed += row[f"beats_{b}"]
                total += 1
                parts.append(f"{row[f'margin_{b}']:+.3f} [{row[f'spread_{b}']:.3f}] "
                             f"{'✓' if row[f'beats_{b}'] else '✗'}")
            cells_ok += row["beats_all"]
            parts_all.append(f"{summary[method][key]['mean']:.3f}: " + " / ".join(parts))
        lines.append(f"| {audio} | " + " | ".join(parts_all) + " |")
    return passed, total, cells_ok, lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report", help="report.json of gesture-sim eval motion --report")
    ap.add_argument("--subset", type=int, action="append", default=[],
                    help="also test consecutive blocks of this many seeds (repeatable)")
    args = ap.parse_args()
    with open(args.report, encoding="utf-8") as fh:
        rows = json.load(fh)["rows"]
    seeds = sorted({int(r["seed"]) for r in rows})
    p, t, c, lines = cells(rows)
    print(f"seeds {seeds[0]}-{seeds[-1]}: comparisons {p}/{t}, cells {c}/{t // 2}")
    print("\n".join(lines))
    for size in args.subset:
        for i in range(0, len(seeds) - size + 1, size):
            sub = set(seeds[i:i + size])
            p, t, c, _ = cells([r for r in rows if r["seed"] in sub])
            print(f"seeds {min(sub)}-{max(sub)}: comparisons {p}/{t}, cells {c}/{t // 2}")


if __name__ == "__main__":
    main()
