"""``gesture-sim listener mine ANNOTATIONS -o RULES.json``: Okwechime 2011's Social Dynamics
Model from a user's own dyadic data — association rules speaker ⇒ listener mined with Apriori
over time-aligned signal annotations (:mod:`gesture_sim.signals.sdm`). Two rule files, one
mined on interested and one on not-interested listeners, drive a conversation's listeners
(``render --two --interest-rules INTERESTED.json BORED.json --interest X``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from gesture_sim.commands import print_json
from gesture_sim.errors import GestureSimError

#: The audio-driven listener's motions (``--listener-motion``;
#: :data:`gesture_sim.signals.listener_audio.MOTIONS`, kept here so the parsers stay light).
LISTENER_MOTIONS: tuple[str, ...] = ("graph", "envelope")


def check_listener_motion(listener: str, motion: str | None) -> None:
    """``--listener-motion`` is the audio-driven listener's (``--listener okwechime``)."""
    if motion is not None and listener != "okwechime":
        raise GestureSimError("--listener-motion: for the audio-driven listener "
                              "(--listener okwechime)")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "listener", help="train the listener: mine Okwechime 2011's speaker => listener rules",
        description=(
            "Mine association rules speaker => listener (Apriori with the temporal bag of "
            "Okwechime 2011, support and confidence as its Eqs. 5.1-5.2) from time-aligned "
            "annotations of the social signals of a conversation: a CSV "
            "(start,end,signal,person or time,signal,person) or an ELAN tab-delimited export "
            "(tier PERSON:SIGNAL, start, end). Signals: voiced, talking, laugh, smile, nod, "
            "shake, brow, activity, gaze_partner, gaze_other, gaze_none (see "
            "gesture_sim/signals/sdm.py)."))
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True,
                                    parser_class=type(parser))
    mine = actions.add_parser("mine", help="mine the rules of an annotated conversation",
                              description="Mine the rules and write them as JSON.")
    mine.add_argument("annotations", type=Path, metavar="ANNOTATIONS",
                      help="a CSV or an ELAN tab-delimited export of the signals")
    mine.add_argument("-o", "--output", type=Path, required=True, metavar="RULES.json",
                      help="the rules file to write")
    mine.add_argument("--fps", type=float, default=25.0,
                      help="annotation frame rate (Hz, default 25)")
    mine.add_argument("--bag", type=int, default=10,
                      help="the temporal bag s: listener frames after a speaker frame that "
                           "count as its response (default 10, the thesis's)")
    mine.add_argument("--min-support", type=float, default=0.005,
                      help="minimum support, a fraction (default 0.005: the thesis's 0.5 %%)")
    mine.add_argument("--min-confidence", type=float, default=0.0,
                      help="minimum confidence, a fraction (default 0)")
    mine.add_argument("--json", action="store_true", help="print a JSON summary")
    mine.set_defaults(func=run_mine)


def run_mine(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v
    from gesture_sim.fileio import atomic_path
    from gesture_sim.signals import sdm

    v.input_file("ANNOTATIONS", args.annotations, "annotation file")
    v.number("--fps", args.fps, 0.0, 1000.0, lo_open=True, hint=" Hz")
    v.number("--bag", args.bag, 1, 10_000)
    v.number("--min-support", args.min_support, 0.0, 1.0)
    v.number("--min-confidence", args.min_confidence, 0.0, 1.0)
    (out,) = v.check_outputs([v.Output("-o/--output", args.output, v.JSON_EXTENSIONS)],
                             inputs=[args.annotations])
    table = sdm.read_annotations(args.annotations, fps=args.fps)
    rules = sdm.mine(table, min_support=args.min_support, min_confidence=args.min_confidence,
                     bag=int(args.bag))
    with atomic_path(out, suffix=".json") as tmp:
        sdm.save_rules(tmp, rules, fps=args.fps, bag=int(args.bag),
                       source=str(args.annotations), min_support=args.min_support,
                       min_confidence=args.min_confidence)
    summary = {"output": str(out), "rules": len(rules), "persons": list(table.persons),
               "frames": table.n_frames, "top": [str(r) for r in sorted(
                   rules, key=lambda r: -r.confidence)[:10]]}
    if args.json:
        return print_json(summary)
    print(f"wrote {out}: {len(rules)} rules from {table.n_frames} frames of "
          f"{', '.join(table.persons)}")
    for line in summary["top"]:
        print(f"  {line}")
    return 0
