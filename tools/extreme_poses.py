"""The most extreme poses of a motion library on the skinned human: does the skin tear?

    python tools/extreme_poses.py OUT.png [--library DIR] [--poses 12] [--size 360] [--json J]

For every body joint of the humanoid the library moves (spine, neck, head, clavicles, shoulders,
elbows, forearms, wrists, hips, knees, ankles; not the face or the fingers), the frame of the
whole library that takes it nearest to each end of its range (the fraction of the way from the
standing pose, 0, to the joint's limit in the model, 1). The ``--poses`` frames with the largest
such fractions (one per joint end at most, distinct frames) are posed kinematically on the
human look (``sim.humanoid.load_model(look="human")``, the clip's own finger motion where the
library has it, the relaxed hand elsewhere) and rendered from the front and from the side (one
above the other; six poses a row), titled with the clip frame, the joint and its fraction of
the range. The JSON lists the same. The frames are what a viewer must look at: blend skinning
stretches at the limits, and a tear shows as a gap or a spike in the mesh.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

#: Joint-name prefixes that are not whole-body posture (the face rig and the fingers).
_SKIP = ("jaw_", "lower_lip", "upper_lip", "left_lip", "right_lip", "left_brow", "right_brow",
         "left_eyelid", "right_eyelid", "left_eye_", "right_eye_", "left_thumb", "right_thumb",
         "left_index", "right_index", "left_middle", "right_middle", "left_ring", "right_ring",
         "left_pinky", "right_pinky")


def extreme_frames(library, model, n: int) -> list[dict]:
    """The ``n`` library frames nearest a body joint's limit (dicts: clip, frame, joint, end,
    fraction of the range, value in degrees), largest fraction first, distinct frames."""
    from gesture_sim.sim import humanoid as hm

    names = list(library.joint_names)
    cands = []
    for j, name in enumerate(names):
        if name.startswith(_SKIP) or name not in hm.ACTUATED_JOINTS:
            continue
        lo, hi = model.jnt_range[model.joint(name).id]
        for ci, clip in enumerate(library.clips):
            q = np.asarray(clip.qpos[:, j], dtype=float)
            for end, limit in (("min", lo), ("max", hi)):
                if (end == "min" and limit >= 0) or (end == "max" and limit <= 0):
                    continue
                frac = q / limit
                f = int(np.argmax(frac))
                cands.append({"clip": ci, "clip_name": clip.name, "frame": f, "joint": name,
                              "end": end, "fraction": float(frac[f]),
                              "deg": float(np.degrees(q[f]))})
    best: dict[tuple[str, str], dict] = {}
    for c in cands:                           # the most extreme clip frame per joint end
        key = (c["joint"], c["end"])
        if key not in best or c["fraction"] > best[key]["fraction"]:
            best[key] = c
    out, seen = [], set()
    for c in sorted(best.values(), key=lambda c: -c["fraction"]):
        if (c["clip"], c["frame"]) in seen:
            continue
        seen.add((c["clip"], c["frame"]))
        out.append(c)
        if len(out) == n:
            break
    return out


def render_sheet(library, fingers: dict, poses: list[dict], out: Path, size: int,
                 per_row: int = 6) -> None:
    """Front and side views (one above the other) of each pose on the human look into ``out``,
    ``per_row`` poses a row."""
    import mujoco
    from PIL import Image, ImageDraw

    from gesture_sim.motion.finger_tracks import relaxed_finger_q
    from gesture_sim.sim import humanoid as hm

    model = hm.load_model(look="human")
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, size, size)
    fcols = hm.actuated_index(hm.FINGER_JOINTS)
    cols = []
    for p in poses:
        q = np.asarray(library.clips[p["clip"]].qpos[p["frame"]], dtype=float).copy()
        track = fingers.get(p["clip"])
        q[fcols] = (track[min(p["frame"], len(track) - 1)] if track is not None
                    else relaxed_finger_q())
        data.qpos[:] = hm.qpos_from_targets(model, q)
        mujoco.mj_forward(model, data)
        tiles = []
        for azimuth in (90.0, 0.0):                     # front (the body faces +x), side
            cam = mujoco.MjvCamera()
            cam.lookat[:] = data.xpos[model.body("pelvis").id] + np.array([0.0, 0.0, 0.25])
            cam.distance, cam.azimuth, cam.elevation = 1.9, azimuth + 90.0, -8.0
            renderer.update_scene(data, cam)
            tiles.append(renderer.render())
        img = Image.fromarray(np.concatenate(tiles, axis=0))
        ImageDraw.Draw(img).text(
            (4, 4), f"{p['clip_name']}:{p['frame']}\n{p['joint']} {p['end']}\n"
                    f"{p['deg']:.0f} deg = {p['fraction']:.2f} of range", fill=(0, 0, 0))
        cols.append(np.asarray(img))
    while len(cols) % per_row:                          # pad the last row
        cols.append(np.full_like(cols[0], 255))
    sheet = np.concatenate([np.concatenate(cols[k:k + per_row], axis=1)
                            for k in range(0, len(cols), per_row)], axis=0)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(sheet).quantize(colors=192, method=Image.Quantize.MEDIANCUT).save(
        out, optimize=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the PNG to write")
    ap.add_argument("--library", type=Path, default=None, help="default: the shipped library")
    ap.add_argument("--poses", type=int, default=12, help="how many poses (default 12)")
    ap.add_argument("--size", type=int, default=360, help="pixels per view (default 360)")
    ap.add_argument("--json", type=Path, default=None, help="also write the poses here")
    args = ap.parse_args(argv)

    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.motion.finger_tracks import load_finger_tracks
    from gesture_sim.motion.library import MotionLibrary
    from gesture_sim.sim import humanoid as hm

    folder = args.library or Path(DEFAULT_LIBRARY_DIR)
    library = MotionLibrary.load(folder)
    fingers = load_finger_tracks(folder, library)
    poses = extreme_frames(library, hm.load_model(look="mannequin"), args.poses)
    render_sheet(library, fingers, poses, args.out, args.size)
    doc = {"library": str(folder), "out": str(args.out), "poses": poses}
    text = json.dumps(doc, indent=1)
    print(text)
    if args.json:
        args.json.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
