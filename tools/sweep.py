#!/usr/bin/env python3
"""One sweep driver: named sweeps of settings through the project's evaluation.

    python tools/sweep.py --list
    python tools/sweep.py NAME AUDIO... [--textgrid TG ...] [--seeds 2] [--physics]
        [--variants NAME ...] [--set NS.KEY=V1,V2 ...] [--cells] [--json OUT]
    python tools/sweep.py --report DIR/report.json [--subset 3 ...]

A sweep is a table of *variants*; each variant is a set of options, and each runs through
:func:`gesture_sim.app.evaluation.evaluate` (kinematic targets on the standing body unless
``--physics``) with the sweep's methods; the baselines run with the first variant only (or with
every variant where the sweep judges per-file cells). Options are named ``NAMESPACE.KEY``:

* ``pipe.KEY``: a :class:`~gesture_sim.pipeline.GesturePipeline` keyword for every method of
  the variant (``pipe.blend_frames``, ``pipe.transition``);
* ``ctl.KEY``: a pipeline keyword for the ``controller`` runs only (``ctl.temperature``,
  ``ctl.repeat_cost``, ``ctl.repeat_tau_s``, ``ctl.sample_state``);
* ``sync.KEY``: a field of the timing layer's
  :class:`~gesture_sim.control.synchrony.SyncSettings` (its ``blend_s`` follows
  ``pipe.blend_frames``);
* ``accents.KEY``: a field of the accent detector's
  :class:`~gesture_sim.audio.accents.AccentConfig`;
* ``policy.KEY``: a field of :class:`~gesture_sim.control.costs.ControlSettings`: the product's
  policy (:func:`gesture_sim.loading.policy_settings`) retrained in memory with it.

``mismatched`` scores the variant's own controller runs against another file's audio (give two
files or more). ``--set NS.KEY=V1,V2`` adds the product of the values given to every variant
chosen (numbers; ``true``/``false``/``none``), which is also how the sweep ``custom`` is filled.
Printed: one markdown row per (variant, method) with the sweep's columns (mean [seed SD]);
``--cells``: the per-file cells of the controller against random clips and mismatched audio
(:func:`gesture_sim.metrics.cells.file_cells`). Each run also reports its segment usage
(distinct segments, entropy of the played frames, top-5 share, replay gap, interrupted share).

The named sweeps replace eight scripts that each wrote this loop again (``blend_ablation``,
``warp_ablation``, ``ramp_sweep``, ``sync_sweep``, ``sync_cells``, ``seed_cells``,
``controller_sweep``, ``selection_diversity``: ``git show 174c411:tools/NAME.py``); which
default each sweep chose is in ``docs/history.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: (summary key, column header, format) of every column a sweep may show.
COLUMNS: dict[str, tuple[str, str]] = {
    "accent_hit_excess": ("accent hits − chance ↑", "{:.3f}"),
    "bc_excess": ("BC − chance ↑", "{:.3f}"),
    "r_intensity_best": ("r(speed, intensity) ↑", "{:.3f}"),
    "beat_align": ("BeatAlign ↑", "{:.3f}"),
    "stress_hit_excess": ("stress hits − chance ↑", "{:.3f}"),
    "head_accent_excess": ("head peaks − chance ↑", "{:.3f}"),
    "disc_accuracy": ("discriminator ↓", "{:.3f}"),
    "fgd": ("FGD ↓", "{:.1f}"),
    "hellinger_speed": ("Hellinger speed ↓", "{:.3f}"),
    "mean_jerk": ("jerk (m/s³)", "{:.1f}"),
    "transition_jerk": ("transition jerk", "{:.1f}"),
    "non_transition_jerk": ("jerk elsewhere", "{:.1f}"),
    "switches_per_min": ("switches / min", "{:.0f}"),
    "segments_played": ("segments played", "{:.0f}"),
    "distinct_segments": ("distinct", "{:.1f}"),
    "usage_entropy_bits": ("entropy (bits)", "{:.2f}"),
    "top5_share": ("top-5 share", "{:.2f}"),
    "back_to_back_s": ("replay gap (s)", "{:.1f}"),
    "interrupted_share": ("interrupted", "{:.2f}"),
    "back_to_back_repeats": ("repeats", "{:.1f}"),
    "foot_skate_mm_s": ("foot skate (mm/s)", "{:.2f}"),
    "hand_error_rms_mm": ("hand error (mm)", "{:.1f}"),
}
COUPLING = ("accent_hit_excess", "bc_excess", "r_intensity_best")
REALISM = ("disc_accuracy", "fgd", "hellinger_speed", "mean_jerk")
USAGE = ("switches_per_min", "distinct_segments", "usage_entropy_bits", "top5_share")


@dataclass(frozen=True)
class Sweep:
    """A named sweep: ``variants`` (name -> options), the ``methods`` every variant runs, the
    ``baselines`` run with the first variant (with every variant when ``cells``), the
    ``columns`` printed, and what it measured (``doc``)."""

    doc: str
    variants: dict[str, dict]
    methods: tuple[str, ...] = ("controller",)
    baselines: tuple[str, ...] = ("random", "mismatched")
    columns: tuple[str, ...] = COUPLING + REALISM + ("switches_per_min",)
    cells: bool = False
    default_variants: tuple[str, ...] = field(default=())


_NO_WARPS = {"sync.rate_max": 1.0, "sync.skip_after_s": None, "sync.hold_max_s": 0.0,
             "sync.hold_at_entry": False, "sync.energy_rate": 0.0, "sync.energy_gain": 0.0,
             "sync.gain_range": (1.0, 1.0)}

SWEEPS: dict[str, Sweep] = {
    "smoke": Sweep(
        "the smallest sweep: the shipped controller alone (for the test)",
        {"default": {}}, baselines=(), columns=("bc_excess", "switches_per_min")),
    "custom": Sweep(
        "only what --set gives, against the defaults", {"default": {}}),
    "controller": Sweep(
        "the controller's fit weight, interruption penalty and softmin temperature: variety and "
        "interruptions (chose fit 2, penalty -4, T 2; was tools/controller_sweep.py)",
        {f"fit {f:g}, penalty {p:g}, T {t:g}": {"policy.fit_weight": f,
                                                 "policy.extra_interrupt_penalty": p,
                                                 "ctl.temperature": t}
         for f, p, t in itertools.product((1.0, 2.0), (0.0, -4.0, -8.0), (1.0, 2.0, 3.0))},
        baselines=(), columns=("segments_played", "distinct_segments", "interrupted_share",
                               "back_to_back_repeats", *COUPLING)),
    "novelty": Sweep(
        "which segments the controller chooses: temperature, the novelty term, state sampling "
        "(chose repeat_cost 16, repeat_tau_s 40 s; was tools/selection_diversity.py)",
        {"default": {},
         "no novelty term (stop 42)": {"ctl.repeat_cost": 0.0},
         "T=0 (argmin), no novelty": {"ctl.temperature": 0.0, "ctl.repeat_cost": 0.0},
         "T=4, no novelty": {"ctl.temperature": 4.0, "ctl.repeat_cost": 0.0},
         "T=8, no novelty": {"ctl.temperature": 8.0, "ctl.repeat_cost": 0.0},
         "repeat 8, 20 s": {"ctl.repeat_cost": 8.0, "ctl.repeat_tau_s": 20.0},
         "repeat 32, 20 s": {"ctl.repeat_cost": 32.0, "ctl.repeat_tau_s": 20.0},
         "sample state": {"ctl.sample_state": True},
         "sample state, repeat 16, 20 s": {"ctl.sample_state": True, "ctl.repeat_tau_s": 20.0},
         "fit 1 (retrained)": {"policy.fit_weight": 1.0}},
        baselines=("random_sync", "random", "mismatched"),
        columns=("fgd", "hellinger_speed", "disc_accuracy", *COUPLING, *USAGE, "back_to_back_s")),
    "warps": Sweep(
        "which of the timing layer's warps costs most naturalness (chose no skipped "
        "preparations and a smoothed amplitude; was tools/warp_ablation.py)",
        {"default": {},
         "unsmoothed amplitude (before stop 41)": {"sync.gain_tau_s": 0.0},
         "skipped preparations at 0.12 s (before stop 43)": {"sync.skip_after_s": 0.12},
         "no fast playback": {"sync.rate_max": 1.0},
         "no holds": {"sync.hold_max_s": 0.0, "sync.hold_at_entry": False},
         "frozen holds": {"sync.hold_rate": 0.0},
         "no energy rate": {"sync.energy_rate": 0.0},
         "no amplitude scaling": {"sync.energy_gain": 0.0, "sync.gain_range": (1.0, 1.0)},
         "no extent normalising": {"sync.gain_range": (1.0, 1.0)},
         "no warps at all": _NO_WARPS},
        methods=("controller", "random_sync"), baselines=("random",),
        columns=COUPLING + REALISM + ("switches_per_min",)),
    "ramp": Sweep(
        "how a segment switch is crossed: ramp length, the carried start, the eased rate "
        "(chose 15 steps, carry_s 0.1, rate_tau_s 0.05; was tools/blend_ablation.py)",
        {"15, carried, eased (default)": {},
         "6, held, stepped (stop 43)": {"pipe.blend_frames": 6, "sync.carry_s": 0.0,
                                        "sync.rate_tau_s": 0.0},
         "6, carried, eased": {"pipe.blend_frames": 6},
         "10, carried, eased": {"pipe.blend_frames": 10},
         "15, carried, stepped rate": {"sync.rate_tau_s": 0.0},
         "15, carried, rate eased 0.1 s": {"sync.rate_tau_s": 0.1},
         "0 (every switch a cut)": {"pipe.blend_frames": 0}},
        columns=(*COUPLING, *REALISM[:3], "mean_jerk", "transition_jerk", "non_transition_jerk",
                 "foot_skate_mm_s")),
    "transition": Sweep(
        "Chiu 2014's GPDM paths against the ramp (the ramp kept; --transition gpdm an option)",
        {"ramp, 15": {}, "gpdm, 15": {"pipe.transition": "gpdm"},
         "ramp, 6": {"pipe.blend_frames": 6}, "gpdm, 6": {"pipe.blend_frames": 6,
                                                         "pipe.transition": "gpdm"}},
        baselines=(), columns=(*COUPLING[:2], *REALISM, "transition_jerk")),
    "hold": Sweep(
        "the pre-stroke hold's drift, per-file cells (chose hold_rate 0.2)",
        {"hold_rate 0.2 (default)": {}, "frozen holds (0)": {"sync.hold_rate": 0.0},
         "hold_rate 0.3": {"sync.hold_rate": 0.3}},
        columns=(*COUPLING, "stress_hit_excess", "hellinger_speed", "mean_jerk"), cells=True),
    "lead": Sweep(
        "the stroke's lead after the accent (kept 0.08 s: 0.04 s is worse with physics)",
        {"lead 0.08 s (default)": {}, "lead 0.04 s": {"sync.lead_s": 0.04}},
        columns=(*COUPLING, "beat_align", "mean_jerk"), cells=True),
    "stroke_rate": Sweep(
        "strokes thinned to the library's stroke rate against a stroke on every accent",
        {"library's rate (default)": {}, "a stroke on every accent": {"sync.stroke_rate": 0.0}},
        columns=(*COUPLING, "stress_hit_excess"), cells=True),
    "accents": Sweep(
        "an accent detector that follows stress instead of F0 (kept the default)",
        {"default": {}, "no F0 term": {"accents.w_f0": 0.0},
         "threshold 0 SD": {"accents.threshold_sd": 0.0},
         "rise weight 1, no F0": {"accents.w_rise": 1.0, "accents.w_f0": 0.0}},
        baselines=("random",), columns=(*COUPLING, "stress_hit_excess")),
}


def parse_value(text: str):
    """A ``--set`` value: a number, ``true``/``false``, ``none`` or a word (a transition)."""
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    if low == "none":
        return None
    try:
        return float(text)
    except ValueError:
        return text


def parse_set(text: str) -> tuple[str, list]:
    """``NS.KEY=V1,V2`` -> (``NS.KEY``, [V1, V2])."""
    key, _, vals = text.partition("=")
    if not vals or "." not in key:
        raise argparse.ArgumentTypeError(f"{text!r}: expected NAMESPACE.KEY=V1,V2")
    if key.split(".", 1)[0] not in ("pipe", "ctl", "sync", "accents", "policy"):
        raise argparse.ArgumentTypeError(f"{text!r}: the namespace is one of pipe, ctl, sync, "
                                         "accents, policy")
    return key, [parse_value(v) for v in vals.split(",")]


def expand(variants: dict[str, dict], sets: Sequence[tuple[str, list]]) -> dict[str, dict]:
    """Every variant crossed with the product of the ``--set`` values."""
    if not sets:
        return dict(variants)
    keys = [k for k, _ in sets]
    out = {}
    for name, opts in variants.items():
        for vals in itertools.product(*[v for _, v in sets]):
            extra = dict(zip(keys, vals, strict=True))
            label = ", ".join(f"{k.split('.', 1)[1]} {v}" for k, v in extra.items())
            out[f"{name}; {label}"] = {**opts, **extra}
    return out


def split_options(opts: dict) -> dict[str, dict]:
    """A variant's options by namespace."""
    out: dict[str, dict] = {ns: {} for ns in ("pipe", "ctl", "sync", "accents", "policy")}
    for key, value in opts.items():
        ns, name = key.split(".", 1)
        out[ns][name] = value
    return out


