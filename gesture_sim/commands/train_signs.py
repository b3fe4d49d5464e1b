"""``gesture-sim train --signs TAKES_DIR -o MODEL_DIR``: train ``chiu14``'s sign predictor on a
user's sign-annotated takes (Chiu 2014's way: audio + words + sign annotations per take).

The takes' layout is :mod:`gesture_sim.inference.sign_annotations`'s (:data:`LAYOUT` is the
``--help`` text). Every take's annotations and words are read first (a bad file stops the run
before any audio is analysed), then each take's audio goes through the prosody tracker (and a
plain transcript through the aligner) under a progress bar, and
:func:`gesture_sim.inference.sign_model.train_on_takes` fits the model. ``signs.npz`` +
``signs.json`` are written together into MODEL_DIR (``render --method chiu14`` reads such a
folder through :class:`~gesture_sim.pipeline.GesturePipeline`'s ``sign_model``).
"""

from __future__ import annotations

import argparse

from gesture_sim.commands import print_json

#: The ``--help`` text about TAKES_DIR (pre-formatted).
LAYOUT = """\
sign model (--signs TAKES_DIR): one take per stem, side by side in TAKES_DIR:

  TAKES_DIR/
    take1.wav          speech (.wav 16 kHz mono, or any audio file ffmpeg reads)
    take1.TextGrid     the words: a tier named "words"
    take1.signs.csv    the signs, one span per row: start,end,sign (s; header optional)
    take2.wav
    take2.txt          or the words as a plain transcript (force-aligned to the audio)
    take2.TextGrid     and the signs as a tier named "signs" (or an ELAN tab-delimited
                       export take2.signs.txt)

  take1.signs.csv:
    start,end,sign
    0.0,1.8,Rest
    1.8,3.5,Deictic.Other
    3.5,6.0,Beats

  The signs are Chiu 2014's 14 (case, spaces and underscores forgiven):
{signs}
  Frames (1 s) no annotation touches are left out of the training unless --unlabelled SIGN
  names their sign. Example:

    gesture-sim train --signs my_takes -o my_signs --unlabelled Rest --json

  --method chiu14 reads the folder written: gesture-sim render AUDIO -o OUT.mp4 --method
  chiu14 --sign-model my_signs (or GesturePipeline.create(method="chiu14",
  sign_model="my_signs")); without --sign-model it uses the shipped model.
"""


#: The 14 signs as ``--help`` lists them (:data:`gesture_sim.inference.sign_model.SIGNS`, which
#: is not imported to build the parser: it brings SciPy; a test keeps the two equal).
HELP_SIGNS: tuple[str, ...] = (
    "Rest", "Palm-face-up", "Head-nod", "Wipe", "Whole", "Frame", "Dismiss", "Block", "Shrug",
    "More-or-less", "Process", "Deictic.Other", "Deictic.Self", "Beats")


