"""``gesture-sim train --pair MOTION AUDIO [--pair ...] -o MODEL``: train the inference layer;
``gesture-sim train --corpus DIR -o MODEL_DIR``: train a whole stack from a corpus folder;
``gesture-sim train --signs TAKES_DIR -o MODEL_DIR``: train chiu14's sign predictor.

With ``--pair``: fits the prosody clusters, the kinematic HMM (number of states by held-out
likelihood unless ``--states``), the remapped CRF and the Levine 2009 baseline on motion +
speech pairs, and writes the model folder (``model.json`` + ``model.npz``). With ``--corpus``:
builds the motion library of the corpus's motion/speech pairs, trains the model on them with
the library's normalisation and solves the controller policy, and writes a library folder laid
out like motion_library/default (``--library MODEL_DIR`` renders with it). With ``--signs``:
fits Chiu 2014's sign predictor (``--method chiu14``) on sign-annotated takes (speech, words
and sign annotations per take) and writes signs.npz + signs.json (the layout is below).

The corpus is the BEAT2 layout (DIR/smplxflame_30/*.npz + DIR/wave16k/*.wav, optional
DIR/textgrid/*.TextGrid, paired by stem) or a folder of .bvh / SMPL-X .npz motion files each
with a .wav (optional .TextGrid) of the same stem beside it; see :mod:`gesture_sim.corpus`.
"""

from __future__ import annotations

