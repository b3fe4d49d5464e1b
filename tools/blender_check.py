"""Check the FBX, GLB and Mixamo-BVH exports through Blender's own importers, and render a frame.

Needs Blender's Python module (``pip install 'gesture-sim[blender]'``). Steps:

1. the motion: a ``render --npz`` file (``--npz``), resampled to ``--fps`` as the exporters do,
   or, without one, a posed gesture of ``--seconds`` (both arms beating, the head nodding, the
   spine turning; the body standing);
2. writes ``human.fbx`` and ``human.glb`` (:func:`gesture_sim.export.blender.write_scene`, timed)
   and ``human_mixamo.bvh`` (:func:`gesture_sim.export.mixamo.bvh_text`) into ``--out``;
3. imports each into a fresh Blender scene and measures the bone heads against the simulated
   body, per joint (RMS and max over the frames, cm, Blender axes):

   * FBX / GLB: every bone head against its MuJoCo body's origin (should be ~0: the same
     skeleton, exact kinematics), and, in mid-gesture, every vertex of the meshes as Blender
     deforms them against the skins as MuJoCo draws them (``skin``);
   * Mixamo BVH: the arm, spine, neck and head bones against the humanoid points the Mixamo
     mapping places them on (``gesture_sim/export/mixamo.py``: ``mixamo_follow``), which
     includes the rig's other proportions (bone lengths, root scaled by the leg ratio), and,
     column ``rig``, against the joint positions the BVH itself encodes (the rig posed by the
     mapping's rotations: Blender's importer alone);

4. prints a table (or ``--json``) and renders one frame of the re-imported FBX, the skinned
   character in mid-gesture, to ``--png`` (EEVEE, else Cycles on the CPU, else Workbench).

Example::

    .venv/bin/python tools/blender_check.py --seconds 10 --png docs/figures/blender_fbx_frame.png
    .venv/bin/python tools/blender_check.py --npz out/motion.npz --json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gesture_sim.errors import GestureSimError  # noqa: E402

#: Mixamo bones compared with the humanoid (the arms, the spine, the neck and the head).
MIXAMO_CHECK = ("Spine", "Spine1", "Spine2", "Neck", "Head",
                *(f"{s}{j}" for s in ("Left", "Right")
                  for j in ("Shoulder", "Arm", "ForeArm", "Hand")))
#: BVH axes (X left, Y up, Z forward) -> Blender axes (Z up, facing -Y): (X, -Z, Y).
BVH_TO_BLENDER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: At most this many frames are measured (evenly spread, first and last included).
MAX_MEASURED = 120


def posed_motion(model: Any, seconds: float, fps: float) -> np.ndarray:
    """(T, nq) qpos of a standing gesture: the right arm beating up and forward with the elbow
    bent, the left arm half raised, the head nodding, the upper spine turning (rad)."""
    from gesture_sim.sim.humanoid import qpos_addresses

    n = max(2, int(round(seconds * fps)))
    t = np.arange(n) / fps
    env = np.clip(t / 0.8, 0.0, 1.0) * np.clip((t[-1] - t) / 0.8, 0.0, 1.0)  # ease in and out
    beat = 0.5 - 0.5 * np.cos(2 * np.pi * 0.7 * t)
    q = np.tile(model.qpos0, (n, 1))
    values = {
        "right_shoulder_flex": 1.2 * beat, "right_shoulder_abduct": 0.35 * beat,
        "right_elbow_flex": 0.5 + 0.6 * beat, "right_forearm_twist": 0.4 * beat,
        "left_shoulder_flex": 0.5 + 0.3 * np.sin(2 * np.pi * 0.35 * t),
        "left_elbow_flex": 0.9 + 0.3 * np.sin(2 * np.pi * 0.35 * t + 1.0),
        "left_shoulder_abduct": 0.15 + 0.0 * t,
        "neck_flex": 0.12 * np.sin(2 * np.pi * 0.7 * t), "head_flex": 0.1 * beat,
        "upper_spine_twist": 0.15 * np.sin(2 * np.pi * 0.25 * t),
        "jaw_open": 0.12 * beat,
    }
    adr = qpos_addresses(model, list(values))
    for a, v in zip(adr, values.values(), strict=True):
        q[:, a] = model.qpos0[a] + env * v
    return q


def npz_motion(model: Any, path: str, fps: float) -> np.ndarray:
    """(T, nq) qpos of a ``render --npz`` file resampled to ``fps`` over its recorded span."""
    from gesture_sim.app.motion_export import read_motion_npz
    from gesture_sim.app.video import frames_for_duration, resample_qpos

    trace = read_motion_npz(path)
    if trace.qpos.ndim != 2 or trace.qpos.shape[1] != model.nq:
        raise GestureSimError(f"{path}: qpos has shape {trace.qpos.shape}, the humanoid nq is "
                              f"{model.nq}")
    span = float(trace.time[-1] - trace.time[0]) if len(trace.time) > 1 else 0.0
    n = frames_for_duration(span, fps) if span > 0 else 1
    return resample_qpos(model, trace.time, trace.qpos, fps, n_frames=n)


def measured_frames(n: int) -> np.ndarray:
    """Indices of the frames measured: all, or :data:`MAX_MEASURED` spread evenly."""
    return np.unique(np.linspace(0, n - 1, min(n, MAX_MEASURED)).round().astype(int))


def errors_cm(got: np.ndarray, want: np.ndarray, names: list[str]) -> dict[str, Any]:
    """Per-joint RMS and max (cm) of position errors (F, n, 3) in m, and over all joints."""
    err = np.linalg.norm(got - want, axis=-1) * 100.0
    joints = {n: {"rms_cm": float(np.sqrt(np.mean(err[:, j] ** 2))),
                  "max_cm": float(err[:, j].max())} for j, n in enumerate(names)}
    return {"rms_cm": float(np.sqrt(np.mean(err ** 2))), "max_cm": float(err.max()),
            "joints": joints}


def mixamo_references(model: Any, qpos: np.ndarray, frames: np.ndarray
                      ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The Mixamo bones checked, the humanoid points they sit on (F, n, 3) and the joint
    positions the BVH encodes (F, n, 3), both in Blender axes (m)."""
    import mujoco

    from gesture_sim.export import PoseTransfer, forward_positions
    from gesture_sim.export.blender import MJ_TO_BLENDER
    from gesture_sim.export.mixamo import (
        PREFIX,
        mixamo_follow,
        mixamo_motion,
        mixamo_skeleton,
    )

    skeleton, _ = mixamo_skeleton()
    transfer = PoseTransfer(model, skeleton, mixamo_follow())
    names = [PREFIX + n for n in MIXAMO_CHECK]
    idx = [skeleton.index(n) for n in names]
    data = mujoco.MjData(model)
    hum = np.empty((len(frames), len(names), 3))
    for i, f in enumerate(frames):
        data.qpos[:] = qpos[f]
        mujoco.mj_kinematics(model, data)
        for k, j in enumerate(idx):
            b, off = transfer.anchor[j]
            hum[i, k] = data.xpos[b] + data.xmat[b].reshape(3, 3) @ off
    hum = hum @ MJ_TO_BLENDER.T
    _, glob, root = mixamo_motion(model, qpos[frames])
    rig = forward_positions(skeleton, glob, root)[:, idx] @ BVH_TO_BLENDER.T
    return names, hum, rig


