"""``gesture-sim bench render``: headless render + encode speed of the humanoid video export.

Renders a fixed, kinematic pose sequence of the humanoid (arms, spine and head swinging on
sines; no physics, so the figure measures rendering and encoding only) at each frame size and
worker count, and reports frames per second and the real-time factor (seconds of video per
wall-clock second; docs/DESIGN.md §7 asks for >= 1 at 1280x720, 30 fps, on 2 CPU cores). It also
reports the CPU seconds spent per second of video (all processes together): on a machine shared
with other work that figure is steadier than the wall clock, and ``n_cores / cpu_s_per_video_s``
bounds the real-time factor that n otherwise idle cores could reach (``idle_realtime_bound``,
with n = the worker count).
"""

from __future__ import annotations

import argparse

from gesture_sim.commands import print_json
from gesture_sim.cpus import usable_cpus


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "render", help="render + encode speed of the video export (fps, real-time factor)",
        description=(
            "Render a fixed 10 s humanoid pose sequence to mp4 (H.264, no audio) at each size "
            "and worker count; report frames per second and the real-time factor."),
    )
    parser.add_argument("--seconds", type=float, default=10.0,
                        help="length of the pose sequence (s, default 10)")
    parser.add_argument("--fps", type=float, default=30.0, help="video frame rate (default 30)")
    parser.add_argument("--sizes", default="640x360,1280x720",
                        help="comma-separated WxH frame sizes (default 640x360,1280x720)")
    parser.add_argument("--workers", default="1,2",
                        help="comma-separated render worker counts (default 1,2)")
    parser.add_argument("--quality", default="standard,fast",
                        help="comma-separated render quality presets: fast, standard, high "
                             "(default standard,fast)")
    parser.add_argument("--camera", default="front", help="camera name or 'track' (default front)")
    parser.add_argument("--looks", default="human,mannequin",
                        help="comma-separated looks to draw: human, mannequin (default both: "
                             "the mannequin is the baseline of the skinned human)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.set_defaults(func=run)


def _parse_sizes(text: str) -> list[tuple[int, int]]:
    from gesture_sim.errors import GestureSimError

    sizes = []
    for item in text.split(","):
        try:
            w, h = (int(v) for v in item.lower().split("x"))
        except ValueError:
            raise GestureSimError(f"bad size {item!r}: use WIDTHxHEIGHT, e.g. 1280x720") from None
        sizes.append((w, h))
    return sizes


def _parse_workers(text: str) -> list[int]:
    from gesture_sim.errors import GestureSimError

    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise GestureSimError(f"bad worker list {text!r}: use e.g. 1,2") from None


def gesture_poses(model, seconds: float, fps: float):
    """A kinematic humanoid pose sequence, shape (round(seconds * fps), model.nq).

    Both arms swing forward and sideways, the elbows bend, the spine and head sway, each on its
    own sine (periods 1.3-3.1 s), from the upright pose of :func:`gesture_sim.sim.humanoid.
    root_qpos`. Deterministic, so every benchmark run renders the same frames.
    """
    import numpy as np

    from gesture_sim.sim.humanoid import qpos_addresses, root_qpos

    n = max(1, round(seconds * fps))
    t = np.arange(n) / fps
    qpos = np.zeros((n, model.nq))
    qpos[:, :7] = root_qpos()
    motions = {  # joint: (amplitude rad, period s, offset rad)
        "left_shoulder_flex": (0.6, 2.3, 0.5), "right_shoulder_flex": (0.5, 1.9, 0.4),
        "left_shoulder_abduct": (0.3, 3.1, 0.3), "right_shoulder_abduct": (0.25, 2.7, 0.3),
        "left_elbow_flex": (0.5, 1.3, 1.0), "right_elbow_flex": (0.4, 1.7, 0.9),
        "upper_spine_twist": (0.15, 2.9, 0.0), "head_bend": (0.12, 2.1, 0.0),
        "neck_flex": (0.1, 1.5, 0.0),
    }
    addr = qpos_addresses(model, list(motions))
    for a, (amp, period, offset) in zip(addr, motions.values(), strict=True):
        qpos[:, a] = offset + amp * np.sin(2 * np.pi * t / period)
    return qpos


def run(args: argparse.Namespace) -> int:
    import tempfile
    from pathlib import Path

    from gesture_sim.app.video import render_video
    from gesture_sim.sim.humanoid import load_model
    from gesture_sim.sim.looks import check_look

    looks = [check_look(x.strip()) for x in args.looks.split(",") if x.strip()]
    models = {look: load_model(look=look) for look in looks}
    qpos = gesture_poses(models[looks[0]], args.seconds, args.fps)
    results = []
    runs = [(look, q, size, workers) for look in looks for q in args.quality.split(",")
            for size in _parse_sizes(args.sizes) for workers in _parse_workers(args.workers)]
    from gesture_sim.fileio import temp_dir_prefix

    with tempfile.TemporaryDirectory(prefix=temp_dir_prefix("bench-render")) as tmp:
        for look, quality, (w, h), workers in runs:
            r = render_video(models[look], qpos, Path(tmp) / "bench.mp4", fps=args.fps, width=w,
                             height=h, camera=args.camera, workers=workers, quality=quality,
                             show_progress=not args.json)
            cpu_per_video_s = r.cpu_s / r.duration_s
            results.append({
                "look": look, "quality": quality, "width": w, "height": h, "workers": r.workers,
                "frames": r.n_frames, "video_s": round(r.duration_s, 3),
                "wall_s": round(r.wall_s, 3), "fps": round(r.frames_per_second, 2),
                "realtime_factor": round(r.realtime_factor, 3), "cpu_s": round(r.cpu_s, 3),
                "cpu_s_per_video_s": round(cpu_per_video_s, 3),
                # what this many otherwise idle CPUs could reach, if the work spread over them
                "idle_realtime_bound": round(min(r.workers, usable_cpus()) / cpu_per_video_s, 3),
            })
    summary = {"benchmark": "render", "camera": args.camera, "video_fps": args.fps,
               "seconds": args.seconds, "cpus": usable_cpus(), "results": results}
    if args.json:
        print_json(summary)
        return 0
    print(f"render + encode, {args.seconds:g} s at {args.fps:g} fps, camera {args.camera}, "
          f"{usable_cpus()} CPUs")
    print(f"{'look':>9} {'quality':>8} {'size':>10} {'workers':>7} {'frames':>6} {'wall s':>7} "
          f"{'fps':>7} {'x real time':>11} {'CPU s / video s':>15} {'idle bound':>10}")
    for r in results:
        print(f"{r['look']:>9} {r['quality']:>8} {r['width']:>5}x{r['height']:<4} "
              f"{r['workers']:>7} {r['frames']:>6} "
              f"{r['wall_s']:>7.2f} {r['fps']:>7.1f} {r['realtime_factor']:>11.2f} "
              f"{r['cpu_s_per_video_s']:>15.2f} {r['idle_realtime_bound']:>10.2f}")
    return 0
