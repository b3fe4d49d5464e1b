"""Before/after physics speed in one run: interleaved processes, one core, CPU-time ratios.

Each tree (a checkout or ``git archive REV gesture_sim assets | tar -x -C DIR`` of an older
revision) is timed in its own process, alternating between trees for ``--rounds`` rounds, pinned
to one core. Two workloads:

* ``bench``: the procedural gesture stream of ``gesture-sim bench physics`` (``--duration`` s,
  seed 0) through ``HumanoidSim.run``;
* ``pipeline``: the physics share of the pipeline, replayed: the 30 Hz joint targets of a
  pipeline run (an ``.npz`` with ``q`` (T, n), ``t`` (T,), ``dt``; see ``--make-targets``)
  stepped with ``begin_trace`` / ``advance_to`` after every control step, with the same linear
  target interpolation as ``GesturePipeline.target_at``, and the trace built at the end.

Both CPU time (``time.process_time``, steadier on a shared machine) and wall time are printed;
report the median per tree. Usage::

    git archive c5d8b5f gesture_sim assets | tar -x -C /tmp/before
    python tools/physics_speed_ab.py --make-targets /tmp/targets.npz \\
        tests/data/pipeline/beat2_scott_0_2_2.wav
    python tools/physics_speed_ab.py /tmp/before . --workload pipeline --targets /tmp/targets.npz
    python tools/physics_speed_ab.py /tmp/before . --workload bench --duration 30
    python tools/physics_speed_ab.py /tmp/before . .@0.0033333333333333335   # and a 300 Hz step
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_CHILD = r"""
import sys, time, numpy as np
from gesture_sim.sim.tracking import HumanoidSim
workload, arg, timestep = sys.argv[1], sys.argv[2], sys.argv[3]
kw = {} if timestep == "none" else {"timestep": float(timestep)}
sim = HumanoidSim(seed=0, **kw)
if workload == "bench":
    from gesture_sim.testing.procedural import gesture_stream
    duration = float(arg)
    stream, _ = gesture_stream(duration, seed=0)
    sim.reset(stream.q[0])
    c0, w0 = time.process_time(), time.perf_counter()
    sim.run(stream, duration=duration)
else:
    z = np.load(arg)
    Q, T, dt = z["q"], z["t"], float(z["dt"])
    duration = float(T[-1])
    sim.reset()
    sim.begin_trace(record=True)
    st = {"p": None, "l": None, "tl": 0.0}
    zero = np.zeros(Q.shape[1])

    def target_at(t):
        p, l, tl = st["p"], st["l"], st["tl"]
        if p is None or t >= tl:
            return l, zero
        a = min(max((t - (tl - dt)) / dt, 0.0), 1.0)
        return p + a * (l - p), (l - p) / dt

    c0, w0 = time.process_time(), time.perf_counter()
    for q, t in zip(Q, T):
        st["p"], st["l"], st["tl"] = st["l"], q, float(t)
        sim.advance_to(float(t), target_at)
    sim.trace()
cpu, wall = time.process_time() - c0, time.perf_counter() - w0
print(f"{duration / cpu:.3f} {duration / wall:.3f}")
"""


def make_targets(out: Path, audio: Path) -> None:
    """Run the pipeline without physics on ``audio`` and save its 30 Hz targets to ``out``."""
    import numpy as np

    sys.path.insert(0, str(REPO))
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(physics=False)
    run_file(pipe, audio)
    np.savez(out, q=np.array(pipe.log.targets, dtype=float),
             t=np.array(pipe.log.step_times, dtype=float), dt=pipe.dt)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trees", nargs="*",
                    help="source trees to compare; TREE@STEP times TREE with physics step STEP")
    ap.add_argument("--workload", choices=("bench", "pipeline"), default="bench")
    ap.add_argument("--duration", type=float, default=30.0, help="bench stream seconds")
    ap.add_argument("--targets", type=Path, help="pipeline targets (.npz)")
    ap.add_argument("--timestep", default="none", help="physics step for every tree (s)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--core", type=int, default=0)
    ap.add_argument("--make-targets", nargs=2, type=Path, metavar=("OUT", "AUDIO"))
    args = ap.parse_args(argv)
    if args.make_targets:
        make_targets(*args.make_targets)
        return 0
    arg = str(args.duration) if args.workload == "bench" else str(args.targets.resolve())
    specs = [(Path(t.split("@")[0]).resolve(), t.split("@")[1] if "@" in t else args.timestep)
             for t in args.trees]
    results: dict[str, list[tuple[float, float]]] = {f"{t}@{s}": [] for t, s in specs}
    for _ in range(args.rounds):
        for tree, step in specs:
            env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1",
                       MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
            cmd = ["taskset", "-c", str(args.core), sys.executable, "-c", _CHILD,
                   args.workload, arg, step]
            out = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True,
                                 check=True).stdout.split()
            results[f"{tree}@{step}"].append((float(out[0]), float(out[1])))
            print(f"{tree}@{step}: cpu {out[0]}x, wall {out[1]}x", flush=True)
    for tree, rows in results.items():
        cpu = sorted(r[0] for r in rows)[len(rows) // 2]
        wall = sorted(r[1] for r in rows)[len(rows) // 2]
        print(f"median {tree}: {cpu:.2f}x real time per CPU second, {wall:.2f}x wall")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
