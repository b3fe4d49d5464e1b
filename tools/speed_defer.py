"""CPU seconds of the pipeline with physics on one take against the feed's physics deferral.

    .venv/bin/python tools/speed_defer.py [--audio WAV] [--rounds 3] 0 0.1 0.3 1.0

For each round and each ``defer_physics_s`` value (:data:`gesture_sim.feed.DEFER_PHYSICS_S`; 0:
off, the physics after every control step), in turn: a fresh pipeline (controller, physics), one
warm-up run, then one timed run (``time.process_time``, this process pinned to one core as
``bench pipeline`` is). Prints every run and the median per value, and the CPU seconds inside
``mj_step`` (the loop's own timer), so that what the deferral saves is read outside the step.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

DEFAULT = Path(__file__).resolve().parents[1] / "tests" / "data" / "pipeline" / \
    "beat2_scott_0_2_2.wav"


def one(audio: Path, defer: float) -> tuple[float, float]:
    import gesture_sim.feed as fd
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method="controller", physics=True)

    old = fd.DEFER_PHYSICS_S
    fd.DEFER_PHYSICS_S = defer
    try:
        run_file(pipe, audio)                       # warm-up
        loop = pipe.sim.loop
        loop.timed, loop.step_cpu_s = True, 0.0
        c0 = time.process_time()
        run_file(pipe, audio)
        return time.process_time() - c0, loop.step_cpu_s
    finally:
        fd.DEFER_PHYSICS_S = old


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("defer", nargs="+", type=float)
    ap.add_argument("--audio", type=Path, default=DEFAULT)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    runs: dict[float, list[tuple[float, float]]] = {d: [] for d in args.defer}
    for r in range(args.rounds):
        for d in args.defer:
            cpu, step = one(args.audio, d)
            runs[d].append((cpu, step))
            print(f"round {r} defer {d:.2f} s: {cpu:.2f} CPU s (mj_step {step:.2f}, "
                  f"outside it {cpu - step:.2f})", flush=True)
    for d, v in runs.items():
        cpu = statistics.median(c for c, _ in v)
        out = statistics.median(c - s for c, s in v)
        print(f"defer {d:.2f} s: median {cpu:.2f} CPU s, outside mj_step {out:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
