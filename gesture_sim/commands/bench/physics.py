"""``gesture-sim bench physics``: simulation speed and plausibility on a procedural gesture stream.

Simulates ``--duration`` seconds of the seeded procedural gesture stream
(:func:`gesture_sim.testing.procedural.gesture_stream`: beats, sweeps, hands to face, sudden
switches every 0.3-2 s) with the free-standing humanoid (PD + balance, no assist), pinned to one
CPU core where the OS allows it. Reports simulated seconds per wall second (stepping and
recording; the settle at reset and the metrics are excluded), also per CPU second of the process
(steadier than wall time on a shared machine), and the plausibility metrics of
:func:`gesture_sim.metrics.physics.physics_metrics`.
"""

from __future__ import annotations

import argparse
import os

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "physics", help="physics speed (x real time, one core) and plausibility metrics",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    parser.add_argument("--duration", type=float, default=60.0, metavar="S",
                        help="simulated seconds of gesture stream (default 60)")
    parser.add_argument("--seed", type=int, default=0, help="procedural stream seed (default 0)")
    parser.add_argument("--control-every", type=int, default=None, metavar="N",
                        help="physics steps per control update (default: 100 Hz, 5 at 500 Hz)")
    parser.add_argument("--timestep", type=float, default=None, metavar="S",
                        help="physics time step (default: the model's, 0.002 s)")
    parser.add_argument("--record-every", type=int, default=None, metavar="N",
                        help="physics steps per recorded trace row (default: --control-every, "
                             "i.e. 100 Hz rows; the metrics are defined on these rows)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import time

    from gesture_sim.errors import GestureSimError
    from gesture_sim.metrics.physics import physics_metrics
    from gesture_sim.sim.tracking import HumanoidSim
    from gesture_sim.testing.procedural import gesture_stream

    if args.duration <= 0:
        raise GestureSimError(f"--duration must be positive, got {args.duration}")
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
        pinned = True
    except (AttributeError, OSError):
        pinned = False
    stream, segments = gesture_stream(args.duration, seed=args.seed)
    if args.timestep is not None and not 0.0 < args.timestep <= 0.01:
        raise GestureSimError(f"--timestep must be in (0, 0.01] s, got {args.timestep}")
    sim = HumanoidSim(seed=args.seed, control_every=args.control_every,
                      record_every=args.record_every, timestep=args.timestep)
    if sim.record_every % sim.control_every:
        raise GestureSimError("--record-every must be a positive multiple of --control-every")
    sim.reset(stream.q[0])
    start, cpu0 = time.perf_counter(), time.process_time()
    trace = sim.run(stream, duration=args.duration, show_progress=not args.json)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu0
    metrics = physics_metrics(trace)
    result = {
        "benchmark": "physics",
        "simulated_s": args.duration,
        "wall_s": wall,
        "x_real_time": args.duration / wall,
        "cpu_s": cpu,
        "x_real_time_cpu": args.duration / cpu,
        "one_core": pinned,
        "physics_hz": 1.0 / sim.model.opt.timestep,
        "control_hz": 1.0 / (sim.model.opt.timestep * sim.control_every),
        "record_hz": 1.0 / (sim.model.opt.timestep * sim.record_every),
        "segments": len(segments),
        "metrics": metrics.to_dict(),
    }
    if args.json:
        print_json(result)
        return 0
    m = result["metrics"]
    print(f"physics: {args.duration:.0f} s of gestures in {wall:.2f} s = "
          f"{result['x_real_time']:.1f}x real time (CPU time: {result['x_real_time_cpu']:.1f}x; "
          f"{'one core' if pinned else 'unpinned'}, "
          f"{result['physics_hz']:.0f} Hz physics, {result['control_hz']:.0f} Hz control)")
    rows = [
        ("fell", m["fell"]), ("assist impulse (N·s/s)", m["assist_impulse_per_s"]),
        ("foot skating (mm/s)", m["foot_skate_mm_s"]),
        ("ground penetration max (mm)", m["ground_penetration_max_mm"]),
        ("self-penetration max (mm)", m["self_penetration_max_mm"]),
        ("joint-limit excess max (deg)", m["joint_limit_max_excess_deg"]),
        ("saturation, any joint (share)", m["saturation_share_any"]),
        ("COM margin min (m)", m["com_margin_min_m"]),
        ("joint error RMS (deg)", m["joint_rms_deg"]),
        ("hand error RMS, all / settled (mm)",
         f"{m['hand_error_rms_mm']:.1f} / {m['hand_error_settled_rms_mm']:.1f}"),
        ("head error RMS, all / settled (mm)",
         f"{m['head_error_rms_mm']:.1f} / {m['head_error_settled_rms_mm']:.1f}"),
        ("target switches", m["n_switches"]),
    ]
    for name, value in rows:
        shown = f"{value:.3g}" if isinstance(value, float) else str(value)
        print(f"  {name:38s} {shown}")
    print("  peak joint acceleration p99.9 (rad/s²): " + ", ".join(
        f"{g} {v:.0f}" for g, v in m["peak_accel_rad_s2"].items()))
    return 0
