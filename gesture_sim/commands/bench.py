"""``gesture-sim bench NAME``: speed and quality benchmarks of one stage or the whole pipeline.

Each benchmark lives in :mod:`gesture_sim.bench` as a module exposing
``register(subparsers)``; it prints a human-readable table, or JSON with ``--json``.
"""

from __future__ import annotations

import argparse
import importlib

#: Benchmark modules under gesture_sim.bench, in the order ``--help`` lists them.
BENCH_MODULES = ("physics", "prosody", "inference", "control", "pipeline", "render")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "bench", help="measure speed and quality of a stage (results for BENCHMARKS.md)",
        description="Benchmarks; each prints a table, or JSON with --json.",
    )
    bench_sub = parser.add_subparsers(dest="bench", metavar="NAME")
    for name in BENCH_MODULES:
        try:
            module = importlib.import_module(f"gesture_sim.bench.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"gesture_sim.bench.{name}":
                continue
            raise
        module.register(bench_sub)
    parser.set_defaults(func=lambda args: parser.print_help() or 1)
