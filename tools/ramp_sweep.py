#!/usr/bin/env python3
"""Measure the segment-switch target ramp: foot skating and hand-speed peaks per ramp length.

Usage (from the repository root):

    .venv/bin/python tools/ramp_sweep.py AUDIO [--frames 0 4 6 8] [--seeds 0 1]

Runs the causal pipeline with physics (default library, model and settings) for each ramp length
(control steps; 0 = the raw jump at a clip switch) and prints the mean over seeds of foot skating
(mm/s), the 99th percentile and maximum hand speed (m/s) and the settled hand tracking error
(mm). This is how the pipeline's ``blend_frames`` default was chosen (BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("audio")
    parser.add_argument("--frames", type=int, nargs="+", default=[0, 4, 6, 8])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    args = parser.parse_args(argv)

    from gesture_sim.feed import run_file
    from gesture_sim.metrics.physics import physics_metrics
    from gesture_sim.pipeline import GesturePipeline

    print("frames  skate mm/s  hand p99 m/s  hand max m/s  settled hand error mm")
    for frames in args.frames:
        rows = []
        for seed in args.seeds:
            pipe = GesturePipeline.create(seed=seed, blend_frames=frames)
            run_file(pipe, args.audio)
            trace = pipe.trace()
            m = physics_metrics(trace)
            hands = trace.sim_sites[:, :2]
            speed = np.linalg.norm(np.diff(hands, axis=0), axis=2) / np.diff(trace.time)[:, None]
            rows.append((m.foot_skate_mm_s, np.percentile(speed, 99), speed.max(),
                         m.hand_error_settled_rms_mm))
        a = np.mean(rows, axis=0)
        print(f"{frames:6d}  {a[0]:10.2f}  {a[1]:12.2f}  {a[2]:12.2f}  {a[3]:21.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