def pipeline_options(parts: dict[str, dict]) -> dict:
    """The GesturePipeline keywords of a variant for every method (``pipe``, ``sync``,
    ``accents``): the one place the driver speaks the pipeline's keyword interface."""
    from gesture_sim.audio.accents import AccentConfig
    from gesture_sim.control.synchrony import SyncSettings

    options = dict(parts["pipe"])
    sync = dict(parts["sync"])
    if "blend_frames" in options:
        sync.setdefault("blend_s", options["blend_frames"] / 30.0)
    if sync:
        options["sync"] = dataclasses.replace(SyncSettings(), **sync)
    if parts["accents"]:
        options["accents"] = dataclasses.replace(AccentConfig(), **parts["accents"])
    return options


def usage(segments: np.ndarray, dt: float) -> dict[str, float]:
    """Segment-usage figures of one run's per-step segments (``-1``: rest, left out)."""
    segs = np.asarray(segments, dtype=int)
    played = segs[segs >= 0]
    if len(played) == 0:
        return {"usage_entropy_bits": 0.0, "top5_share": 0.0, "back_to_back_s": float("nan")}
    _, counts = np.unique(played, return_counts=True)
    p = counts / counts.sum()
    change = np.nonzero(np.diff(segs) != 0)[0] + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(segs)]])
    last_end: dict[int, int] = {}
    gaps = []
    for s0, s1 in zip(starts, ends, strict=True):
        a = int(segs[s0])
        if a < 0:
            continue
        if a in last_end:
            gaps.append((s0 - last_end[a]) * dt)
        last_end[a] = s1
    return {"usage_entropy_bits": float(-(p * np.log2(p)).sum()),
            "top5_share": float(np.sort(p)[::-1][:5].sum()),
            "back_to_back_s": float(np.median(gaps)) if gaps else float("nan")}


