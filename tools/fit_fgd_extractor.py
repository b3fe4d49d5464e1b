"""Fit the FGD feature extractor of a motion library and store it in the library folder.

    .venv/bin/python tools/fit_fgd_extractor.py [motion_library/default]

Writes ``<library>/fgd_extractor.npz``: a PCA (32 components) of 34-frame, pelvis-relative
windows of the 12 evaluation points (``gesture_sim.app.evaluation.EVAL_POINTS``) of every clip
of the library, posed on the standing body, with the library's fingerprint (``gesture-sim eval
motion`` refits in memory when the fingerprint no longer matches). Deterministic; about a
second.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.errors import GestureSimError
    from gesture_sim.metrics.reference import EXTRACTOR_FILE, fit_extractor, save_extractor
    from gesture_sim.motion.library import MotionLibrary

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("library", nargs="?", type=Path, default=DEFAULT_LIBRARY_DIR,
                        help="library folder (default: the shipped one)")
    args = parser.parse_args(argv)
    try:
        lib = MotionLibrary.load(args.library)
        ext = fit_extractor(lib)
        out = Path(args.library) / EXTRACTOR_FILE
        save_extractor(ext, out, lib)
    except GestureSimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out}: {ext.components.shape[0]} components over windows of shape "
          f"{ext.window_shape}, library {lib.fingerprint}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