def check(model: Any, qpos: np.ndarray, fps: float, out: Path) -> dict[str, Any]:
    """Write the three files into ``out``, read them back, and measure (see the module
    docstring)."""
    from gesture_sim.export.blender import (
        BVH_FIRST_FRAME,
        body_positions,
        bone_heads,
        read_back,
        rig_from_model,
        write_scene,
    )
    from gesture_sim.export.mixamo import bvh_text

    report: dict[str, Any] = {"frames": len(qpos), "fps": fps,
                              "seconds": len(qpos) / fps, "files": {}}
    frames = measured_frames(len(qpos))
    mid = mid_gesture_frame(model, qpos)
    report["frames_measured"], report["skin_frame"] = len(frames), mid
    rig = rig_from_model(model)
    names = list(rig.names)
    want = body_positions(model, qpos[frames], names)
    for fmt in ("fbx", "glb"):
        path = out / f"human.{fmt}"
        t0 = time.perf_counter()
        write_scene(path, model, qpos, fps, fmt)
        seconds = time.perf_counter() - t0
        arm = read_back(path, fmt, fps)
        got = bone_heads(arm, names, frames)
        rng = arm.animation_data.action.frame_range if arm.animation_data else (0, 0)
        report["files"][fmt] = {"path": str(path), "bytes": path.stat().st_size,
                                "export_s": seconds, "bones": len(arm.data.bones),
                                "frame_range": [float(rng[0]), float(rng[1])],
                                **errors_cm(got, want, names),
                                "skin": skin_errors_cm(model, qpos, mid)}
    path = out / "human_mixamo.bvh"
    t0 = time.perf_counter()
    path.write_text(bvh_text(model, qpos, fps), encoding="utf-8")
    seconds = time.perf_counter() - t0
    mix_names, hum, rig_pos = mixamo_references(model, qpos, frames)
    arm = read_back(path, "bvh", fps)
    got = bone_heads(arm, mix_names, frames + BVH_FIRST_FRAME)
    entry = errors_cm(got, hum, mix_names)
    vs_rig = errors_cm(got, rig_pos, mix_names)
    entry["rig_rms_cm"], entry["rig_max_cm"] = vs_rig["rms_cm"], vs_rig["max_cm"]
    for n in mix_names:
        entry["joints"][n]["rig_rms_cm"] = vs_rig["joints"][n]["rms_cm"]
    report["files"]["bvh"] = {"path": str(path), "bytes": path.stat().st_size,
                              "export_s": seconds, "bones": len(arm.data.bones), **entry}
    return report


