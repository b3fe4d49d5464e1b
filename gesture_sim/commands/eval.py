"""``gesture-sim eval MODE ...``: evaluations that print a table (or JSON with ``--json``).

Modes are sub-commands registered from :data:`EVAL_MODES` (module path, function name); each
adds its own parser. ``inference`` is the paper's Figure 4 (held-out likelihood per step of
the remapped CRF and of an HMM over the same input windows). ``motion`` scores the simulated
body's motion on speech files against baselines and real motion
(:mod:`gesture_sim.app.evaluation`). A bare ``gesture-sim eval AUDIO...`` (first argument an
existing file) means ``gesture-sim eval motion AUDIO...``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gesture_sim.commands import print_json

if TYPE_CHECKING:
    from gesture_sim.app.batch import DaskTarget
    from gesture_sim.app.evaluation import MotionRun

#: (module, register function) of each evaluation mode, in ``--help`` order.
EVAL_MODES = (
    ("gesture_sim.commands.eval_inference", "register"),
    ("gesture_sim.commands.eval", "register_motion"),
)
#: The mode a bare ``eval FILE ...`` runs.
DEFAULT_FILE_MODE = "motion"


class _ModeChoices(dict):
    """The mode table; an existing file also counts as a valid choice (the bare form)."""

    def __contains__(self, key: object) -> bool:
        return dict.__contains__(self, key) or (
            isinstance(key, str) and DEFAULT_FILE_MODE in self.keys() and os.path.isfile(key))


class _ModesAction(argparse._SubParsersAction):
    """Sub-parser action that routes ``eval FILE ...`` to ``eval motion FILE ...``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._name_parser_map = _ModeChoices()
        self.choices = self._name_parser_map

    def __call__(self, parser, namespace, values, option_string=None):
        if values and not dict.__contains__(self._name_parser_map, values[0]):
            values = [DEFAULT_FILE_MODE, *values]
        return super().__call__(parser, namespace, values, option_string)


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "eval", help="evaluate models and output (`eval motion AUDIO...`: motion vs baselines "
                     "and real motion; `eval inference`: CRF vs HMM, Fig. 4)",
        description="Evaluations; each mode prints a table, or JSON with --json. "
                    "`gesture-sim eval AUDIO...` is short for `gesture-sim eval motion AUDIO...`.",
    )
    modes = parser.add_subparsers(dest="eval_mode", metavar="MODE", action=_ModesAction)
    for module_name, fn in EVAL_MODES:   # a mode that fails to import is a broken install:
        getattr(importlib.import_module(module_name), fn)(modes)   # say so, do not hide it
    if "inference" in modes.choices:
        _with_checks(modes.choices["inference"], _check_inference)
    parser.set_defaults(func=lambda args: parser.print_help() or 1)


def _with_checks(parser: argparse.ArgumentParser, check) -> None:
    """Run ``check(args)`` before the parser's command function."""
    func = parser.get_default("func")

    def checked(args: argparse.Namespace) -> int:
        check(args)
        return func(args)

    parser.set_defaults(func=checked)


def _check_inference(args: argparse.Namespace) -> None:
    """Argument checks of ``eval inference`` (before any pair is loaded)."""
    from gesture_sim import validation as v
    from gesture_sim.commands.train import check_pairs

    if getattr(args, "states", None) is not None:
        v.integer("--states", args.states, 2, 64)
    v.integer("--clusters", args.clusters, 2, 64)
    v.number("--held-out", args.held_out, 0.05, 0.9, hint=" (share of each pair)")
    for w in args.windows:
        v.integer("--windows", w, 0, 16, hint=" steps")
    v.seed("--seed", args.seed)
    check_pairs("--pair", args.pair)
    check_pairs("--test-pair", args.test_pair)


# ------------------------------------------------------------------------------------------
# eval motion
# ------------------------------------------------------------------------------------------