def layout_help() -> str:
    import textwrap

    return LAYOUT.format(signs=textwrap.fill(", ".join(HELP_SIGNS) + ".", 88,
                                             initial_indent="    ",
                                             subsequent_indent="    ", break_on_hyphens=False))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``--signs`` (an argument group of ``train``)."""
    g = parser.add_argument_group("sign model options (with --signs)")
    g.add_argument("--unlabelled", metavar="SIGN", default=None,
                   help="the sign of frames no annotation touches (default: they are left "
                   "out of the training)")
    g.add_argument("--hidden", type=int, nargs="+", default=None, metavar="N",
                   help="sizes of the sigmoid layers in front of the chain (Chiu's DCNF, e.g. "
                   "--hidden 16; default none: a linear-chain CRF, for little data)")
    g.add_argument("--order", type=int, default=1, choices=(1, 2),
                   help="chain order (default 1; 2: Chiu's second-order CRF)")
    g.add_argument("--min-count", type=int, default=SIGNS_ONLY["min_count"], metavar="N",
                   dest="min_count",
                   help="a word enters the vocabulary when the transcripts hold it at least "
                   "N times (default 2)")
    d = SIGNS_ONLY
    g.add_argument("--l2", type=float, default=d["l2"], metavar="W",
                   help=f"penalty per frame on the input weights (default {d['l2']:g}; lower "
                   "lets the words and prosody weigh more)")
    g.add_argument("--prior-weight", type=float, default=d["prior_weight"], metavar="W",
                   dest="prior_weight",
                   help="penalty per frame pulling the sign transitions towards Chiu's Table "
                   f"A.1 (default {d['prior_weight']:g}; lower trusts the annotations' own "
                   "transitions more)")


#: ``--signs`` options and their defaults (refused without --signs); l2, prior_weight and
#: min_count are :class:`~gesture_sim.inference.sign_model.SignModelSettings`'s (a test keeps
#: them equal).
SIGNS_ONLY = {"unlabelled": None, "hidden": None, "order": 1, "min_count": 2, "l2": 0.1,
              "prior_weight": 0.05}
#: ``train`` options that mean nothing with --signs, and their defaults.
NOT_WITH_SIGNS = {"states": None, "clusters": 8, "window": 4, "rate": 30.0, "library": None}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def check_signs_only(args: argparse.Namespace) -> None:
    """Without ``--signs``: none of its options."""
    from gesture_sim.errors import GestureSimError

    for name, default in SIGNS_ONLY.items():
        if getattr(args, name, default) != default:
            raise GestureSimError(f"{_flag(name)} needs --signs (it is about the sign model)")


def run_signs(args: argparse.Namespace, corpus_only: dict) -> int:
    """``train --signs TAKES_DIR``: see the module docstring."""
    import sys
    from pathlib import Path

    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError
    from gesture_sim.inference import sign_annotations as sa
    from gesture_sim.inference import sign_model as sm

    for names, why in ((NOT_WITH_SIGNS, "the motion model"), (corpus_only, "a corpus folder")):
        for name, default in names.items():
            if getattr(args, name) != default:
                raise GestureSimError(f"{_flag(name)} cannot be used with --signs (it is about "
                                      f"{why}, not the sign model)")
    unlabelled = None
    if args.unlabelled is not None:
        from gesture_sim.motion.signs import canonical_sign

        try:
            unlabelled = canonical_sign(args.unlabelled)
        except GestureSimError as exc:
            raise GestureSimError(f"--unlabelled: {exc}") from None
    for h in args.hidden or ():
        v.integer("--hidden", h, 1, 1024, hint=" units")
    v.integer("--min-count", args.min_count, 1, 10_000)
    v.number("--l2", args.l2, 0.0, 100.0)
    v.number("--prior-weight", args.prior_weight, 0.0, 100.0)
    if args.output is None:
        raise GestureSimError("-o/--output is required (the folder to write signs.npz and "
                              "signs.json into)")
    root = v.input_folder("--signs", args.signs, "folder of takes")
    takes = sa.discover_takes(root)
    inputs = [f for t in takes for f in t.files()]
    out = Path(args.output)
    v.check_outputs([v.Output("-o/--output", out, folder=True),
                     *(v.Output("-o/--output", out / name, within=args.output)
                       for name in (sm.SIGN_MODEL_NPZ, sm.SIGN_MODEL_JSON))], inputs=inputs)
    read = [sa.check_take(t) for t in takes]       # every annotation file before any audio

    from gesture_sim.fileio import atomic_folder
    from gesture_sim.progress import progress

    show = not args.json
    labelled = []
    for take, (spans, text) in progress(list(zip(takes, read, strict=True)),
                                        desc="analysing takes", enabled=show, unit="take"):
        labelled.append(sa.load_take(take, spans, text))
    cfg = sm.SignModelSettings(hidden=tuple(args.hidden or ()), order=args.order,
                               min_count=args.min_count, seed=args.seed, l2=args.l2,
                               prior_weight=args.prior_weight)
    if show:
        print(f"gesture-sim: training the sign model on {len(labelled)} take(s) ...",
              file=sys.stderr)
    try:
        model = sm.train_on_takes(labelled, cfg, unlabelled=unlabelled)
    except ValueError as exc:   # no labelled frame at all
        raise GestureSimError(f"--signs {root}: {exc} (every frame is unannotated; give "
                              "--unlabelled SIGN or annotate the takes)") from None
    per_take = []
    for take, lt in zip(takes, labelled, strict=True):
        n = max(int(-(-lt.duration_s // cfg.frame_s)), 1)
        y = sm.frame_labels(lt.spans, n, cfg.frame_s, unlabelled)
        counts = {sm.SIGNS[i]: int((y == i).sum()) for i in range(sm.N_SIGNS) if (y == i).any()}
        per_take.append({"name": take.name, "audio": str(take.audio), "words": str(take.words),
                         "words_from": take.words_kind, "signs": str(take.signs),
                         "signs_from": take.signs_kind, "duration_s": round(lt.duration_s, 3),
                         "frames": n, "labelled_frames": int((y >= 0).sum()),
                         "annotations": len(lt.spans), "n_words": len(lt.words),
                         "syllables": len(lt.syllables), "sign_frames": counts})
    model.info["labels_from"] = f"sign annotations in {root}"
    with atomic_folder(out) as stage:
        model.save(stage)
    info = model.info
    summary = {
        "takes": per_take,
        "frames": sum(t["frames"] for t in per_take),
        "labelled_frames": info["frames"],
        "sign_frames": dict(info["label_counts"]),
        "unlabelled": unlabelled,
        "training": {k: info[k] for k in ("sequences", "objective_per_frame", "iterations",
                                          "seconds", "vocabulary_size")},
        "settings": {"hidden": list(cfg.hidden), "order": cfg.order,
                     "min_count": cfg.min_count, "l2": cfg.l2,
                     "prior_weight": cfg.prior_weight, "seed": cfg.seed,
                     "frame_s": cfg.frame_s},
        "output": str(out),
        "written": [str(out / sm.SIGN_MODEL_NPZ), str(out / sm.SIGN_MODEL_JSON)],
    }
    if args.json:
        return print_json(summary)
    shares = ", ".join(f"{s} {n}" for s, n in summary["sign_frames"].items())
    print(f"trained on {len(per_take)} take(s): {summary['labelled_frames']} labelled frame(s) "
          f"of {summary['frames']} ({shares}); vocabulary {info['vocabulary_size']} words")
    t = summary["training"]
    print(f"objective per frame {t['objective_per_frame']:.4f} after {t['iterations']} L-BFGS "
          f"iterations, {t['seconds']:.1f} s")
    print(f"sign model written to {out}; use it with gesture-sim render AUDIO -o OUT.mp4 "
          f"--method chiu14 --sign-model {out}")
    return 0