def skin_errors_cm(model: Any, qpos: np.ndarray, frame: int) -> dict[str, Any]:
    """How far the re-imported meshes, deformed by Blender at ``frame``, are from the skins
    MuJoCo draws for that frame (``mujoco_skin_vertices``): RMS and max over the vertices (cm)
    of every skin and of all. The imported vertices are matched to the skins' by their rest
    positions (nearest neighbour: importers may reorder or split vertices)."""
    from scipy.spatial import cKDTree

    from gesture_sim.export.blender import MJ_TO_BLENDER, mujoco_skin_vertices, require_bpy

    bpy = require_bpy()
    scene = bpy.context.scene
    want = mujoco_skin_vertices(model, qpos[frame])
    out: dict[str, Any] = {"frame": frame, "skins": {}}
    all_err = []
    scene.frame_set(frame)
    dg = bpy.context.evaluated_depsgraph_get()
    for s in range(model.nskin):
        name = model.skin(s).name
        obj = bpy.data.objects.get(name)
        if obj is None or obj.type != "MESH":
            out["skins"][name] = None
            continue
        mw = np.array(obj.matrix_world)
        rest = np.empty(len(obj.data.vertices) * 3)
        obj.data.vertices.foreach_get("co", rest)
        ev = obj.evaluated_get(dg).to_mesh()
        posed = np.empty(len(ev.vertices) * 3)
        ev.vertices.foreach_get("co", posed)
        obj.evaluated_get(dg).to_mesh_clear()
        rest = rest.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
        posed = posed.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
        va, nv = int(model.skin_vertadr[s]), int(model.skin_vertnum[s])
        bind = model.skin_vert[va:va + nv].astype(float) @ MJ_TO_BLENDER.T
        dist, idx = cKDTree(bind).query(rest)
        err = np.linalg.norm(posed - want[s][idx], axis=1) * 100.0
        out["skins"][name] = {"vertices": len(rest), "rms_cm": float(np.sqrt(np.mean(err ** 2))),
                              "max_cm": float(err.max()), "match_max_cm": float(dist.max() * 100)}
        all_err.append(err)
    err = np.concatenate(all_err) if all_err else np.zeros(1)
    out["rms_cm"], out["max_cm"] = float(np.sqrt(np.mean(err ** 2))), float(err.max())
    return out


def mid_gesture_frame(model: Any, qpos: np.ndarray) -> int:
    """The frame where the hands are farthest from where they hang at rest."""
    from gesture_sim.export.blender import body_positions

    hands = body_positions(model, qpos, ["left_hand", "right_hand"])
    rest = body_positions(model, model.qpos0[None], ["left_hand", "right_hand"])
    return int(np.argmax(np.linalg.norm(hands - rest, axis=-1).sum(axis=1)))