def register_motion(modes: argparse._SubParsersAction) -> None:
    """Add the ``motion`` mode."""
    parser = modes.add_parser(
        "motion", help="objective motion metrics (BC, coupling, FGD, jerk, plausibility) of the "
                       "gesture controller vs random selection, Levine 2009 and real motion",
        description=(
            "Run every method on every AUDIO file through the causal pipeline with physics and "
            "score the simulated body's motion: beat consistency (and its chance level), "
            "prosody-motion coupling, FGD and speed histograms against the library's real "
            "co-speech motion, diversity, jerk, transition jerk, and physical plausibility. "
            "Methods: controller, levine09, random, real (the audio's own motion capture, given "
            "with --reference, retargeted and tracked by the same physics) and mismatched (the "
            "controller's motion scored against another file's audio: a chance-level control)."
        ),
    )
    parser.add_argument("audio", nargs="+", type=Path, metavar="AUDIO", help="speech files")
    parser.add_argument("--reference", action="append", type=Path, default=[], metavar="MOTION",
                        help="motion capture (.bvh or SMPL-X .npz) of the audio file with the "
                             "same name (or of the only audio file); repeatable")
    parser.add_argument("--textgrid", action="append", type=Path, default=[], metavar="FILE",
                        help="Praat TextGrid (words + ARPAbet phones with stress digits) of the "
                             "audio file with the same name: adds the stroke-to-stress timing "
                             "(share of stressed vowels with a hand-speed peak within ±0.2 s, "
                             "median error); repeatable")
    parser.add_argument("--no-physics", action="store_true",
                        help="score the kinematic targets on the standing body instead of the "
                             "simulated body (fast; no physics figures)")
    parser.add_argument("--methods", nargs="+", default=None, metavar="METHOD",
                        help="subset of: controller levine09 random random_sync real "
                             "mismatched (default all but random_sync; random_sync is random "
                             "choice behind the same timing layer)")
    parser.add_argument("--seeds", type=int, default=3, metavar="N",
                        help="seeds 0..N-1 per method and file, for spreads (default 3)")
    parser.add_argument("--library", type=Path, default=None,
                        help="motion library folder (default: the shipped one)")
    parser.add_argument("--model", type=Path, default=None,
                        help="inference model folder (default: LIBRARY/model, else the "
                             "shipped model)")
    parser.add_argument("--report", type=Path, default=None, metavar="DIR",
                        help="write report.json, table.md, bars.png, velocity_hist.png and "
                             "timelines/ into DIR")
    parser.add_argument("--no-timelines", action="store_true",
                        help="with --report: skip the per-run timeline figures")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="run the (method, seed, file) runs in N worker processes (one "
                             "core each; default 1); the figures are the same as a serial "
                             "run's (same seeds). With --report the per-run timelines are "
                             "drawn by the workers; the compare figures then lack the "
                             "speech-intensity panel")
    parser.add_argument("--dask", default=None, metavar="ADDRESS",
                        help="run the runs as jobs on a Dask cluster: local (one "
                             "single-threaded worker process per CPU), local:N, or a scheduler "
                             "address such as tcp://host:8786 (every worker must see the "
                             "files, as given). Needs gesture_sim[dask]")
    parser.set_defaults(func=run_motion)


def run_motion(args: argparse.Namespace) -> int:
    import functools
    import shlex

    from gesture_sim import validation as v
    from gesture_sim.app.batch import check_dask, check_jobs
    from gesture_sim.errors import GestureSimError

    v.integer("--seeds", args.seeds, 1, 100)
    check_jobs("--jobs", args.jobs)
    target = check_dask("--dask", args.dask) if args.dask is not None else None
    for a in args.audio:
        v.input_file("AUDIO", a, "audio file")
    for r in args.reference:
        v.motion_file("--reference", r)
    for r in args.textgrid:
        v.input_file("--textgrid", r, "TextGrid")
    for name in ("library", "model"):
        if getattr(args, name) is not None:
            v.input_folder(f"--{name}", getattr(args, name))
    if args.report is not None:
        v.check_outputs([v.Output("--report", args.report, folder=True)],
                        inputs=[*args.audio, *args.reference,
                                *v.inputs_of(args, "textgrid", "library", "model")])

    from gesture_sim.app import evaluation as ev
    from gesture_sim.app.report import write_report_files
    from gesture_sim.fileio import atomic_folder
    from gesture_sim.progress import progress

    methods = args.methods or list(ev.DEFAULT_METHODS)
    bad = [m for m in methods if m not in ev.EVAL_METHODS]
    if bad:
        raise GestureSimError(f"unknown method {bad[0]!r}; choose from "
                              f"{', '.join(ev.EVAL_METHODS)}")
    if args.methods and "real" in methods and not args.reference:
        raise GestureSimError("--methods real needs --reference MOTION (the audio's own motion "
                              "capture)")
    if args.methods and "mismatched" in methods and len(args.audio) < 2:
        raise GestureSimError("--methods mismatched needs at least two AUDIO files (each "
                              "file's motion is scored against another file's audio)")
    refs = ev.match_references(args.audio, args.reference)
    show = not args.json
    grids = ev.match_references(args.audio, args.textgrid, kind="TextGrid")
    if grids:    # their times and stressed vowels, before the stack loads
        from gesture_sim.audio.sources import audio_duration_s
        from gesture_sim.audio.textgrid import read_textgrid
        from gesture_sim.metrics.inputs import check_textgrid_times, stress_note

        for i, path in grids.items():
            grid = read_textgrid(path)
            check_textgrid_times(grid, path, audio_duration_s(args.audio[i]))
            note = stress_note(grid, path)
            if note is not None:
                print(f"gesture-sim: warning: {note}", file=sys.stderr)
    report = None
    if args.report is not None:   # every file of the report, before the work
        report = v.check_outputs(
            report_outputs(args.report, args.audio, methods, not args.no_timelines),
            inputs=[*args.audio, *args.reference,
                    *v.inputs_of(args, "textgrid", "library", "model")])[0]
    command = "gesture-sim " + " ".join(shlex.quote(a) for a in sys.argv[1:]) \
        if sys.argv and Path(sys.argv[0]).name.startswith("gesture-sim") else ""
    # the report is drawn into a staging folder (the workers of --jobs draw their timelines
    # there too) and published all at once at the end: a failure or a signal leaves a
    # previous report as it was
    with contextlib.ExitStack() as stack:
        stage = stack.enter_context(atomic_folder(report)) if report is not None else None
        evaluator = ev.Evaluator(args.library, args.model, physics=not args.no_physics)
        total = ev.n_runs(len(args.audio), len(refs), methods, args.seeds)
        bar = stack.enter_context(contextlib.closing(
            progress(total=total, desc="evaluating", enabled=show, unit="run")))
        parallel = {}
        if args.jobs > 1 or target is not None:
            parallel["run_jobs"] = functools.partial(_run_jobs, n_jobs=args.jobs, dask=target)
            if stage is not None and not args.no_timelines:
                parallel["in_worker"] = functools.partial(draw_timeline, stage / "timelines")
        result = ev.evaluate(args.audio, args.reference, methods, args.seeds, evaluator,
                             on_step=lambda text: (bar.set_postfix_str(text), bar.update(1)),
                             textgrids=args.textgrid, **parallel)
        bar.close()
        if stage is not None:
            write_report_files(result, stage, command=command, timelines=not args.no_timelines)
    if args.json:
        data = result.to_dict()
        data["command"] = command
        print_json(data)
        return 0
    print(ev.format_table(result, markdown=False))
    verdicts = ev.coupling_verdicts(result.summary())
    if verdicts:
        print("\nDoes the motion follow the speech? (margin over random selection and over "
              "mismatched audio, against the seed spread)")
        print(ev.format_verdicts(verdicts))
    t = result.timing
    print(f"\n{len(result.rows)} runs on {t['audio_s']:.0f} s of audio in {t['total_s']:.0f} s"
          f"; FGD extractor {result.info['fgd_extractor']}"
          + (f"; report in {args.report}" if args.report else ""))
    return 0


