#!/usr/bin/env python3
"""Write a library's finger tracks (``<library>/fingers.npz``, :mod:`gesture_sim.motion.
finger_tracks`) from the SMPL-X sources of its clips: each source's hand pose mapped onto the
humanoid's 40 finger joints (:func:`gesture_sim.motion.finger_tracks.smplx_finger_targets`), one row
per clip frame.

Usage (the shipped library's BEAT2 clip, from the BEAT2 take's SMPL-X file)::

    .venv/bin/python tools/build_finger_tracks.py --library motion_library/default \\
        --smplx 2_scott_0_1_1=PATH/2_scott_0_1_1.npz
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--library", type=Path, required=True, help="the library folder")
    ap.add_argument("--smplx", action="append", required=True, metavar="CLIP=NPZ",
                    help="a clip of the library and its SMPL-X source (repeatable)")
    args = ap.parse_args(argv)

    from gesture_sim.motion.finger_tracks import save_finger_tracks, smplx_finger_targets
    from gesture_sim.motion.library import MotionLibrary
    from gesture_sim.sim import humanoid as hm

    lib = MotionLibrary.load(args.library)
    model = hm.load_model(scene=False)
    names = [c.name for c in lib.clips]
    tracks = {}
    for item in args.smplx:
        clip, _, path = item.partition("=")
        if clip not in names:
            raise SystemExit(f"{clip!r} is not a clip of {args.library}")
        with np.load(path) as z:
            poses, fps = np.asarray(z["poses"], float), float(z["mocap_frame_rate"])
        n = lib.clips[names.index(clip)].n_frames
        if abs(fps - lib.fps) > 1e-6 or len(poses) < n:
            raise SystemExit(f"{path}: {len(poses)} frames at {fps:g} Hz; the clip has {n} at "
                             f"{lib.fps:g} Hz")
        q, _ = smplx_finger_targets(poses[:n], model)
        tracks[clip] = q
        print(f"{clip}: {n} frames, finger SD {np.degrees(q.std(0)).mean():.1f} deg per joint")
    print(f"wrote {save_finger_tracks(args.library, lib, tracks)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
