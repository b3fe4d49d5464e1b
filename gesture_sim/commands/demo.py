"""``gesture-sim demo``: the README's first command — the shipped example speech, rendered.

Runs the shipped public-domain recording (``assets/audio/jfk.wav``, see its SOURCE.md) through
the whole causal pipeline with the default library and model, and writes ``out/demo.mp4`` (the
speech muxed in), ``out/demo_timeline.png`` and ``out/demo_metrics.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gesture_sim import ASSETS_DIR

#: The example speech shipped with the package (assets/audio/SOURCE.md).
EXAMPLE_SPEECH = ASSETS_DIR / "audio" / "jfk.wav"
DEFAULT_OUTPUT = Path("out") / "demo.mp4"


def register(sub: argparse._SubParsersAction) -> None:
    from gesture_sim.commands.render import add_render_options

    parser = sub.add_parser(
        "demo", help="render the shipped example speech to out/demo.mp4 (+ timeline, metrics)",
        description=(
            "Render the shipped example speech (JFK, 11 s, public domain) with the default "
            "motion library and model: out/demo.mp4 with the speech muxed in, the timeline "
            "figure out/demo_timeline.png and the metrics out/demo_metrics.json."),
    )
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT,
                        help=f"output mp4 (default {DEFAULT_OUTPUT}); the timeline and metrics "
                             "go beside it")
    add_render_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v
    from gesture_sim.commands.render import check_render_options, print_summary
    from gesture_sim.errors import GestureSimError

    if not EXAMPLE_SPEECH.is_file():
        raise GestureSimError(f"example speech missing: {EXAMPLE_SPEECH} (reinstall gesture_sim)")
    check_render_options(args)
    out = args.output
    v.check_outputs([v.Output("-o/--output", out, v.VIDEO_EXTENSIONS)])
    v.check_outputs([v.Output("-o/--output", out, v.VIDEO_EXTENSIONS),
                     v.Output("timeline (beside -o)", out.with_name(out.stem + "_timeline.png")),
                     v.Output("metrics (beside -o)", out.with_name(out.stem + "_metrics.json"))],
                    inputs=[EXAMPLE_SPEECH, *v.inputs_of(args, "keywords", "signals", "transcript",
                                                         "text", "library", "model", "sign_model")])

    from gesture_sim.app.render import render_speech

    summary = render_speech(
        EXAMPLE_SPEECH, out, library=args.library, model=args.model, method=args.method,
        seed=args.seed, style=args.style, width=args.width, height=args.height, fps=args.fps,
        camera=args.camera, workers=args.workers, quality=args.quality,
        timeline=out.with_name(out.stem + "_timeline.png"),
        metrics=out.with_name(out.stem + "_metrics.json"), show_progress=not args.json,
        labels=tuple(args.label), phones=args.phones, text=args.text,
        sign_model=args.sign_model, transition=args.transition,
    )
    print_summary(summary, as_json=args.json)
    return 0
