"""How long should a switch ramp be, and should its start carry on moving? The controller with
``blend_frames`` N and the timing layer's ``carry_s`` C, against random selection and
mismatched audio at the defaults, through the project's ``evaluate``.

    python tools/blend_ablation.py --audio A.wav B.wav --textgrid A.TextGrid B.TextGrid \
        --blend 6 10 15 [--carry 0 0.07] [--rate-tau 0 0.1] [--seeds 2] [--physics] [--json OUT]

``--rate-tau`` sets the timing layer's ``rate_tau_s`` (the easing of its playback rate).
Prints one JSON row per (method, blend, carry, rate-tau): mean and seed SD of the coupling and
naturalness figures, among them the jerk inside and outside the switch transitions.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--audio", nargs="+", required=True)
    ap.add_argument("--textgrid", nargs="*", default=[])
    ap.add_argument("--blend", type=int, nargs="+", default=[6, 10, 15])
    ap.add_argument("--carry", type=float, nargs="+", default=[None],
                    help="the timing layer's carry_s values (s); default: its default only")
    ap.add_argument("--rate-tau", type=float, nargs="+", default=[None],
                    help="the timing layer's rate_tau_s values (s); default: its default only")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--physics", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    from gesture_sim.app.evaluation import Evaluator, evaluate

    ev = Evaluator(physics=args.physics)
    out = {}
    for bf in args.blend:
        for carry in args.carry:
            for tau in args.rate_tau:
                _one(ev, evaluate, bf, carry, tau, args, out)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


def _one(ev, evaluate, bf: int, carry: float | None, tau: float | None, args,
         out: dict) -> None:
    from gesture_sim.control.synchrony import SyncSettings

    ev.pipeline_options = {"blend_frames": bf}
    name = f"blend {bf}"
    sync = {}
    if carry is not None:
        sync["carry_s"] = carry
        name += f" carry {carry:g}"
    if tau is not None:
        sync["rate_tau_s"] = tau
        name += f" rate-tau {tau:g}"
    if sync:
        ev.pipeline_options["sync"] = SyncSettings(blend_s=bf / 30.0, **sync)
    first = bf == args.blend[0] and carry == args.carry[0] and tau == args.rate_tau[0]
    methods = ["controller"] + (["random", "mismatched"] if first else [])
    res = evaluate(args.audio, methods=methods, seeds=args.seeds, evaluator=ev,
                   textgrids=args.textgrid)
    s = res.summary()
    keys = ("accent_hit_excess", "bc_excess", "r_speed_intensity", "disc_accuracy", "fgd",
            "hellinger_speed", "mean_jerk", "transition_jerk", "non_transition_jerk",
            "switches_per_min", "stress_hit_rate", "head_accent_hits", "foot_skate_mm_s")
    for m in methods:
        row = {k: (round(s[m][k]["mean"], 4), round(s[m][k].get("sd", 0), 4))
               for k in keys if k in s[m] and isinstance(s[m][k], dict)}
        out[f"{m} {name}"] = row
        print(f"{m} {name}", json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())
