"""How should a segment switch be crossed? The controller with ``blend_frames`` N, the
pipeline's ``transition`` and timing-layer settings, against random selection and mismatched
audio at the first combination, through the project's ``evaluate``.

    python tools/blend_ablation.py --audio A.wav B.wav --textgrid A.TextGrid B.TextGrid \\
        --blend 6 10 15 [--transition ramp gpdm] [--sync carry_s=0,0.1 rate_tau_s=0,0.05] \\
        [--accents w_f0=0,0.5] [--seeds 2] [--physics] [--json OUT]

``--sync KEY=V1,V2,...`` sets a :class:`~gesture_sim.control.synchrony.SyncSettings` field
(numbers; ``true``/``false`` for a switch), ``--accents KEY=V1,V2,...`` an
:class:`~gesture_sim.audio.accents.AccentConfig` field of the accent detector; every
combination of the values given is run.
Prints one JSON row per (method, combination): mean and seed SD of the coupling and
naturalness figures, among them the jerk inside and outside the switch transitions.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEYS = ("accent_hit_excess", "bc_excess", "r_speed_intensity", "disc_accuracy", "fgd",
        "hellinger_speed", "mean_jerk", "transition_jerk", "non_transition_jerk",
        "switches_per_min", "stress_hit_rate", "stress_hit_excess", "head_accent_hits",
        "head_accent_excess",
        "foot_skate_mm_s")


def _values(text: str) -> tuple[str, list]:
    key, _, vals = text.partition("=")
    if not vals:
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY=V1,V2")

    def one(v: str) -> bool | float:
        return v.lower() == "true" if v.lower() in ("true", "false") else float(v)
    return key, [one(v) for v in vals.split(",")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--audio", nargs="+", required=True)
    ap.add_argument("--textgrid", nargs="*", default=[])
    ap.add_argument("--blend", type=int, nargs="+", default=[6])
    ap.add_argument("--transition", nargs="+", default=["ramp"],
                    help="the pipeline's transition values (ramp, gpdm; default ramp)")
    ap.add_argument("--sync", type=_values, nargs="*", default=[],
                    help="SyncSettings fields KEY=V1,V2 (default: the defaults)")
    ap.add_argument("--accents", type=_values, nargs="*", default=[],
                    help="AccentConfig fields KEY=V1,V2 (default: the defaults)")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--physics", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    from gesture_sim.app.evaluation import Evaluator, evaluate
    from gesture_sim.audio.accents import AccentConfig
    from gesture_sim.control.synchrony import SyncSettings

    ev = Evaluator(physics=args.physics)
    keys = [k for k, _ in args.sync]
    akeys = [k for k, _ in args.accents]
    out = {}
    combos = itertools.product(args.blend, args.transition,
                               itertools.product(*[v for _, v in args.sync]),
                               itertools.product(*[v for _, v in args.accents]))
    for n, (bf, tr, vals, avals) in enumerate(combos):
        sync = dict(zip(keys, vals, strict=True))
        acc = dict(zip(akeys, avals, strict=True))
        ev.pipeline_options = {"blend_frames": bf, "transition": tr}
        if sync:
            ev.pipeline_options["sync"] = SyncSettings(blend_s=bf / 30.0, **sync)
        if acc:
            ev.pipeline_options["accents"] = AccentConfig(**acc)
        name = " ".join([f"blend {bf}", *([tr] if tr != "ramp" else []),
                         *(f"{k} {v:g}" for k, v in {**sync, **acc}.items())])
        methods = ["controller"] + (["random", "mismatched"] if n == 0 else [])
        res = evaluate(args.audio, methods=methods, seeds=args.seeds, evaluator=ev,
                       textgrids=args.textgrid)
        s = res.summary()
        for m in methods:
            row = {k: (round(s[m][k]["mean"], 4), round(s[m][k].get("sd", 0), 4))
                   for k in KEYS if k in s[m] and isinstance(s[m][k], dict)}
            out[f"{m} {name}"] = row
            print(f"{m} {name}", json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
