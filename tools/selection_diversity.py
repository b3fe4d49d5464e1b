#!/usr/bin/env python3
"""Which segments does the controller choose, and how varied? (issue 31, "dynamics like real clips")

    .venv/bin/python tools/selection_diversity.py AUDIO... [--textgrid TG ...] [--seeds 3]
        [--first-seed 0] [--variants all|NAME ...] [--baselines random_sync random mismatched]
        [--physics] [--json OUT]

Every variant runs the controller through :func:`gesture_sim.app.evaluation.evaluate` (kinematic
targets unless ``--physics``) with some controller options (the softmin ``temperature``, the
novelty term ``repeat_cost`` / ``repeat_tau_s`` and the posterior sampling ``sample_state`` of
:class:`~gesture_sim.control.controller.GestureController`); the baselines (``random_sync``:
random choice behind the same timing layer, ``random``: real clips at random, ``mismatched``:
the default controller scored against another file's audio) run once, in the same evaluation
as the first variant. Besides the evaluation's figures (FGD, Hellinger speed, discriminator,
accent hits − chance, r(speed, intensity), BC − chance, switches/min) each run reports its
segment usage from the pipeline's log (control steps, rest left out):

* ``distinct_segments``: segments played at all;
* ``usage_entropy_bits``: entropy (bits) of the played-frames distribution over segments;
* ``top5_share``: share of the played frames from the run's five most-played segments;
* ``back_to_back_s``: median time (s) between a segment's end and its next entry (a replay);

and over all runs of a method: how many of the library's co-speech segments were ever played.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict

import numpy as np

#: variant -> controller options (GesturePipeline's ``temperature``; the controller's
#: ``repeat_cost``, ``repeat_tau_s``). "default" is the controller as shipped.
VARIANTS: dict[str, dict] = {
    "default": {},
    "T=0 (argmin)": {"temperature": 0.0},
    "T=4": {"temperature": 4.0},
    "T=8": {"temperature": 8.0},
    "repeat 4, 10 s": {"repeat_cost": 4.0, "repeat_tau_s": 10.0},
    "repeat 8, 10 s": {"repeat_cost": 8.0, "repeat_tau_s": 10.0},
    "repeat 8, 20 s": {"repeat_cost": 8.0, "repeat_tau_s": 20.0},
    "repeat 16, 20 s": {"repeat_cost": 16.0, "repeat_tau_s": 20.0},
    "repeat 8, 20 s, T=4": {"repeat_cost": 8.0, "repeat_tau_s": 20.0, "temperature": 4.0},
    # diagnostics: a policy retrained in memory with another fit weight (the shipped one: 2)
    "fit 1 (retrained)": {"fit_weight": 1.0},
    "fit 0.5 (retrained)": {"fit_weight": 0.5},
    "fit 1, repeat 8, 20 s": {"fit_weight": 1.0, "repeat_cost": 8.0, "repeat_tau_s": 20.0},
    "fit 0.5, repeat 8, 20 s": {"fit_weight": 0.5, "repeat_cost": 8.0, "repeat_tau_s": 20.0},
    "repeat 16, 40 s": {"repeat_cost": 16.0, "repeat_tau_s": 40.0},
    "repeat 32, 20 s": {"repeat_cost": 32.0, "repeat_tau_s": 20.0},
    "sample state": {"sample_state": True},
    "sample state, repeat 8, 20 s": {"sample_state": True, "repeat_cost": 8.0,
                                     "repeat_tau_s": 20.0},
    "sample state, repeat 16, 20 s": {"sample_state": True, "repeat_cost": 16.0,
                                      "repeat_tau_s": 20.0},
    "sample state, T=0": {"sample_state": True, "temperature": 0.0},
    "sample state, repeat 16, 40 s": {"sample_state": True, "repeat_cost": 16.0,
                                      "repeat_tau_s": 40.0},
}
#: the controller's own options (set on it after the pipeline is built)
CONTROLLER_OPTIONS = ("repeat_cost", "repeat_tau_s", "sample_state")
#: options of the policy's training (a policy retrained in memory; nothing is saved)
POLICY_OPTIONS = ("fit_weight",)

#: (summary key, column header, format).
COLUMNS = (
    ("fgd", "FGD ↓", "{:.1f}"),
    ("hellinger_speed", "Hellinger speed ↓", "{:.3f}"),
    ("disc_accuracy", "discriminator ↓", "{:.3f}"),
    ("accent_hit_excess", "accent hits − chance ↑", "{:.3f}"),
    ("r_intensity_best", "r(speed, intensity) ↑", "{:.3f}"),
    ("bc_excess", "BC − chance ↑", "{:.3f}"),
    ("switches_per_min", "switches / min", "{:.0f}"),
    ("distinct_segments", "distinct", "{:.1f}"),
    ("usage_entropy_bits", "entropy (bits)", "{:.2f}"),
    ("top5_share", "top-5 share", "{:.2f}"),
    ("back_to_back_s", "replay gap (s)", "{:.1f}"),
)


def usage(segments: np.ndarray, dt: float) -> dict[str, float]:
    """Segment-usage figures of one run's per-step segments (``-1``: rest, left out)."""
    segs = np.asarray(segments, dtype=int)
    played = segs[segs >= 0]
    if len(played) == 0:
        return {"distinct_segments": 0.0, "usage_entropy_bits": 0.0, "top5_share": 0.0,
                "back_to_back_s": float("nan")}
    _, counts = np.unique(played, return_counts=True)
    p = counts / counts.sum()
    # replay gaps: time from the end of a stretch of segment a to the next stretch of a
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
    return {"distinct_segments": float(len(counts)),
            "usage_entropy_bits": float(-(p * np.log2(p)).sum()),
            "top5_share": float(np.sort(p)[::-1][:5].sum()),
            "back_to_back_s": float(np.median(gaps)) if gaps else float("nan")}