def render_png(fbx: Path, fps: float, frame: int, png: Path, size: tuple[int, int],
               center: np.ndarray) -> str:
    """Render ``frame`` of the re-imported ``fbx`` to ``png`` (front view, one sun and a fill
    light, a floor); returns the render engine used."""
    from gesture_sim.export.blender import read_back, require_bpy

    bpy = require_bpy()
    arm = read_back(fbx, "fbx", fps)
    scene = bpy.context.scene
    scene.frame_set(frame)
    arm.hide_render = True
    world = bpy.data.worlds.new("world")
    world.color = (0.8, 0.82, 0.86)
    scene.world = world
    if getattr(world, "node_tree", None) is not None:
        bg = world.node_tree.nodes.get("Background")
        if bg is not None:
            bg.inputs["Color"].default_value = (0.62, 0.66, 0.72, 1.0)
            bg.inputs["Strength"].default_value = 0.9
    floor_mesh = bpy.data.meshes.new("floor")
    floor_mesh.from_pydata([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)], [],
                           [(0, 1, 2, 3)])
    floor = bpy.data.objects.new("floor", floor_mesh)
    mat = bpy.data.materials.new("floor")
    mat.diffuse_color = (0.5, 0.5, 0.5, 1.0)
    if getattr(mat, "node_tree", None) is not None:
        mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (
            0.45, 0.45, 0.45, 1.0)
    floor_mesh.materials.append(mat)
    scene.collection.objects.link(floor)
    cx, cy = float(center[0]), float(center[1])
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 50.0
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (cx + 0.7, cy - 3.9, 1.0)
    cam.rotation_euler = (np.radians(87.5), 0.0, np.radians(10.2))
    scene.collection.objects.link(cam)
    scene.camera = cam
    for name, energy, rot in (("key", 3.5, (50.0, 0.0, 30.0)), ("fill", 1.2, (70.0, 0.0, -60.0))):
        light = bpy.data.lights.new(name, "SUN")
        light.energy = energy
        obj = bpy.data.objects.new(name, light)
        obj.rotation_euler = tuple(np.radians(rot))
        scene.collection.objects.link(obj)
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(png)
    try:
        scene.view_settings.view_transform = "Standard"
    except TypeError:
        pass
    errors = []
    for engine in ("BLENDER_EEVEE", "CYCLES", "BLENDER_WORKBENCH"):
        try:
            scene.render.engine = engine
            if engine == "CYCLES":
                scene.cycles.device = "CPU"
                scene.cycles.samples = 24
                scene.cycles.use_denoising = False
            elif engine == "BLENDER_EEVEE":
                scene.eevee.taa_render_samples = 16
            bpy.ops.render.render(write_still=True)
            if png.is_file() and png.stat().st_size > 0:
                return engine
        except (RuntimeError, TypeError, AttributeError) as exc:
            errors.append(f"{engine}: {exc}")
    raise GestureSimError("Blender could not render: " + "; ".join(errors))


def shrink_png(png: Path, colors: int) -> None:
    """Rewrite ``png`` with a palette of ``colors`` (median cut, no dithering), when Pillow is
    installed (imageio brings it); left as rendered otherwise."""
    try:
        from PIL import Image
    except ImportError:
        return
    with Image.open(png) as im:
        small = im.convert("RGB").quantize(colors=min(max(colors, 2), 256),
                                           method=Image.Quantize.MEDIANCUT,
                                           dither=Image.Dither.NONE)
    small.save(png, optimize=True)


