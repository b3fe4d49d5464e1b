"""``gesture-sim train --pair MOTION AUDIO [--pair ...] -o MODEL``: train the inference layer.

Fits the prosody clusters, the kinematic HMM (number of states by held-out likelihood unless
``--states``), the remapped CRF and the Levine 2009 baseline on motion + speech pairs, and
writes the model folder (``model.json`` + ``model.npz``).
"""

from __future__ import annotations

import argparse
import math

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "train", help="train the inference model (HMM + remapped CRF) on motion/speech pairs",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
        epilog="A new motion library does not need a new model: build it with the model's "
               "normalisation (`gesture-sim library build ... --normalisation-from MODEL`) and "
               "train only its control layer (`gesture-sim library policy LIBRARY --model "
               "MODEL`, or let the first render do it).",
    )
    add_pair_arguments(parser)
    parser.add_argument("-o", "--output", required=True, metavar="MODEL",
                        help="output model folder (created; model.json + model.npz)")
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
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.set_defaults(func=run)


def add_pair_arguments(parser: argparse.ArgumentParser, required: bool = True) -> None:
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


#: Motion and speech of one pair may differ by this share of the longer one (and by 1 s).
PAIR_MISMATCH_SHARE = 0.1


def check_pair_durations(takes: list, pairs: list[list[str]]) -> None:
    """Refuse a pair whose motion and speech durations differ by more than 10 % (and 1 s):
    they are not recordings of the same take."""
    from gesture_sim.errors import GestureSimError

    for take, (motion, audio) in zip(takes, pairs, strict=True):
        m_s = take.motion.n_frames / take.motion.fps
        a_s = getattr(take, "audio_duration_s", None)
        if a_s is None:
            continue
        if abs(m_s - a_s) > max(1.0, PAIR_MISMATCH_SHARE * max(m_s, a_s)):
            raise GestureSimError(
                f"--pair {motion} {audio}: the motion lasts {m_s:.1f} s but the speech "
                f"{a_s:.1f} s; a pair must be the motion and speech of the same take")


def library_normalisation(folder: str | None) -> tuple[dict | None, str | None]:
    """(param_normalisation, fingerprint) of a library folder, or (None, None)."""
    if folder is None:
        return None, None
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(folder)
    return lib.param_normalisation, lib.fingerprint


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from gesture_sim import validation as v

    if args.states is not None:
        v.integer("--states", args.states, 2, 64)
    v.integer("--clusters", args.clusters, 2, 64)
    v.integer("--window", args.window, 1, 16, hint=" steps")
    v.number("--rate", args.rate, 1.0, 120.0, hint=" steps per second")
    v.seed("--seed", args.seed)
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

    from gesture_sim.inference.features import StepSettings
    from gesture_sim.inference.train import TrainSettings, train_model
    from gesture_sim.progress import progress

    norm, lib_fp = library_normalisation(args.library)
    takes = load_pairs(args.pair, enabled=not args.json)
    check_pair_durations(takes, args.pair)
    cfg = TrainSettings(n_states=args.states, n_clusters=args.clusters, window=args.window,
                        seed=args.seed, steps=replace(StepSettings(), rate_hz=args.rate))
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
    curve = summary["held_out_loglik_per_step"]
    if curve:
        print("held-out HMM log-likelihood per step by number of states:")
        for k, v in curve.items():
            mark = "  <- chosen" if int(k) == summary["states"] else ""
            print(f"  S={int(k):>3}  {_fmt(v)}{mark}")
    print(f"states {summary['states']}, clusters {summary['clusters']}, window "
          f"{summary['window']}; CRF objective per step {summary['crf_objective_per_step']:.4f} "
          f"after {summary['crf_iterations']} L-BFGS iterations")
    print(f"training time {summary['training_seconds']:.1f} s; model written to {args.output}")
    return 0


def _fmt(v: float) -> str:
    return f"{v:9.3f}" if math.isfinite(v) else "   failed"