def make_evaluator(physics: bool):
    """An :class:`~gesture_sim.app.evaluation.Evaluator` whose pipeline runs also take the
    controller's own options and report their segment usage."""
    from gesture_sim.app.evaluation import Evaluator

    class UsageEvaluator(Evaluator):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            self.controller_options: dict = {}
            #: method label -> segments ever played (over all its runs)
            self.used: dict[str, set[int]] = defaultdict(set)
            self.label = ""

        def run_pipeline(self, method, inp, seed):
            import gesture_sim.pipeline as gp

            options = dict(self.controller_options) if method == "controller" else {}
            base = gp.GesturePipeline
            captured = {}

            class Configured(base):
                def __init__(self, *a, **kw) -> None:
                    super().__init__(*a, **kw)
                    for key, value in options.items():
                        setattr(self.controller, key, value)
                    captured["pipe"] = self

            gp.GesturePipeline = Configured
            try:
                run = super().run_pipeline(method, inp, seed)
            finally:
                gp.GesturePipeline = base
            pipe = captured["pipe"]
            segs = np.asarray(pipe.log.segments, dtype=int)
            run.extra.setdefault("selection", {}).update(usage(segs, pipe.dt))
            key = self.label if method == "controller" else method
            self.used[key].update(int(s) for s in np.unique(segs[segs >= 0]))
            return run

    return UsageEvaluator(physics=physics)


def retrained(ev, changes: dict):
    """The product's policy (:func:`gesture_sim.loading.train_library_policy`) trained in
    memory with some settings changed (e.g. ``fit_weight``)."""
    import dataclasses

    from gesture_sim.control.inputs import StateModel
    from gesture_sim.control.policy import train_policy
    from gesture_sim.control.style import default_tones
    from gesture_sim.loading import policy_settings

    lib = ev.control_library
    settings = dataclasses.replace(policy_settings(), **changes)
    return train_policy(lib, StateModel.from_inference(ev.model), settings, tones=default_tones(),
                        labels=tuple(sorted(lib.all_tags())))