import argparse
import math

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    import textwrap

    from gesture_sim.commands.train_signs import add_arguments as add_sign_arguments
    from gesture_sim.commands.train_signs import layout_help

    fill = textwrap.TextWrapper(88).fill
    parser = sub.add_parser(
        "train", help="train the inference model (HMM + remapped CRF) on motion/speech pairs, "
        "or the sign predictor on sign-annotated takes (--signs)",
        description=fill(" ".join(__doc__.split("\n\n")[1].split())) if __doc__ else None,
        epilog=fill("A new motion library does not need a new model: build it with the model's "
                    "normalisation (`gesture-sim library build ... --normalisation-from MODEL`) "
                    "and train only its control layer (`gesture-sim library policy LIBRARY "
                    "--model MODEL`, or let the first render do it).") + "\n\n" + layout_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = parser.add_mutually_exclusive_group(required=True)
    add_pair_arguments(source, required=False)
    source.add_argument("--corpus", metavar="DIR",
                        help="train library + model + policy from a corpus folder: the BEAT2 "
                        "layout (smplxflame_30/*.npz, wave16k/*.wav, optional textgrid/) or "
                        "motion files (.bvh / SMPL-X .npz) each with a .wav of the same stem "
                        "beside it")
    source.add_argument("--signs", metavar="TAKES_DIR",
                        help="train chiu14's sign predictor on sign-annotated takes: per stem "
                        "speech, words (.TextGrid or .txt) and sign annotations (.signs.csv, "
                        "ELAN .signs.txt or a 'signs' TextGrid tier); layout below")
    parser.add_argument("-o", "--output", metavar="MODEL",
                        help="output folder (created): with --pair the model (model.json + "
                        "model.npz); with --corpus a library folder (library.npz, "
                        "manifest.json, model/ with the model and its policy, README.md); "
                        "with --signs the sign model (signs.npz + signs.json)")
    parser.add_argument("--states", type=int, metavar="N",
                        help="number of hidden states (default: chosen by held-out likelihood)")
    parser.add_argument("--clusters", type=int, default=8, metavar="K",
                        help="prosody clusters (default 8)")
    parser.add_argument("--window", type=int, default=4, metavar="W",
                        help="CRF input window in steps (default 4, the paper's best)")
    parser.add_argument("--rate", type=float, default=30.0, metavar="HZ",
                        help="inference steps per second (default 30 = the clip frame rate)")
    parser.add_argument("--library", metavar="FOLDER",
                        help="motion library whose parameter normalisation the model uses "
                        "(default: fitted on the training motion; a library built with "
                        "`library build --normalisation-from` an existing model needs no new "
                        "model)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    c = parser.add_argument_group("corpus options (with --corpus)")
    c.add_argument("--speaker", metavar="NAME",
                   help="only this speaker's pairs: BEAT2 stems' second token (scott in "
                   "2_scott_0_1_1; the id 2 works too), else the top-level subfolder name")
    c.add_argument("--list", action="store_true",
                   help="list the corpus's speakers and pairs, then stop (no -o needed)")
    c.add_argument("--cache", metavar="DIR",
                   help="where the per-file analyses are kept, keyed by content hash, so an "
                   "interrupted run resumes (default MODEL_DIR/.cache)")
    c.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="worker processes for the per-file analysis (default 1)")
    c.add_argument("--dask", metavar="ADDRESS",
                   help="run the per-file analysis on Dask: local, local:N or a scheduler "
                   "address (the workers must see the files and the cache folder)")
    c.add_argument("--on-error", choices=("stop", "skip"), default="stop", dest="on_error",
                   help="a broken file: stop with its name (default), or skip it with a "
                   "warning and list it in the summary and README")
    add_sign_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.set_defaults(func=run)


def add_pair_arguments(parser: argparse.ArgumentParser | argparse._ActionsContainer,
                       required: bool = True) -> None:
    """``--pair MOTION AUDIO`` (repeatable)."""
    parser.add_argument("--pair", nargs=2, action="append", metavar=("MOTION", "AUDIO"),
                        required=required, default=None,
                        help="a motion file (BVH or SMPL-X .npz) and its speech (WAV ...); "
                        "repeat for more pairs")


def load_pairs(pairs: list[list[str]], enabled: bool = True) -> list:
    """Load motion/speech pairs with a progress bar."""
    from gesture_sim.commands.library import name_the_file
    from gesture_sim.errors import GestureSimError
    from gesture_sim.inference.train import load_pair
    from gesture_sim.progress import progress

    takes = []
    for motion, audio in progress(pairs, desc="loading pairs", enabled=enabled, unit="pair"):
        try:
            takes.append(load_pair(motion, audio))
        except GestureSimError as exc:
            named = str(motion) in str(exc) or str(audio) in str(exc)
            raise (exc if named else name_the_file(exc, f"--pair {motion} {audio}")) from None
    return takes


def check_pairs(name: str, pairs: list[list[str]] | None) -> None:
    """Every MOTION and AUDIO of ``--pair`` is a readable regular file."""
    from gesture_sim import validation as v

    for motion, audio in pairs or []:
        v.motion_file(f"{name} MOTION", motion)
        v.input_file(f"{name} AUDIO", audio, "audio file")


def check_pair_durations(takes: list, pairs: list[list[str]]) -> None:
    """Refuse a pair whose motion and speech are not of the same take
    (:func:`gesture_sim.inference.train.check_pair_duration`)."""
    from gesture_sim.inference.train import check_pair_duration

    for take, (motion, audio) in zip(takes, pairs, strict=True):
        a_s = getattr(take, "audio_duration_s", None)
        if a_s is not None:
            check_pair_duration(take.motion.n_frames / take.motion.fps, a_s,
                                f"--pair {motion} {audio}")


def library_normalisation(folder: str | None) -> tuple[dict | None, str | None]:
    """(param_normalisation, fingerprint) of a library folder, or (None, None)."""
    if folder is None:
        return None, None
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(folder)
    return lib.param_normalisation, lib.fingerprint


def _check_settings(args: argparse.Namespace) -> None:
    from gesture_sim import validation as v

    if args.states is not None:
        v.integer("--states", args.states, 2, 64)
    v.integer("--clusters", args.clusters, 2, 64)
    v.integer("--window", args.window, 1, 16, hint=" steps")
    v.number("--rate", args.rate, 1.0, 120.0, hint=" steps per second")
    v.seed("--seed", args.seed)


def _train_settings(args: argparse.Namespace):
    from dataclasses import replace

    from gesture_sim.inference.features import StepSettings
    from gesture_sim.inference.train import TrainSettings

    return TrainSettings(n_states=args.states, n_clusters=args.clusters, window=args.window,
                         seed=args.seed, steps=replace(StepSettings(), rate_hz=args.rate))


#: Options that only mean something with --corpus, and their defaults.
_CORPUS_ONLY = {"speaker": None, "list": False, "cache": None, "jobs": 1, "dask": None,
                "on_error": "stop"}


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError

    _check_settings(args)
    if getattr(args, "signs", None) is not None:
        from gesture_sim.commands.train_signs import run_signs

        return run_signs(args, _CORPUS_ONLY)
    from gesture_sim.commands.train_signs import check_signs_only

    check_signs_only(args)
    if args.corpus is not None:
        return run_corpus(args)
    for name, default in _CORPUS_ONLY.items():
        if getattr(args, name) != default:
            flag = "--" + name.replace("_", "-")
            raise GestureSimError(f"{flag} needs --corpus (it is about a corpus folder)")
    if args.output is None:
        raise GestureSimError("-o/--output is required (the model folder to write)")
    check_pairs("--pair", args.pair)
    if args.library is not None:
        v.input_folder("--library", args.library, "motion library folder")
    from pathlib import Path

    from gesture_sim.inference.model import MODEL_JSON, MODEL_NPZ

    v.check_outputs([v.Output("-o/--output", args.output, folder=True),
                     *(v.Output("-o/--output", Path(args.output) / name, within=args.output)
                       for name in (MODEL_NPZ, MODEL_JSON))],
                    inputs=[*(f for pair in args.pair for f in pair),
                            *v.inputs_of(args, "library")])

    from gesture_sim.inference.train import train_model
    from gesture_sim.progress import progress

    norm, lib_fp = library_normalisation(args.library)
    takes = load_pairs(args.pair, enabled=not args.json)
    check_pair_durations(takes, args.pair)
    cfg = _train_settings(args)
    bar = progress(total=6, desc="training", enabled=not args.json, unit="stage")

    def stage(text: str) -> None:
        bar.set_description(text)
        bar.update(1)

    model = train_model(takes, cfg, param_normalisation=norm, library_fingerprint=lib_fp,
                        on_stage=stage)
    bar.close()
    model.save(args.output)
    summary = dict(model.summary, output=str(args.output), fingerprint=model.fingerprint)
    if args.json:
        print_json(summary)
        return 0
    print(f"trained on {len(summary['pairs'])} pair(s): {summary['steps']} steps "
          f"({summary['seconds_of_data']:.1f} s), {summary['segments']} segments, "
          f"{summary['syllables']} syllables")
    print_model_figures(summary)
    print(f"training time {summary['training_seconds']:.1f} s; model written to {args.output}")
    return 0


def print_model_figures(summary: dict) -> None:
    """The held-out likelihood curve of the state choice and the CRF's fit, as text."""
    curve = summary["held_out_loglik_per_step"]
    if curve:
        print("held-out HMM log-likelihood per step by number of states:")
        for k, v in curve.items():
            mark = "  <- chosen" if int(k) == summary["states"] else ""
            print(f"  S={int(k):>3}  {_fmt(v)}{mark}")
    print(f"states {summary['states']}, clusters {summary['clusters']}, window "
          f"{summary['window']}; CRF objective per step {summary['crf_objective_per_step']:.4f} "
          f"after {summary['crf_iterations']} L-BFGS iterations")


def _fmt(v: float) -> str:
    return f"{v:9.3f}" if math.isfinite(v) else "   failed"


def corpus_outputs(output: str, cache: str | None) -> list:
    """The outputs of ``train --corpus -o DIR`` for :func:`gesture_sim.validation.check_outputs`:
    the folder, the library files, ``model/`` with its three files, the README, the cache."""
    from pathlib import Path

    from gesture_sim import validation as v
    from gesture_sim.corpus import README
    from gesture_sim.inference.model import MODEL_JSON, MODEL_NPZ
    from gesture_sim.loading import POLICY_FILE
    from gesture_sim.motion.library import ARRAYS, MANIFEST

    out = Path(output)
    return [v.Output("-o/--output", out, folder=True),
            *(v.Output("-o/--output", out / name, within=output)
              for name in (ARRAYS, MANIFEST, README)),
            v.Output("-o/--output", out / "model", folder=True, within=output),
            *(v.Output("-o/--output", out / "model" / name, within=output)
              for name in (MODEL_JSON, MODEL_NPZ, POLICY_FILE)),
            v.Output("--cache", cache, folder=True) if cache is not None else None]


def run_corpus(args: argparse.Namespace) -> int:
    """``train --corpus DIR``: see the module docstring and :mod:`gesture_sim.corpus`."""
    import sys
    from pathlib import Path

    from gesture_sim import validation as v
    from gesture_sim.app.batch import check_dask, check_jobs
    from gesture_sim.errors import GestureSimError

    if args.library is not None:
        raise GestureSimError("--library cannot be used with --corpus: the corpus's own library "
                              "is built and the model trained with its normalisation")
    corpus_dir = v.input_folder("--corpus", args.corpus, "corpus folder")
    check_jobs("--jobs", args.jobs)
    dask = check_dask("--dask", args.dask) if args.dask is not None else None
    if args.output is None and not args.list:
        raise GestureSimError("-o/--output is required (the folder to write), or give --list")
    from gesture_sim.corpus import discover, select_speaker

    cache = args.cache if args.cache is not None else (
        str(Path(args.output) / ".cache") if args.output is not None else None)
    corpus = discover(corpus_dir, exclude=[p for p in (args.output, cache) if p is not None])
    if args.speaker is not None:
        corpus = select_speaker(corpus, args.speaker)
    if args.list:
        return _list_corpus(corpus, args.json)
    if not corpus.items:
        from gesture_sim.corpus import no_pairs_message

        raise GestureSimError(no_pairs_message(corpus))
    v.check_outputs(corpus_outputs(args.output, args.cache), inputs=corpus.files())

    from gesture_sim.corpus import train_corpus
    from gesture_sim.progress import progress

    show = not args.json
    if corpus.unpaired:
        print(f"gesture-sim: note: {len(corpus.unpaired)} motion file(s) without speech are "
              f"left out (first: {corpus.unpaired[0]})", file=sys.stderr)
    n_stages = 1 + (6 if args.states is None else 5) + 1
    bar = progress(total=n_stages, desc="training", enabled=show, unit="stage")
    first = [True]

    def on_stage(text: str) -> None:
        if not first[0]:
            bar.update(1)
        first[0] = False
        bar.set_description(text)

    import contextlib

    from gesture_sim.fileio import new_folders_removed_on_error

    try:
        # a failed or interrupted run removes the (empty) folders it created: the output and
        # the cache, never one that existed before
        with contextlib.ExitStack() as created:
            created.enter_context(new_folders_removed_on_error(args.output))
            created.enter_context(new_folders_removed_on_error(cache))
            result = train_corpus(corpus, args.output, cache,
                                  train_settings=_train_settings(args), on_error=args.on_error,
                                  runner=_batch_runner(args.jobs, dask, show),
                                  show_progress=show, on_stage=on_stage)
    finally:
        bar.close()
    summary = result.summary
    for k in summary["skipped"]:
        print(f"gesture-sim: warning: skipped {k['reason']}", file=sys.stderr)
    if args.json:
        print_json(summary)
        return 0
    sp = ", ".join(f"{k} ({n})" for k, n in summary["speakers"].items())
    print(f"{summary['files']} pair(s) of {corpus.root} ({corpus.layout} layout; speakers {sp}): "
          f"{summary['seconds']:.1f} s, {summary['segments']} segments, "
          f"{summary['syllables']} syllables, {summary['words']} words")
    if summary["skipped"]:
        print(f"skipped {len(summary['skipped'])} broken file(s): "
              + ", ".join(k["file"] for k in summary["skipped"]))
    if summary["unpaired"]:
        print(f"left out {len(summary['unpaired'])} motion file(s) without speech")
    print_model_figures(summary)
    c = summary["cache"]
    print(f"cache {c['dir']}: {c['hits']} hit(s), {c['misses']} file(s) analysed; "
          f"{summary['seconds_total']:.1f} s in all")
    print(f"library {summary['library_fingerprint']}, model {summary['model_fingerprint']} "
          f"written to {args.output}; render with `gesture-sim render SPEECH --library "
          f"{args.output} -o out.mp4`")
    return 0


def _batch_runner(n_jobs: int, dask, show: bool):
    """The corpus's per-file jobs over :func:`gesture_sim.app.batch.run_jobs` (serially,
    ``--jobs N`` worker processes or ``--dask``)."""
    from gesture_sim.app.batch import Job, run_jobs

    def run(tasks, fail_fast: bool):
        outcomes = run_jobs([Job(t.label, t.fn, t.args) for t in tasks], n_jobs=n_jobs,
                            dask=dask, desc="analysing files", unit="file",
                            show_progress=show, fail_fast=fail_fast)
        return [(o.value, None if o.ok else o.line()) for o in outcomes]
    return run


def _list_corpus(corpus, as_json: bool) -> int:
    speakers = corpus.speakers()
    if as_json:
        print_json({"corpus": str(corpus.root), "layout": corpus.layout, "speakers": speakers,
                    "pairs": [{"name": it.name, "speaker": it.speaker, "motion": str(it.motion),
                               "audio": str(it.audio),
                               "textgrid": None if it.textgrid is None else str(it.textgrid)}
                              for it in corpus.items],
                    "unpaired": [str(p) for p in corpus.unpaired]})
        return 0
    print(f"{corpus.root}: {corpus.layout} layout, {len(corpus.items)} pair(s), "
          f"{len(corpus.unpaired)} motion file(s) without speech")
    for name, n in speakers.items():
        print(f"  {name}: {n['pairs']} pair(s)" + (f", {n['unpaired']} without speech"
                                                     if n["unpaired"] else ""))
    return 0