def make_evaluator(physics: bool):
    """An :class:`~gesture_sim.app.evaluation.Evaluator` whose ``controller`` runs take the
    variant's ``ctl`` options too, and whose runs report their segment usage."""
    from gesture_sim.app.evaluation import Evaluator
    from gesture_sim.metrics.selection import selection_summary

    class SweepEvaluator(Evaluator):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            #: pipeline keywords for the controller's runs only
            self.controller_options: dict = {}

        def run_pipeline(self, method, inp, seed):
            common = self.pipeline_options
            if method == "controller":
                self.pipeline_options = {**common, **self.controller_options}
            try:
                run = super().run_pipeline(method, inp, seed)
            finally:
                self.pipeline_options = common
            pipe = run.run.pipeline
            sel = run.extra.setdefault("selection", {})
            sel.update(usage(np.asarray(pipe.log.segments, dtype=int), pipe.dt))
            s = selection_summary(run.run)
            sel.update({k: float(s[k]) for k in ("segments_played", "interrupted_share",
                                                  "back_to_back_repeats") if k in s})
            return run

    return SweepEvaluator(physics=physics)


def retrained_policy(ev, changes: dict):
    """The product's policy trained in memory with some ControlSettings fields changed."""
    from gesture_sim.control.inputs import StateModel
    from gesture_sim.control.policy import train_policy
    from gesture_sim.control.style import default_tones
    from gesture_sim.loading import policy_settings

    lib = ev.control_library
    settings = dataclasses.replace(policy_settings(), **changes)
    return train_policy(lib, StateModel.from_inference(ev.model), settings, tones=default_tones(),
                        labels=tuple(sorted(lib.all_tags())))