def cell(entry: dict, fmt: str) -> str:
    mean, sd = entry.get("mean", float("nan")), entry.get("seed_sd", float("nan"))
    return fmt.format(mean) + (f" [{fmt.format(sd)}]" if sd == sd and sd > 0 else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("audio", nargs="+", help="speech files (WAV ...)")
    ap.add_argument("--textgrid", action="append", default=[], metavar="FILE",
                    help="a TextGrid of one of the files (repeat)")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per method and file (default 3)")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="the first seed (default 0: seeds 0 .. SEEDS-1)")
    ap.add_argument("--variants", nargs="+", default=["default"],
                    help=f"controller variants (default: default; 'all'): {', '.join(VARIANTS)}")
    ap.add_argument("--baselines", nargs="*", default=["random_sync", "random", "mismatched"],
                    help="baseline methods run with the first variant (default: random_sync "
                         "random mismatched)")
    ap.add_argument("--physics", action="store_true", help="the simulated body (slow)")
    ap.add_argument("--json", metavar="OUT", help="also write the summaries as JSON")
    args = ap.parse_args(argv)
    names = list(VARIANTS) if args.variants == ["all"] else args.variants
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        print(f"error: unknown variant(s) {unknown}; choose from {list(VARIANTS)}",
              file=sys.stderr)
        return 2

    from gesture_sim.app.evaluation import evaluate

    ev = make_evaluator(args.physics)
    n_cospeech = int(np.asarray(ev.control_library.cospeech).sum())
    shipped_policy = ev.policy
    rows: dict[str, dict] = {}
    for i, name in enumerate(names):
        opts = VARIANTS[name]
        ev.policy = shipped_policy
        if any(k in opts for k in POLICY_OPTIONS):
            ev.policy = retrained(ev, {k: opts[k] for k in POLICY_OPTIONS if k in opts})
        ev.pipeline_options = {k: v for k, v in opts.items()
                               if k not in CONTROLLER_OPTIONS + POLICY_OPTIONS}
        ev.controller_options = {k: v for k, v in opts.items() if k in CONTROLLER_OPTIONS}
        methods = ["controller"] + (list(args.baselines) if i == 0 else [])
        if "mismatched" in methods and opts:
            methods.remove("mismatched")      # mismatched: the shipped controller's motion
        ev.label = f"controller {name}"
        seeds = list(range(args.first_seed, args.first_seed + args.seeds))
        res = evaluate(args.audio, methods=methods, seeds=seeds, evaluator=ev,
                       textgrids=args.textgrid)
        summ = res.summary()
        for m in methods:
            if m not in summ:
                continue
            key = f"controller {name}" if m == "controller" else m
            rows[key] = summ[m]
            used = ev.used.get(key, set())
            rows[key]["ever_used"] = {"mean": float(len(used)), "seed_sd": 0.0}
        print(f"  {name}: done", file=sys.stderr)
    from gesture_sim.metrics.summary import coupling_verdicts

    base = {b: rows[b] for b in ("random", "mismatched") if b in rows}
    verdicts = coupling_verdicts({**base, **{k: v for k, v in rows.items() if k not in base}})
    header = ["run", *(h for _, h, _ in COLUMNS), f"ever used (of {n_cospeech})",
              "coupling figures beating random & mismatched by > spread"]
    print("| " + " | ".join(header) + " |")
    print("|" + " --- |" * len(header))
    for key, summ in rows.items():
        cells = [cell(summ.get(k, {}), fmt) for k, _, fmt in COLUMNS]
        cells.append(f"{summ['ever_used']['mean']:.0f}")
        figs = verdicts.get(key, {}).get("figures", {})
        cells.append(f"{sum(f['beats_all'] for f in figs.values())}/{len(figs)}" if figs else "")
        print(f"| {key} | " + " | ".join(cells) + " |")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"variants": {n: VARIANTS[n] for n in names}, "rows": rows,
                       "cospeech_segments": n_cospeech, "verdicts": verdicts}, fh, indent=1,
                      default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