def print_table(report: dict[str, Any]) -> None:
    """The per-joint errors as a plain table."""
    print(f"motion: {report['frames']} frames at {report['fps']:g} Hz "
          f"({report['seconds']:.1f} s), {report['frames_measured']} measured")
    print(f"{'file':<5} {'bytes':>10} {'export s':>9} {'bones':>5} {'RMS cm':>8} {'max cm':>8}"
          f"   (bone heads; skin: vertices at frame {report['skin_frame']})")
    for fmt, r in report["files"].items():
        print(f"{fmt:<5} {r['bytes']:>10} {r['export_s']:>9.2f} {r['bones']:>5} "
              f"{r['rms_cm']:>8.3f} {r['max_cm']:>8.3f}"
              + (f"   skin RMS {r['skin']['rms_cm']:.3f}, max {r['skin']['max_cm']:.3f}"
                 if "skin" in r else "")
              + (f"   (vs the rig's own joints: RMS {r['rig_rms_cm']:.3f}, max "
                 f"{r['rig_max_cm']:.3f})" if "rig_rms_cm" in r else ""))
    for fmt, r in report["files"].items():
        print(f"\n{fmt}: per joint, cm (RMS / max"
              + (" / RMS vs the rig's joints)" if fmt == "bvh" else ")"))
        for name, j in r["joints"].items():
            extra = f" {j['rig_rms_cm']:8.3f}" if "rig_rms_cm" in j else ""
            print(f"  {name:<26} {j['rms_cm']:8.3f} {j['max_cm']:8.3f}{extra}")
    if "png" in report:
        print(f"\nrendered frame {report['png_frame']} with {report['png_engine']} "
              f"to {report['png']}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--npz", help="motion written by `gesture-sim render --npz` (default: "
                                      "a posed gesture of --seconds)")
    parser.add_argument("--seconds", type=float, default=3.0,
                        help="length of the posed gesture without --npz (s, default 3)")
    parser.add_argument("--fps", type=float, default=30.0, help="frame rate (Hz, default 30)")
    parser.add_argument("--out", help="folder for human.fbx, human.glb, human_mixamo.bvh "
                                      "(default: a temporary folder, removed)")
    parser.add_argument("--png", help="render the re-imported FBX in mid-gesture to this PNG")
    parser.add_argument("--size", default="640x480", help="PNG size WIDTHxHEIGHT (px)")
    parser.add_argument("--png-colors", type=int, default=128,
                        help="palette size of the PNG, to keep the file small (Pillow's "
                             "median cut; 0: full colour; default 128)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    args = parser.parse_args(argv)
    # Blender's C code prints to the stdout file descriptor: send it to stderr while working
    sys.stdout.flush()
    saved_stdout = os.dup(1)
    os.dup2(2, 1)
    try:
        code, report = _run(args)
    finally:
        sys.stdout.flush()
        os.dup2(saved_stdout, 1)
        os.close(saved_stdout)
    if code:
        return code
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print_table(report)
    return 0


def _run(args: argparse.Namespace) -> tuple[int, dict[str, Any]]:
    """Everything of :func:`main` but the printing: (exit status, report)."""
    try:
        from gesture_sim.export.blender import require_bpy
        from gesture_sim.sim.humanoid import load_model

        require_bpy()
        if not (args.fps > 0 and args.seconds > 0):
            raise GestureSimError("--fps and --seconds must be positive")
        try:
            size = tuple(int(x) for x in args.size.lower().split("x"))
            assert len(size) == 2 and min(size) > 0
        except (ValueError, AssertionError):
            raise GestureSimError(f"--size must be WIDTHxHEIGHT, got {args.size!r}") from None
        model = load_model(scene=False, look="human")
        qpos = (npz_motion(model, args.npz, args.fps) if args.npz
                else posed_motion(model, args.seconds, args.fps))
        with tempfile.TemporaryDirectory(prefix="blender_check_") as tmp:
            out = Path(args.out) if args.out else Path(tmp)
            out.mkdir(parents=True, exist_ok=True)
            report = check(model, qpos, args.fps, out)
            if args.png:
                from gesture_sim.export.blender import body_positions

                frame = mid_gesture_frame(model, qpos)
                center = body_positions(model, qpos[frame:frame + 1], ["pelvis"])[0, 0]
                png = Path(args.png).resolve()
                png.parent.mkdir(parents=True, exist_ok=True)
                t0 = time.perf_counter()
                report["png_engine"] = render_png(out / "human.fbx", args.fps, frame, png,
                                                  size, center)
                report["png_s"] = time.perf_counter() - t0
                if args.png_colors > 0:
                    shrink_png(png, args.png_colors)
                report["png"], report["png_frame"] = str(png), frame
            if not args.out:
                for r in report["files"].values():
                    r["path"] = os.path.basename(r["path"])
    except GestureSimError as exc:
        print(f"blender_check: error: {exc}", file=sys.stderr)
        return 2, {}
    return 0, report


if __name__ == "__main__":
    sys.exit(main())