def cell(entry: dict, fmt: str) -> str:
    """``mean [seed SD]`` of a summary entry."""
    mean, sd = entry.get("mean", float("nan")), entry.get("seed_sd", float("nan"))
    return fmt.format(mean) + (f" [{sd:.3f}]" if sd == sd and sd > 0 else "")


def table(rows: dict[str, dict], columns: Sequence[str]) -> list[str]:
    """Markdown lines: one row per (variant, method)."""
    header = ["variant", "method", *(COLUMNS[k][0] for k in columns)]
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for name, by_method in rows.items():
        for method, summ in by_method.items():
            cells = [cell(summ.get(k, {}), COLUMNS[k][1]) for k in columns]
            lines.append(f"| {name} | {method} | " + " | ".join(cells) + " |")
    return lines


def run_sweep(sweep: Sweep, variants: dict[str, dict], audio: Sequence[str],
              textgrids: Sequence[str] = (), seeds: int = 2, physics: bool = False,
              show_cells: bool = False, log=print) -> dict:
    """Run ``variants`` of ``sweep``; return ``{"rows": {variant: {method: summary}},
    "cells": {variant: [lines]}}`` (summaries as :meth:`EvalResult.summary` gives them)."""
    from gesture_sim.app.evaluation import evaluate
    from gesture_sim.metrics.cells import file_cells

    ev = make_evaluator(physics)
    policies = {(): ev.policy}                  # policies by their changed settings
    rows: dict[str, dict] = {}
    cells: dict[str, list[str]] = {}
    judge = sweep.cells or show_cells
    for i, (name, opts) in enumerate(variants.items()):
        parts = split_options(opts)
        key = tuple(sorted(parts["policy"].items()))
        if key not in policies:
            policies[key] = retrained_policy(ev, parts["policy"])
        ev.policy = policies[key]
        ev.pipeline_options = pipeline_options(parts)
        ev.controller_options = dict(parts["ctl"])
        methods = list(sweep.methods)
        for b in (("random", "mismatched") if judge else ()) + (sweep.baselines if i == 0 else ()):
            if b not in methods:
                methods.append(b)
        res = evaluate(list(audio), methods=methods, seeds=seeds, evaluator=ev,
                       textgrids=list(textgrids))
        summ = res.summary()
        rows[name] = {m: summ[m] for m in methods if m in summ}
        if judge:
            c = file_cells(res.rows)
            cells[name] = [*c.lines, f"comparisons {c.passed}/{c.total}, "
                                     f"cells {c.cells_passed}/{c.cells}"]
        log(f"  {name}: done", file=sys.stderr)
    return {"rows": rows, "cells": cells}


