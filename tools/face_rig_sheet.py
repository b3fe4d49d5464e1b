#!/usr/bin/env python3
"""A contact sheet of the face rig's shapes on the human look (``docs/figures/face_rig.png``):
visemes (open, closed over an open jaw, rounded, spread, tucked), a smile, the brow action units
(AU1 inner, AU2 outer, AU4 frown) and two gazes, each posed kinematically through
:mod:`gesture_sim.signals.face_rig` / the joints directly (no physics).

Usage::

    MUJOCO_GL=egl .venv/bin/python tools/face_rig_sheet.py OUT.png [--person 0|1] [--distance M]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def poses() -> dict[str, dict[str, float]]:
    """Label -> joint offsets (``S_`` = both sides); mouths through the face rig."""
    from gesture_sim.signals import face_rig as fr

    def mouth(ch, smile=0.0):
        return dict(zip(fr.MOUTH_JOINTS, fr.mouth_offsets(np.array(ch, float), smile),
                        strict=True))

    def brows(a1, a2, a4):
        return dict(zip(fr.BROW_JOINTS, fr.brow_offsets(a1, a2, a4), strict=True))

    def gaze(yaw, pitch):
        return dict(zip(fr.GAZE_JOINTS, fr.gaze_offsets(yaw, pitch), strict=True))

    return {
        "neutral": {}, "AA open": mouth([0.30, 0, 0, 0, 0, 0]),
        "M (closed over open jaw)": mouth([0.08, 1, 0, 0, 0, 0]),
        "UW round": mouth([0.08, 0, 1, 0, 0, 0]), "IY spread": mouth([0.06, 0, 0, 1, 0, 0]),
        "F tuck": mouth([0.08, 0, 0, 0, 1, 0]), "smile": mouth([0, 0, 0, 0, 0, 0], smile=1.0),
        "AU1 inner up": brows(1, 0, 0), "AU2 outer up": brows(0, 1, 0),
        "AU4 frown": brows(0, 0, 1), "gaze left": gaze(0.45, 0.0),
        "gaze down-right": gaze(-0.35, 0.3),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("output", type=Path)
    ap.add_argument("--person", type=int, default=0, help="body a (0) or b (1)")
    ap.add_argument("--distance", type=float, default=0.36, help="camera distance (m)")
    args = ap.parse_args(argv)

    import mujoco
    from PIL import Image, ImageDraw

    from gesture_sim.sim import humanoid as hm
    from gesture_sim.sim import looks

    spec = mujoco.MjSpec.from_file(str(hm.SCENE_XML))
    looks.apply_look(spec, "human", args.person)
    m = spec.compile()
    d = mujoco.MjData(m)
    r = mujoco.Renderer(m, 216, 240)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.distance, cam.azimuth, cam.elevation = args.distance, 180.0, -3.0
    tiles = []
    for label, offsets in poses().items():
        q = np.zeros(len(hm.ACTUATED_JOINTS))
        for name, v in offsets.items():
            q[hm.ACTUATED_JOINTS.index(name)] = v
        d.qpos[:] = hm.qpos_from_targets(m, q)
        mujoco.mj_kinematics(m, d)
        cam.lookat[:] = d.body("head").xpos + np.array([0.08, 0.0, 0.01])
        r.update_scene(d, cam)
        img = Image.fromarray(r.render())
        ImageDraw.Draw(img).text((8, 8), label, fill=(255, 255, 0))
        tiles.append(img)
    w, h = tiles[0].size
    sheet = Image.new("RGB", (w * 4, h * ((len(tiles) + 3) // 4)))
    for i, t in enumerate(tiles):
        sheet.paste(t, ((i % 4) * w, (i // 4) * h))
    sheet.save(args.output)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
