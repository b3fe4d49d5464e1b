#!/usr/bin/env python3
"""Sweep the planner's settings on one take, kinematic or with physics (issue 51).

    PYTHONPATH=. .venv/bin/python tools/planner_sweep.py TAKE.wav --textgrid TAKE.TextGrid \\
        [--reference TAKE.npz] [--physics] [--seeds 1] [--set NAME:key=value,key=value ...]

Each ``--set`` registers a variant of the ``planned`` row with those
:class:`~gesture_sim.control.planner.PlanSettings` changes (``unbent=1`` starts from the
unbent settings) and evaluates it beside ``--methods`` (the evaluation's own methods) with
:func:`gesture_sim.app.evaluation.evaluate`; prints one line of figures per method.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEYS = ("bc_excess", "accent_hit_rate", "accent_hit_excess", "stress_hit_excess", "r_intensity",
        "disc_accuracy", "fgd", "hellinger_speed", "distinct_segments", "switches_per_min",
        "mean_jerk")


def _value(v: str):
    if "/" in v:
        return tuple(float(x) for x in v.split("/"))
    return float(v)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("audio", type=Path, nargs="+")
    ap.add_argument("--textgrid", type=Path, action="append", default=[])
    ap.add_argument("--reference", type=Path, action="append", default=[])
    ap.add_argument("--physics", action="store_true")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--methods", nargs="*", default=[])
    ap.add_argument("--set", action="append", default=[], metavar="NAME:k=v,k=v")
    args = ap.parse_args(argv)

    from dataclasses import replace

    from gesture_sim import app as _app  # noqa: F401
    from gesture_sim import methods as M
    from gesture_sim.app import evaluation as E
    from gesture_sim.control.planner import PlanSettings

    names = []
    for spec in args.set:
        name, _, kv = spec.partition(":")
        changes = {k: _value(v) for k, v in (x.split("=") for x in kv.split(",") if x)}
        unbent = bool(changes.pop("unbent", 0))
        if "repeat_window" in changes:
            changes["repeat_window"] = int(changes["repeat_window"])
        if "rates" in changes and not isinstance(changes["rates"], tuple):
            changes["rates"] = (changes["rates"],)

        def settings(p, changes=changes, unbent=unbent):
            cfg = PlanSettings().unbent() if unbent else PlanSettings()
            return replace(cfg, **changes)

        M.REGISTRY[name] = M.MethodSpec(name, M._planned(settings), policy=True)
        names.append(name)
    E.PIPELINE_METHODS = tuple(E.PIPELINE_METHODS) + tuple(names)
    E.EVAL_METHODS = tuple(E.EVAL_METHODS) + tuple(names)
    ev = E.Evaluator(physics=args.physics)
    res = E.evaluate(args.audio, references=args.reference, textgrids=args.textgrid,
                     methods=list(args.methods) + names, seeds=args.seeds, evaluator=ev)
    print(f"{'audio/method':<30}" + "".join(f"{k[:10]:>10}" for k in KEYS))
    groups: dict = {}
    for r in res.rows:
        groups.setdefault((r["audio"], r["method"]), []).append(r["metrics"])
    for (a, m), rows in groups.items():
        cells = []
        for k in KEYS:
            v = [x[k] for x in rows if k in x and np.isfinite(x[k])]
            cells.append(f"{np.mean(v):10.3f}" if v else f"{'-':>10}")
        print(f"{a[-8:] + '/' + m:<30}" + "".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
