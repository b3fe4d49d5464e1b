#!/usr/bin/env python3
"""Sweep the controller's settings on real speech: variety and interruptions per setting.

Usage (from the repository root):

    .venv/bin/python tools/controller_sweep.py AUDIO [--seeds 4] [--fit 1 2] [--penalty 0 -4 -8]
        [--temperature 1 2 3]

For each (fit weight, extra interruption penalty) a policy is trained for the default library
and model (default tones, no labels), then the causal pipeline (without physics) runs AUDIO
with each softmin temperature and seed; printed per setting: segments played, distinct
segments, the share of segments left at an interruption frame, and back-to-back repeats.
This is how the product's settings (`gesture_sim.loading.policy_settings`,
`DEFAULT_TEMPERATURE`) were chosen; see BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("audio")
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--fit", type=float, nargs="+", default=[1.0, 2.0])
    parser.add_argument("--penalty", type=float, nargs="+", default=[0.0, -4.0, -8.0])
    parser.add_argument("--temperature", type=float, nargs="+", default=[1.0, 2.0, 3.0])
    args = parser.parse_args(argv)

    from gesture_sim.control.costs import ControlSettings
    from gesture_sim.control.inputs import StateModel
    from gesture_sim.control.policy import train_policy
    from gesture_sim.control.style import default_tones
    from gesture_sim.feed import run_file
    from gesture_sim.metrics.selection import selection_summary
    from gesture_sim.pipeline import GesturePipeline

    base = GesturePipeline.create(physics=False)
    state_model = StateModel.from_inference(base.model)
    print("fit  penalty  T    played  distinct (min)  interrupted (min-max)  repeats")
    for fit, penalty in itertools.product(args.fit, args.penalty):
        settings = ControlSettings(fit_weight=fit, extra_interrupt_penalty=penalty)
        policy = train_policy(base.control_library, state_model, settings, tones=default_tones())
        for temperature in args.temperature:
            rows = []
            for seed in range(args.seeds):
                pipe = GesturePipeline(base.library, base.model, policy, physics=False, seed=seed,
                                       temperature=temperature,
                                       control_library=base.control_library)
                s = selection_summary(run_file(pipe, args.audio))
                rows.append((s["segments_played"], s["distinct_segments"],
                             s["interrupted_share"], s["back_to_back_repeats"]))
            a = np.array(rows, dtype=float)
            print(f"{fit:<4g} {penalty:<8g} {temperature:<4g} {a[:, 0].mean():6.0f}  "
                  f"{a[:, 1].mean():6.1f} ({a[:, 1].min():.0f})     "
                  f"{a[:, 2].mean():.2f} ({a[:, 2].min():.2f}-{a[:, 2].max():.2f})          "
                  f"{a[:, 3].max():.0f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
