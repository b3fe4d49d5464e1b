"""``gesture-sim words AUDIO``: the keywords the spotter hears in a recording (or that a
transcript names), with times, confidences and the gesture labels they ask for."""

from __future__ import annotations

import argparse
import math

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "words", help="show the keywords (and their gesture labels) spotted in a recording",
        description=(
            "Run the PocketSphinx keyword spotter over an audio file, block by block as the "
            "live pipeline does, and print each hit: phrase, start, end, confidence (log10 "
            "likelihood ratio against a free phone loop), emission time and label. With "
            "--transcript the same table is applied to a TextGrid word tier or a "
            "'start end word' list instead."),
    )
    parser.add_argument("audio", metavar="AUDIO", help="audio file (WAV of any width/rate; "
                        "other formats decoded with ffmpeg)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--keywords", metavar="FILE", help="keyword table (JSON or 'LABEL "
                        "PHRASE [/THRESHOLD/]' lines; default: the shipped table)")
    parser.add_argument("--transcript", metavar="FILE", help="take the words from this Praat "
                        "TextGrid (tier 'words') or 'start end word' list instead of the audio")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v

    v.input_file("AUDIO", args.audio, "audio file")
    if args.keywords:
        v.input_file("--keywords", args.keywords, "keyword table")
    if args.transcript:
        v.input_file("--transcript", args.transcript, "transcript")

    from gesture_sim.audio.keywords import (
        KeywordTable,
        SpotterStats,
        spot_file,
        transcript_keywords,
    )
    from gesture_sim.audio.sources import load_audio

    table = KeywordTable.load(args.keywords)
    samples, info = load_audio(args.audio)
    stats = SpotterStats()
    if args.transcript:
        hits = transcript_keywords(args.transcript, table)
        source = "transcript"
    else:
        hits = spot_file(samples, table, stats=stats)
        source = "pocketsphinx"
    if args.json:
        out = {"audio": str(args.audio), "duration_s": round(info.duration_s, 3),
               "source": source, "table": table.source,
               "keywords": [{"word": h.word, "label": h.label, "t_start": round(h.t_start, 3),
                             "t_end": round(h.t_end, 3),
                             "confidence": (round(h.confidence, 2)
                                            if math.isfinite(h.confidence) else None),
                             "t_emitted": round(h.t_emitted, 3),
                             "latency_s": round(h.t_emitted - h.t_end, 3)} for h in hits]}
        if source == "pocketsphinx":
            out["spotter"] = stats.to_dict()
        print_json(out)
        return 0
    if not hits:
        print(f"{args.audio}: no keywords ({info.duration_s:.2f} s, {len(table.entries)} "
              f"phrases listened for)")
        return 0
    print(f"{'phrase':<20} {'label':<11} {'start s':>8} {'end s':>8} {'conf':>7} "
          f"{'emitted s':>9} {'latency ms':>10}")
    for h in hits:
        conf = f"{h.confidence:.1f}" if math.isfinite(h.confidence) else "-"
        print(f"{h.word:<20} {h.label:<11} {h.t_start:>8.2f} {h.t_end:>8.2f} {conf:>7} "
              f"{h.t_emitted:>9.2f} {1000 * (h.t_emitted - h.t_end):>10.0f}")
    if source == "pocketsphinx":
        print(f"\nspotter: {stats.decoded_s:.1f} s decoded, {100 * stats.core_share:.1f} % "
              "of one core")
    return 0
