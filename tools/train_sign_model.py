"""Train the sign predictor (Chiu 2014, docs/SIGNS.md §4) on a take whose motion is in a library.

    python tools/train_sign_model.py --audio 2_scott_0_1_1.wav \\
        --textgrid 2_scott_0_1_1.TextGrid --library motion_library/default \\
        -o motion_library/default/model

The labels are the signs of the library's co-speech segments of the clip named like the audio
(``--clip`` to name another): each segment's frames map to the take's timeline at the library's
frame rate, and each 1-s frame takes the sign covering most of it (frames past the clip's end
are left out). The signs are the library's stored annotations or its form labeller's
(:func:`gesture_sim.motion.signs.library_signs`). Writes ``signs.npz`` + ``signs.json`` into the
output folder, with every segment's sign under the library's fingerprint (the chooser reads them
instead of labelling the library again).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def take_from_library(audio: Path, textgrid: Path | None, library, clip: str | None = None,
                      signs: list[str] | None = None):
    """A :class:`~gesture_sim.inference.sign_model.LabelledTake` from an audio file, its
    TextGrid and the library clip of the same take."""
    from gesture_sim.audio.phones import words_from_textgrid
    from gesture_sim.audio.prosody import analyze_file
    from gesture_sim.inference.sign_model import LabelledTake
    from gesture_sim.motion.signs import library_signs

    name = clip or audio.stem
    clips = [c.name for c in library.clips]
    if name not in clips:
        raise SystemExit(f"{name!r} is not a clip of the library ({len(clips)} clips)")
    ci = clips.index(name)
    if signs is None:
        signs, _ = library_signs(library)
    fps = float(library.fps)
    spans = [(s.start / fps, s.end / fps, signs[s.index]) for s in library.segments
             if s.clip == ci and not library.clips[ci].tags]
    an = analyze_file(audio)
    duration = min(len(an.samples) / 16000.0, max(b for _, b, _ in spans))
    words = [(w.start_s, w.end_s, w.text) for w in words_from_textgrid(textgrid)] \
        if textgrid is not None else []
    syl = [s for s in an.syllables if s.t_end <= duration + 0.5]
    return LabelledTake(name, duration, syl, [w for w in words if w[0] < duration], spans)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--audio", type=Path, required=True)
    ap.add_argument("--textgrid", type=Path, default=None)
    ap.add_argument("--library", type=Path, required=True)
    ap.add_argument("--clip", default=None, help="the library clip of the take (default: the "
                                                 "audio's stem)")
    ap.add_argument("-o", "--output", type=Path, required=True, help="folder for signs.*")
    ap.add_argument("--hidden", type=int, nargs="*", default=[],
                    help="sigmoid layer sizes (none: a linear-chain CRF)")
    ap.add_argument("--order", type=int, default=1, choices=(1, 2))
    ap.add_argument("--min-count", type=int, default=2)
    args = ap.parse_args(argv)

    from gesture_sim.inference.sign_model import SignModelSettings, train_on_takes
    from gesture_sim.motion.library import MotionLibrary
    from gesture_sim.motion.signs import library_signs

    lib = MotionLibrary.load(args.library)
    signs, source = library_signs(lib)
    take = take_from_library(args.audio, args.textgrid, lib, args.clip, signs)
    cfg = SignModelSettings(hidden=tuple(args.hidden), order=args.order,
                            min_count=args.min_count)
    model = train_on_takes([take], cfg)
    model.info["labels_from"] = f"{args.library.name} segments of {take.name} ({source})"
    model.segment_signs = {"fingerprint": str(lib.fingerprint), "source": source,
                           "signs": list(signs)}
    npz, js = model.save(args.output)
    print(json.dumps({"written": [str(npz), str(js)], **model.info}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