def report_outputs(folder: Path, audio: list[Path], methods: list[str],
                   timelines: bool) -> list:
    """The outputs of ``--report DIR`` for :func:`gesture_sim.validation.check_outputs`: the
    folder, and every file (and ``timelines/``) the report may write in it, so that a folder
    or special file where one goes fails before the work, not after it. The timeline names are
    those :func:`gesture_sim.app.evaluation.evaluate` gives the inputs (the file stem,
    ``_2``, ``_3`` ... for repeated stems): all it may use."""
    from gesture_sim import validation as v
    from gesture_sim.app.evaluation import PIPELINE_METHODS
    from gesture_sim.app.report import REPORT_FILES

    outs = [v.Output("--report", folder, folder=True)]
    outs += [v.Output("--report", folder / name, within=folder) for name in REPORT_FILES]
    if timelines:
        sub = folder / "timelines"
        outs.append(v.Output("--report", sub, folder=True, within=folder))
        names: list[str] = []
        for a in audio:
            base, name, k = Path(a).stem, Path(a).stem, 2
            while name in names:
                name, k = f"{base}_{k}", k + 1
            names.append(name)
        drawn = [m for m in PIPELINE_METHODS if m in methods] + ["compare"]
        outs += [v.Output("--report", sub / f"{n}_{m}.png", within=folder)
                 for n in names for m in drawn]
    return outs


def _run_jobs(calls: list[tuple[str, Callable[..., Any], tuple]],
              on_done: Callable[[int, Any], None], *, n_jobs: int,
              dask: DaskTarget | None) -> list[Any]:
    """``evaluate(run_jobs=...)``: the runs as jobs of :func:`gesture_sim.app.batch.run_jobs`
    (no bar of its own: the command's bar counts the runs); the first failure ends them all."""
    from gesture_sim.app.batch import Job, run_jobs

    jobs = [Job(label, fn, tuple(fn_args)) for label, fn, fn_args in calls]
    outcomes = run_jobs(jobs, n_jobs=n_jobs, dask=dask, show_progress=False, fail_fast=True,
                        on_done=lambda i, o: on_done(i, o.value) if o.ok else None)
    return [o.value for o in outcomes]


def draw_timeline(folder: Path, run: MotionRun) -> None:
    """In a worker of ``eval --jobs --report``: the run's timeline figure, as the report draws
    it (``timelines/<audio>_<method>.png``), while the pipeline is still there."""
    from gesture_sim.app.render import timeline_data
    from gesture_sim.app.timeline import plot_timeline

    folder.mkdir(parents=True, exist_ok=True)
    plot_timeline(timeline_data(run.run, title=f"{run.audio} — {run.method}"),
                  folder / f"{run.audio}_{run.method}.png")