def report_cells(path: str, subsets: Sequence[int]) -> list[str]:
    """The per-file cells of a saved ``eval motion --report`` for all its seeds and for
    consecutive blocks of ``subsets`` seeds (how much a verdict depends on the seeds)."""
    from gesture_sim.metrics.cells import file_cells

    with open(path, encoding="utf-8") as fh:
        rows = json.load(fh)["rows"]
    seeds = sorted({int(r["seed"]) for r in rows})
    c = file_cells(rows)
    lines = [f"seeds {seeds[0]}-{seeds[-1]}: comparisons {c.passed}/{c.total}, "
             f"cells {c.cells_passed}/{c.cells}", *c.lines]
    for size in subsets:
        for i in range(0, len(seeds) - size + 1, size):
            sub = set(seeds[i:i + size])
            c = file_cells([r for r in rows if int(r["seed"]) in sub])
            lines.append(f"seeds {min(sub)}-{max(sub)}: comparisons {c.passed}/{c.total}, "
                         f"cells {c.cells_passed}/{c.cells}")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="sweeps:\n" + "\n".join(
                                     f"  {n:12s} {s.doc}" for n, s in SWEEPS.items()))
    ap.add_argument("sweep", nargs="?", help="the sweep's name (--list shows them)")
    ap.add_argument("audio", nargs="*", help="speech files (WAV ...)")
    ap.add_argument("--list", action="store_true", help="list the sweeps and their variants")
    ap.add_argument("--textgrid", action="append", default=[], metavar="FILE",
                    help="a TextGrid of one of the files (repeat the option)")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per method and file (default 2)")
    ap.add_argument("--physics", action="store_true", help="the simulated body (slow)")
    ap.add_argument("--variants", nargs="+", default=["all"], metavar="NAME",
                    help="the variants to run (default: all of the sweep's)")
    ap.add_argument("--set", type=parse_set, action="append", default=[], metavar="NS.KEY=V,..",
                    help="cross every variant with these values (repeatable)")
    ap.add_argument("--cells", action="store_true", help="also print the per-file cells")
    ap.add_argument("--json", metavar="OUT", help="also write the summaries as JSON")
    ap.add_argument("--report", metavar="REPORT", help="the cells of a saved eval report")
    ap.add_argument("--subset", type=int, action="append", default=[],
                    help="with --report: also blocks of this many seeds (repeatable)")
    args = ap.parse_args(argv)
    if args.list:
        for name, sweep in SWEEPS.items():
            print(f"{name}: {sweep.doc}")
            for v, opts in sweep.variants.items():
                print(f"    {v}: {opts or 'the defaults'}")
        return 0
    if args.report:
        print("\n".join(report_cells(args.report, args.subset)))
        return 0
    if args.sweep not in SWEEPS:
        ap.error(f"unknown sweep {args.sweep!r}; choose from {', '.join(SWEEPS)}")
    if not args.audio:
        ap.error("give at least one speech file")
    sweep = SWEEPS[args.sweep]
    names = list(sweep.variants) if args.variants == ["all"] else args.variants
    unknown = [n for n in names if n not in sweep.variants]
    if unknown:
        ap.error(f"unknown variant(s) {unknown}; choose from {list(sweep.variants)}")
    variants = expand({n: sweep.variants[n] for n in names}, args.set)
    out = run_sweep(sweep, variants, args.audio, args.textgrid, args.seeds, args.physics,
                    args.cells)
    print("\n".join(table(out["rows"], sweep.columns)))
    for name, lines in out["cells"].items():
        print(f"\ncells, {name}:")
        print("\n".join(lines))
    if args.json:
        Path(args.json).write_text(json.dumps({"sweep": args.sweep, "variants": variants, **out},
                                              indent=1, default=str) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
