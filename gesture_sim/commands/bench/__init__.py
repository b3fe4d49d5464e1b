"""``gesture-sim bench NAME``: speed and quality benchmarks of one stage or the whole pipeline.

Each benchmark is a module of this package exposing ``register(subparsers)``; it prints a
human-readable table, or JSON with ``--json``. Every module of :data:`BENCH_MODULES` must import
(a broken one is an error, never a benchmark silently missing from ``--help``).
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from typing import Any

#: Benchmark modules of this package, in the order ``--help`` lists them.
BENCH_MODULES = ("physics", "prosody", "inference", "control", "pipeline", "render", "train",
                 "onset", "robot")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "bench", help="measure speed and quality of a stage (results for BENCHMARKS.md)",
        description="Benchmarks; each prints a table, or JSON with --json.",
    )
    bench_sub = parser.add_subparsers(dest="bench", metavar="NAME")
    for name in BENCH_MODULES:
        module = importlib.import_module(f"gesture_sim.commands.bench.{name}")
        module.register(bench_sub)
    for name, check in BENCH_CHECKS.items():
        if name in bench_sub.choices:
            _with_checks(bench_sub.choices[name], check)
    parser.set_defaults(func=lambda args: parser.print_help() or 1)


def _with_checks(parser: argparse.ArgumentParser, check: Callable[[argparse.Namespace], None],
                 ) -> None:
    """Run ``check(args)`` before the benchmark's run function."""
    func = parser.get_default("func")

    def checked(args: argparse.Namespace) -> int:
        check(args)
        return func(args)

    parser.set_defaults(func=checked)


def _opt(args: argparse.Namespace, name: str) -> Any:
    return getattr(args, name.lstrip("-").replace("-", "_"), None)


def _check_numbers(args: argparse.Namespace, specs: dict[str, tuple]) -> None:
    """``specs``: option -> (kind, lo, hi) with kind "int" or "float"; lists checked per item."""
    from gesture_sim import validation as v

    for name, (kind, lo, hi) in specs.items():
        value = _opt(args, name)
        if value is None:
            continue
        for x in value if isinstance(value, list) else [value]:
            if kind == "int":
                v.integer(name, x, lo, hi)
            else:
                v.number(name, x, lo, hi, lo_open=lo == 0.0)


def _files(args: argparse.Namespace, name: str) -> None:
    from gesture_sim import validation as v

    for f in _opt(args, name) or []:
        v.input_file(name.upper(), f, "audio file")


def _prosody_checks(args: argparse.Namespace) -> None:
    from gesture_sim.contracts import SAMPLE_RATE

    _check_numbers(args, {"--block-size": ("int", 1, SAMPLE_RATE), "--repeat": ("int", 1, 100)})
    _files(args, "files")


def _train_checks(args: argparse.Namespace) -> None:
    from gesture_sim import validation as v

    _check_numbers(args, {"--minutes": ("float", 0.0, 600.0), "--states": ("int", 2, 64),
                          "--threads": ("int", 1, 256), "--decisions": ("int", 1, 10_000_000),
                          "--seed": ("int", 0, 2**32 - 1)})
    for motion, audio in _opt(args, "pair") or []:
        v.input_file("MOTION", motion, "motion file")
        v.input_file("AUDIO", audio, "audio file")


#: Argument checks per benchmark (they run before the benchmark's heavy imports).
BENCH_CHECKS: dict[str, Callable[[argparse.Namespace], None]] = {
    "physics": lambda a: _check_numbers(a, {
        "--duration": ("float", 0.0, 3600.0), "--seed": ("int", 0, 2**32 - 1),
        "--control-every": ("int", 1, 1000), "--record-every": ("int", 1, 1000)}),
    "prosody": _prosody_checks,
    "inference": lambda a: _check_numbers(a, {
        "--states": ("int", 2, 64), "--clusters": ("int", 2, 64), "--window": ("int", 1, 16),
        "--steps": ("int", 1, 10_000_000)}),
    "control": lambda a: _check_numbers(a, {
        "--lengths": ("float", 0.0, 3600.0), "--states": ("int", 1, 64),
        "--decisions": ("int", 1, 10_000_000), "--seed": ("int", 0, 2**32 - 1)}),
    "pipeline": lambda a: _files(a, "audio"),
    "render": lambda a: _check_numbers(a, {"--seconds": ("float", 0.0, 600.0),
                                           "--fps": ("float", 1.0, 240.0)}),
    "train": lambda a: _train_checks(a),
}
