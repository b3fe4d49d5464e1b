"""``gesture-sim export MOTION.npz --format FMT -o OUT``: a render's saved motion onto another
skeleton or file format, without rendering again.

``MOTION.npz`` is the motion file ``render --npz`` writes (:mod:`gesture_sim.app.motion_export`:
the simulated humanoid's qpos (T, nq) at its recorded times (T,) s). The formats, each written
by the same writer as the matching ``render`` option, so the files are the same:

=============== ====== ==============================================================
``--format``    OUT    what (and the ``render`` option that writes the same)
=============== ====== ==============================================================
``smplx``       .npz   SMPL-X parameters in BEAT2's layout (``render --smplx``)
``bvh-mixamo``  .bvh   BVH on the Mixamo rig, ``mixamorig:*`` bones (``render --mixamo``)
``bvh``         .bvh   BVH of the project's own humanoid skeleton (``render --bvh``)
``skeleton``    .bvh   BVH on the user's skeleton ``--to-skeleton SKELETON.bvh``
                       (``render --to-skeleton SKELETON.bvh OUT.bvh``)
``fbx``/``glb`` .fbx   the skinned human and its motion through Blender's ``bpy``
                .glb   (the optional extra ``gesture-sim[blender]``)
=============== ====== ==============================================================

The motion is resampled to ``--fps`` (default 30 Hz, the render's) over its own time span
(the last recorded time less the first), so ``T = ceil(span · fps)`` frames (at least one).
A render's own exports cover the audio's length, which the motion file does not store; but a
render's trace runs from t = 0 to the audio's end (4.0 s of speech: 401 rows, 0 … 4.0 s), so
its span is that length and ``export`` of a render's npz writes the same file as the
corresponding ``render`` option (tested byte for byte).

Promises, as for ``render``'s outputs: the inputs are checked first (a missing or damaged
file, a file that is not a motion npz, a skeleton the exporter cannot take: one line, exit
status 2), the output before any work (not an input, not a folder, the right extension, a
folder that can be written; an existing file is replaced, as ``render`` replaces its outputs),
and the file is written to a temporary beside it and renamed at the end, so an interrupted or
failed export leaves the previous file as it was.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from gesture_sim.commands import print_json

#: ``--format`` -> the output's accepted extensions.
FORMATS: dict[str, tuple[str, ...]] = {
    "smplx": (".npz",), "bvh-mixamo": (".bvh",), "bvh": (".bvh",), "skeleton": (".bvh",),
    "fbx": (".fbx",), "glb": (".glb",),
}
#: The most frames one export writes (the span times ``--fps``): 1e6 is 9.3 h at 30 Hz, about
#: 1 GiB of resampled poses; a motion whose times span more (a time column in milliseconds, a
#: damaged file: two rows 1e6 s apart once asked for 25 GiB) is refused before any work.
MAX_EXPORT_FRAMES = 1_000_000
#: The hint when Blender's module is missing (the same words as
#: :data:`gesture_sim.export.blender.BLENDER_EXTRA_HINT`, for when that module is missing too).
BLENDER_HINT = ("FBX/glTF export needs Blender's Python module: "
                "pip install 'gesture-sim[blender]'")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "export", help="write a render's saved motion (render --npz) as SMPL-X, Mixamo BVH, "
                       "BVH, your skeleton's BVH, FBX or glTF",
        description=(
            "Read the motion file that `gesture-sim render --npz` wrote and write it in another "
            "format, without rendering again: smplx (SMPL-X in BEAT2's npz layout), "
            "bvh-mixamo (a BVH on the Mixamo rig, for Blender's retargeting; Unity and "
            "Unreal import no BVH: they take fbx or glb), bvh (the "
            "humanoid's own skeleton), skeleton (a BVH on your skeleton, --to-skeleton), fbx / "
            "glb (the skinned human, through Blender's bpy: pip install "
            "'gesture-sim[blender]'). The motion is resampled to --fps over its time span."),
    )
    parser.add_argument("motion", type=Path, metavar="MOTION.npz",
                        help="motion file written by `gesture-sim render --npz`")
    parser.add_argument("--format", required=True, choices=tuple(FORMATS), dest="fmt",
                        help="output format (see above)")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUT",
                        help="output file: .npz for smplx, .bvh for the BVH formats, .fbx, .glb; "
                             "an existing file is replaced")
    parser.add_argument("--to-skeleton", type=Path, default=None, metavar="SKELETON.bvh",
                        help="with --format skeleton: the BVH whose hierarchy receives the "
                             "motion (its rest pose is calibrated automatically)")
    parser.add_argument("--fps", type=float, default=30.0,
                        help="frame rate of the output (Hz, default 30)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    parser.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> Path:
    """Validate everything before any heavy import; return the path to write."""
    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError

    v.fps("--fps", args.fps)
    v.motion_file("MOTION", args.motion)
    if args.motion.suffix.lower() != ".npz":
        raise GestureSimError(f"MOTION {args.motion}: not a motion .npz (the file `gesture-sim "
                              "render --npz` writes); a BVH is an input of `library build`")
    if args.fmt == "skeleton":
        if args.to_skeleton is None:
            raise GestureSimError("--format skeleton needs --to-skeleton SKELETON.bvh (the "
                                  "skeleton that receives the motion)")
        v.input_file("--to-skeleton", args.to_skeleton, "BVH skeleton")
    elif args.to_skeleton is not None:
        raise GestureSimError(f"--to-skeleton: only with --format skeleton (not {args.fmt})")
    (out,) = v.check_outputs(
        [v.Output("-o/--output", args.output, FORMATS[args.fmt])],
        inputs=[args.motion, *([args.to_skeleton] if args.to_skeleton is not None else [])])
    return out


def _read(path: Path) -> tuple[Any, list[str] | None]:
    """The motion file's ``time`` (T,) s and ``qpos`` (T, nq) (:func:`read_motion_npz`), and
    the names of its qpos columns where it stores them."""
    import numpy as np

    from gesture_sim.app.motion_export import read_motion_npz

    trace = read_motion_npz(path)
    with np.load(path, allow_pickle=False) as z:
        names = [str(x) for x in z["qpos_names"]] if "qpos_names" in z.files else None
    return trace, names


def _check_motion(path: Path, trace: Any, names: list[str] | None, model: Any) -> None:
    """The motion fits ``model``: its qpos columns are the humanoid's (by name where the file
    names them, else by count), times increase, every value finite."""
    import numpy as np

    from gesture_sim.app.motion_export import qpos_names
    from gesture_sim.errors import GestureSimError

    t, q = trace.time, trace.qpos
    if t.ndim != 1 or len(t) == 0:
        raise GestureSimError(f"MOTION {path}: holds no frames (time has shape {t.shape})")
    ours = qpos_names(model)
    if names is not None and names != ours:
        k = next((i for i, (a, b) in enumerate(zip(names, ours, strict=False)) if a != b),
                 min(len(names), len(ours)))
        theirs = names[k] if k < len(names) else "(none)"
        mine = ours[k] if k < len(ours) else "(none)"
        raise GestureSimError(
            f"MOTION {path}: written for another version of the humanoid ({len(names)} qpos "
            f"columns, this one has {len(ours)}; column {k} is {theirs!r}, here {mine!r}); "
            "render it again")
    if q.shape != (len(t), model.nq):
        raise GestureSimError(
            f"MOTION {path}: qpos has shape {q.shape}, expected ({len(t)}, {model.nq}) for the "
            "humanoid (a motion file of another model or version?)")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise GestureSimError(f"MOTION {path}: holds non-finite times or poses")
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        raise GestureSimError(f"MOTION {path}: its times do not increase")


def check_span(path: Path, time_s: Any, fps: float,
               max_frames: int = MAX_EXPORT_FRAMES) -> None:
    """The motion's span (``time_s`` (T,) s, last less first) resampled at ``fps`` Hz must be
    at most ``max_frames`` frames (GestureSimError naming the file otherwise)."""
    import numpy as np

    from gesture_sim.errors import GestureSimError

    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t[[0, -1]])):
        return          # no frames or non-finite times: _check_motion names those
    span = float(t[-1] - t[0])
    frames = span * float(fps)
    if frames > max_frames:
        raise GestureSimError(
            f"MOTION {path}: its {len(t)} rows span {span:.6g} s ({span / 3600:.3g} h), "
            f"{frames:.3g} frames at --fps {fps:g}, over the {max_frames:,} an export writes "
            f"({max_frames / fps / 3600:.3g} h at that rate): a damaged time column, or times "
            "not in seconds? (render --npz stores seconds)")


def _scene_writer() -> Any:
    """:func:`gesture_sim.export.blender.write_scene`, with ``bpy`` loaded (both are optional,
    so imported here, before any work): a missing module is one line
    (:data:`BLENDER_HINT`, or the Blender module's own message)."""
    from gesture_sim.errors import GestureSimError

    try:
        from gesture_sim.export.blender import require_bpy, write_scene

        require_bpy()
    except ImportError as exc:
        raise GestureSimError(BLENDER_HINT) from exc
    return write_scene


def _write_scene(write_scene: Any, path: Path, model: Any, trace: Any, duration: float,
                 fps: float, fmt: str) -> int:
    """FBX/GLB of the motion resampled as the other writers resample it."""
    from gesture_sim.app.video import frames_for_duration, resample_qpos

    qpos = resample_qpos(model, trace.time, trace.qpos, fps,
                         n_frames=frames_for_duration(duration, fps))
    return int(write_scene(path, model, qpos, fps, fmt))


def export_motion(motion: Path, output: Path, fmt: str, fps: float = 30.0,
                  to_skeleton: Path | None = None, show_progress: bool = True) -> dict[str, Any]:
    """Export ``motion`` (a ``render --npz`` file) as ``fmt`` to ``output`` (already checked:
    :func:`_check_args`), atomically. Returns the summary: format, output, frames, fps,
    duration_s (the motion's span, s), motion_frames (rows in the file), seconds (wall)."""
    from gesture_sim.app import motion_export as me
    from gesture_sim.fileio import atomic_path
    from gesture_sim.progress import progress
    from gesture_sim.sim import humanoid as hm

    t0 = time.perf_counter()
    bar = progress(total=3, desc=f"export {fmt}", unit="step", enabled=show_progress)
    try:
        skeleton = scene_writer = None
        if fmt in ("fbx", "glb"):
            scene_writer = _scene_writer()          # no bpy: one line, before any work
        if fmt == "skeleton":
            from gesture_sim.export.skeleton import read_skeleton

            skeleton = read_skeleton(to_skeleton)   # one it cannot take: here, before work
        trace, names = _read(motion)                # a damaged or foreign file: here
        check_span(motion, trace.time, fps)         # terabytes of frames: before the model
        bar.update()
        # the render's model (scene and human look: the skins the FBX/glTF need)
        model = hm.load_model(scene=True, look="human")
        _check_motion(motion, trace, names, model)
        duration = float(trace.time[-1] - trace.time[0])
        bar.update()
        with atomic_path(output) as tmp:
            if fmt == "bvh":
                frames = me.write_bvh_from_trace(tmp, model, trace, duration, fps)
            elif fmt == "bvh-mixamo":
                frames = me.write_mixamo_from_trace(tmp, model, trace, duration, fps)
            elif fmt == "smplx":
                frames = me.write_smplx_from_trace(tmp, model, trace, duration, fps)
            elif fmt == "skeleton":
                frames = me.write_skeleton_from_trace(tmp, skeleton, model, trace, duration, fps)
            else:
                frames = _write_scene(scene_writer, tmp, model, trace, duration, fps, fmt)
        bar.update()
    finally:
        bar.close()
    return {"format": fmt, "output": str(output), "frames": int(frames), "fps": float(fps),
            "duration_s": round(duration, 6), "motion": str(motion),
            "motion_frames": len(trace.time),
            **({"to_skeleton": str(to_skeleton)} if to_skeleton is not None else {}),
            "seconds": round(time.perf_counter() - t0, 3)}


def run(args: argparse.Namespace) -> int:
    out = _check_args(args)
    summary = export_motion(args.motion, out, args.fmt, fps=args.fps,
                            to_skeleton=args.to_skeleton, show_progress=not args.json)
    summary["output"] = str(args.output)
    if args.json:
        return print_json(summary)
    print(f"wrote {args.output}: {args.fmt}, {summary['frames']} frames at {args.fps:g} fps "
          f"({summary['duration_s']:.2f} s) from {args.motion}")
    return 0
