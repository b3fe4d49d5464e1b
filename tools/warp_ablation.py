#!/usr/bin/env python3
"""Which of the timing layer's warps costs most naturalness? (issue 31 item 2)

    .venv/bin/python tools/warp_ablation.py AUDIO... [--textgrid TG ...] [--seeds 3]
        [--variants all|NAME ...] [--physics] [--json OUT]

The timing layer (:mod:`gesture_sim.control.synchrony`) buys its coupling with warps of the
real clips it plays: faster playback into a stroke (``rate_max``), skipped preparations
(``skip_after_s``), pre-stroke holds (``hold_max_s``, ``hold_rate``), the energy's playback
rate (``energy_rate``) and amplitude (``energy_gain``, ``gain_range``, smoothed over
``gain_tau_s``). Each variant switches one of them off (the smoothing: back to none, as
before stop 41); every variant runs the controller (and ``random_sync`` for the same
warps on random choice) through :func:`gesture_sim.app.evaluation.evaluate` — kinematic
targets unless ``--physics`` — and the table shows, per variant, the coupling (accent hits − chance,
BC − chance, r(hand speed, intensity)) beside the realism figures against the library's real
co-speech motion (discriminator accuracy, 0.5 = like real; FGD; Hellinger distance of the
hand-speed histogram; jerk) and target switches per minute. ``random`` (real clips played
unwarped, at random) is the floor of the realism figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

#: variant -> SyncSettings fields it changes (the warp it switches off).
VARIANTS: dict[str, dict] = {
    "default": {},
    "unsmoothed amplitude (before stop 41)": {"gain_tau_s": 0.0},
    "no skipped preparations": {"skip_after_s": None},
    "no skips, unsmoothed amplitude": {"skip_after_s": None, "gain_tau_s": 0.0},
    "no fast playback": {"rate_max": 1.0},
    "no holds": {"hold_max_s": 0.0, "hold_at_entry": False},
    "frozen holds": {"hold_rate": 0.0},
    "no energy rate": {"energy_rate": 0.0},
    "no amplitude scaling": {"energy_gain": 0.0, "gain_range": (1.0, 1.0)},
    "no extent normalising": {"gain_range": (1.0, 1.0)},
    "no warps at all": {"rate_max": 1.0, "skip_after_s": None, "hold_max_s": 0.0,
                        "hold_at_entry": False, "energy_rate": 0.0, "energy_gain": 0.0,
                        "gain_range": (1.0, 1.0)},
}

#: (summary key, column header, format).
COLUMNS = (
    ("accent_hit_excess", "accent hits − chance ↑", "{:.3f}"),
    ("bc_excess", "BC − chance ↑", "{:.3f}"),
    ("r_intensity_best", "r(speed, intensity) ↑", "{:.3f}"),
    ("disc_accuracy", "discriminator ↓", "{:.3f}"),
    ("fgd", "FGD ↓", "{:.1f}"),
    ("hellinger_speed", "Hellinger speed ↓", "{:.3f}"),
    ("mean_jerk", "jerk (m/s³)", "{:.0f}"),
    ("switches_per_min", "switches / min", "{:.0f}"),
)


def cell(entry: dict, fmt: str) -> str:
    mean, sd = entry.get("mean", float("nan")), entry.get("seed_sd", float("nan"))
    return fmt.format(mean) + (f" [{sd:.3f}]" if sd == sd and sd > 0 else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("audio", nargs="+", help="speech files (WAV ...)")
    ap.add_argument("--textgrid", action="append", default=[], metavar="FILE",
                    help="a TextGrid of one of the files (repeat)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--variants", nargs="+", default=["all"],
                    help=f"variants to run (default all): {', '.join(VARIANTS)}")
    ap.add_argument("--physics", action="store_true", help="the simulated body (slow)")
    ap.add_argument("--json", metavar="OUT", help="also write the summaries as JSON")
    args = ap.parse_args(argv)
    names = list(VARIANTS) if args.variants == ["all"] else args.variants
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        print(f"error: unknown variant(s) {unknown}; choose from {list(VARIANTS)}",
              file=sys.stderr)
        return 2

    from gesture_sim.app.evaluation import Evaluator, evaluate
    from gesture_sim.control.synchrony import SyncSettings

    ev = Evaluator(physics=args.physics)
    rows: dict[str, dict] = {}
    for name in names:
        settings = dataclasses.replace(SyncSettings(), **VARIANTS[name])
        ev.pipeline_options = {"sync": settings}
        methods = ["controller", "random_sync"] + (["random"] if name == "default" else [])
        res = evaluate(args.audio, methods=methods, seeds=args.seeds, evaluator=ev,
                       textgrids=args.textgrid)
        summ = res.summary()
        rows[name] = {m: summ[m] for m in methods}
        print(f"  {name}: done", file=sys.stderr)
    header = ["variant", "method", *(h for _, h, _ in COLUMNS)]
    print("| " + " | ".join(header) + " |")
    print("|" + " --- |" * len(header))
    for name, by_method in rows.items():
        for method, summ in by_method.items():
            cells = [cell(summ.get(k, {}), fmt) for k, _, fmt in COLUMNS]
            print(f"| {name} | {method} | " + " | ".join(cells) + " |")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"variants": {n: VARIANTS[n] for n in names}, "rows": rows}, fh, indent=1,
                      default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
