"""``gesture-sim bench robot``: speech-driven motion on a robot, within its limits, vs the humanoid.

Runs the controller (and the controls: random clips, mismatched audio) on each ``--body`` for
every ``--audio`` file and ``--seeds`` seed, with physics, and prints per body and method the
robot's compliance figures (falls, joint-limit excess, motors at their torque limit per joint,
joint-velocity excess, arm–trunk and arm–arm contacts, foot skating) and the hands' speech
synchrony (BC − chance, accent hits − chance); see :mod:`gesture_sim.app.robot_eval`.
"""

from __future__ import annotations

import argparse

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "robot", help="a robot body's limits and speech synchrony vs the humanoid",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    parser.add_argument("--body", action="append", default=None, metavar="BODY",
                        help="a body (humanoid, g1, h1 or a robot map .json); repeat for "
                             "several (default: humanoid g1 h1)")
    parser.add_argument("--audio", action="append", default=None, metavar="FILE",
                        help="a speech file (repeatable; default: the shipped example speech)")
    parser.add_argument("--seeds", type=int, default=3, metavar="N",
                        help="seeds 0..N-1 (default 3)")
    parser.add_argument("--seconds", type=float, default=None, metavar="S",
                        help="score only the first S seconds of each file")
    parser.add_argument("--no-controls", action="store_true",
                        help="the controller only (no random-clip and mismatched-audio runs)")
    parser.add_argument("--progress", action="store_true",
                        help="print each run's figures to stderr (one JSON line) as it ends")
    parser.add_argument("--json", action="store_true", help="print JSON (every run too)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gesture_sim import EXAMPLE_SPEECH
    from gesture_sim import validation as v
    from gesture_sim.app.robot_eval import bench_robot
    from gesture_sim.errors import GestureSimError
    from gesture_sim.sim.bodies import resolve_body

    bodies = args.body or ["humanoid", "g1", "h1"]
    for b in bodies:
        resolve_body(b)                       # an unknown body fails before any work
    audio = args.audio or [str(EXAMPLE_SPEECH)]
    for a in audio:
        v.input_file("--audio", a, "audio file")
    v.integer("--seeds", args.seeds, 1, 100)
    if args.seconds is not None and not args.seconds > 3.0:
        raise GestureSimError(f"--seconds must be more than 3, got {args.seconds}")
    def progress(row: dict) -> None:
        import json
        import sys

        print(json.dumps(row, default=float), file=sys.stderr, flush=True)

    out = bench_robot(bodies, audio, list(range(args.seeds)), seconds=args.seconds,
                      controls=not args.no_controls, on_run=progress if args.progress else None)
    if args.json:
        print_json(out)
        return 0
    for name, s in out["summary"].items():
        line = [f"{name:24s} runs {s['runs']}"]
        for k in ("bc_excess", "accent_hit_excess"):
            if k in s:
                line.append(f"{k} {s[k]['mean']:+.3f}±{s[k]['std']:.3f}")
        if "joint_limit_excess_deg" in s:
            line.append(f"falls {s['falls']} limit {s['joint_limit_excess_deg']['max']:.2f}° "
                        f"sat {100 * s['saturation_share_max']['max']:.2f}% "
                        f"vel {s['velocity_excess_max']['max']:.2f} rad/s "
                        f"self {s['self_contacts']} "
                        f"skate {s['foot_skate_mm_s']['mean']:.2f} mm/s")
        elif "falls" in s:
            line.append(f"falls {s['falls']}")
        print("  ".join(line))
    return 0
