#!/usr/bin/env python3
"""Build the shipped default motion library ``motion_library/default``.

Sources (given as arguments, never read from a fixed path):
  * the BEAT2 take ``2_scott_0_1_1.npz`` (SMPL-X, co-speech gestures, 63.5 s), and
  * Bandai Namco Research Motion Dataset folders: only their communicative gesture clips
    (bow, bye, byebye, call, guide, respond, wave-*, raise-up-*), no locomotion or dance.

Example::

    .venv/bin/python tools/build_default_library.py \
        --beat2 /path/beat2_scott/2_scott_0_1_1.npz \
        --bandai /path/bandai_namco_motion/dataset-1 /path/bandai_namco_motion/dataset-2 \
        -o motion_library/default
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

#: Bandai Namco contents that are gestures (the rest is locomotion, fighting or dance).
GESTURE_CONTENTS = ("bow", "bye", "byebye", "call", "guide", "respond", "wave-both-hands",
                    "wave-left-hand", "wave-right-hand", "raise-up-both-hands",
                    "raise-up-left-hand", "raise-up-right-hand")
_BANDAI = re.compile(r"^dataset-[12]_(?P<content>[a-z-]+)_(?P<style>[a-z-]+)_\d{3}$")


def gesture_clips(folders: list[Path]) -> list[Path]:
    """The gesture BVH files of Bandai Namco dataset folders, sorted by name."""
    out = []
    for folder in folders:
        for path in sorted(folder.glob("*.bvh")):
            m = _BANDAI.match(path.stem)
            if m and m["content"] in GESTURE_CONTENTS:
                out.append(path)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--beat2", type=Path, required=True, help="BEAT2 SMPL-X .npz take")
    parser.add_argument("--bandai", type=Path, nargs="+", required=True,
                        help="Bandai Namco dataset folders with .bvh files")
    parser.add_argument("-o", "--output", type=Path, default=Path("motion_library/default"))
    args = parser.parse_args(argv)

    from gesture_sim.errors import GestureSimError
    from gesture_sim.motion.build import build_library

    inputs = [args.beat2, *gesture_clips(args.bandai)]
    t0 = time.perf_counter()
    try:
        lib, reports = build_library(inputs, on_clip=lambda r: print(
            f"  {r.name}: {r.segments} segments, retarget error {100 * r.retarget_error:.1f}%",
            file=sys.stderr))
    except GestureSimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    lib.save(args.output)
    summary = {"clips": len(lib.clips), "segments": len(lib.segments),
               "seconds": round(lib.duration, 1), "fingerprint": lib.fingerprint,
               "build_seconds": round(time.perf_counter() - t0, 1),
               "max_retarget_error": round(max(r.retarget_error for r in reports), 4)}
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
