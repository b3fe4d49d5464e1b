"""``gesture-sim prosody AUDIO``: syllables, F0 and intensity of a recording, as the live
pipeline sees them (the same causal tracker, fed block by block)."""

from __future__ import annotations

import argparse
import math
from typing import Any

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "prosody", help="show the syllables, F0 and intensity the tracker finds in a recording",
        description=(
            "Run the causal prosody tracker (Praat pitch + intensity, online syllable "
            "segmenter) over an audio file and print its syllables and summary figures."
        ),
    )
    parser.add_argument("audio", metavar="AUDIO", help="audio file (WAV of any width/rate; "
                        "other formats decoded with ffmpeg)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")
    parser.add_argument("--plot", metavar="PNG", help="draw waveform, F0, intensity and "
                        "syllables to this PNG")
    parser.add_argument("--block-size", type=int, default=160, metavar="N",
                        help="samples per block fed to the tracker (default 160 = 10 ms; the "
                        "result does not depend on it)")
    parser.set_defaults(func=run)


def _fmt(v: Any, nd: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{nd}f}"


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v
    from gesture_sim.contracts import SAMPLE_RATE

    v.integer("--block-size", args.block_size, 1, SAMPLE_RATE,
              hint=f" samples at {SAMPLE_RATE // 1000} kHz")
    v.input_file("AUDIO", args.audio, "audio file")
    if args.plot:
        v.check_outputs([v.Output("--plot", args.plot, v.PNG_EXTENSIONS)], inputs=[args.audio])

    from gesture_sim.audio.prosody import analyze_file
    analysis = analyze_file(args.audio, block_size=args.block_size)
    s = analysis.summary
    if args.plot:
        from gesture_sim.audio.plot import plot_prosody

        plot_prosody(analysis, args.plot, title=str(args.audio))
    if args.json:
        out = analysis.to_dict()
        out["speech_found"] = bool(s["n_syllables"])
        print_json(out)
        return 0
    if not s["n_syllables"]:
        print(f"{args.audio}: no speech found ({s['duration_s']:.2f} s of audio, "
              f"{s['speech_s']:.2f} s above the silence threshold, no syllables)")
        return 0
    print(f"{'#':>4} {'start s':>8} {'end s':>8} {'len ms':>7} {'F0 Hz':>7} {'I dB':>6} "
          f"{'latency ms':>10}")
    for i, syl in enumerate(analysis.syllables):
        print(f"{i:>4} {syl.t_start:>8.2f} {syl.t_end:>8.2f} {1000 * syl.length:>7.0f} "
              f"{_fmt(syl.f0_hz):>7} {syl.intensity_db:>6.1f} "
              f"{1000 * (syl.t_emitted - syl.t_end):>10.0f}")
    print()
    rows = [
        ("duration", f"{s['duration_s']:.2f} s"),
        ("speech", f"{s['speech_s']:.2f} s"),
        ("syllables", f"{s['n_syllables']} ({s['n_voiced_syllables']} voiced)"),
        ("syllable rate", f"{s['syllable_rate']:.2f} /s of speech"),
        ("voiced share", f"{100 * s['voiced_share']:.0f} % of speech frames"),
        ("F0 range (p5-p95)", f"{_fmt(s['f0_p5_hz'], 0)}-{_fmt(s['f0_p95_hz'], 0)} Hz "
                              f"(median {_fmt(s['f0_p50_hz'], 0)})"),
        ("latency mean/median", f"{_fmt(1000 * s['latency_mean_s'], 0)} / "
                                f"{_fmt(1000 * s['latency_median_s'], 0)} ms "
                                f"(p95 {_fmt(1000 * s['latency_p95_s'], 0)} ms)"),
    ]
    for key, value in rows:
        print(f"{key:<22}{value}")
    if args.plot:
        print(f"{'plot':<22}{args.plot}")
    return 0
