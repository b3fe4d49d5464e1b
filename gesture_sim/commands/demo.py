"""``gesture-sim demo``: render the shipped example speech with the humanoid gesturing.

Interim version: the humanoid's joint targets come from a procedural gesture stream
(:mod:`gesture_sim.sim.procedural`) rather than from the speech-driven pipeline; the physics
(:mod:`gesture_sim.sim.tracking`) tracks them for the speech's duration, qpos is recorded at the
video rate, and :func:`gesture_sim.app.video.render_video` renders it with the speech muxed in.
Only :func:`simulate_poses` knows where the poses come from; the render step does not.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

#: The example speech shipped with the package (assets/audio/SOURCE.md).
EXAMPLE_SPEECH = Path(__file__).resolve().parents[2] / "assets" / "audio" / "jfk.wav"
DEFAULT_OUTPUT = Path("out") / "demo.mp4"


def use_egl_when_headless() -> None:
    """Choose MuJoCo's EGL back-end when ``MUJOCO_GL`` is unset and there is no display.

    Call it before :mod:`mujoco` is first imported (the back-end is fixed at import time).
    """
    if (
        sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ
        and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY")
    ):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo", help="render the shipped example speech to out/demo.mp4",
        description=(
            "Simulate the humanoid gesturing for the duration of the shipped example speech "
            "(JFK, 11 s) and render it to an mp4 with the speech muxed in."),
    )
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT,
                        help=f"output mp4 (default {DEFAULT_OUTPUT})")
    parser.add_argument("--width", type=int, default=1280, help="frame width (px, default 1280)")
    parser.add_argument("--height", type=int, default=720, help="frame height (px, default 720)")
    parser.add_argument("--fps", type=float, default=30.0, help="video frame rate (default 30)")
    parser.add_argument("--camera", default="front",
                        help="camera: front, side, face, or track (follows the pelvis)")
    parser.add_argument("--workers", type=int, default=None,
                        help="parallel render processes (default: the number of CPUs)")
    parser.add_argument("--quality", default="standard", choices=("fast", "standard", "high"),
                        help="render quality preset (default standard)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the gesture stream")
    parser.add_argument("--json", action="store_true",
                        help="print a JSON summary (path, duration, frames, speed)")
    parser.set_defaults(func=run)


def simulate_poses(model, n_frames: int, fps: float, seed: int = 0,
                   show_progress: bool = False):
    """The humanoid tracking a procedural gesture stream: qpos at ``fps``, (n_frames, model.nq).

    The physics (:class:`gesture_sim.sim.tracking.HumanoidSim`, PD + balance, no external help)
    tracks :func:`gesture_sim.sim.procedural.gesture_stream` for ``n_frames / fps`` seconds; the
    trace (recorded at 100 Hz) is resampled to the video frames. This is the demo's interim
    source of motion; the coordinator replaces it by the speech-driven pipeline.
    """
    from gesture_sim.app.video import resample_qpos
    from gesture_sim.sim.procedural import gesture_stream
    from gesture_sim.sim.tracking import HumanoidSim

    duration = n_frames / fps
    stream, _ = gesture_stream(duration=duration, seed=seed, rate=fps)
    sim = HumanoidSim(model, seed=seed)
    sim.reset()
    trace = sim.run(stream, duration=duration, show_progress=show_progress)
    return resample_qpos(model, trace.time, trace.qpos, fps, n_frames)


def _check_output_folder(path: Path) -> None:
    """Create the output's folder if needed; raise GestureSimError when it cannot be written."""
    from gesture_sim.errors import GestureSimError

    folder = path.parent if str(path.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GestureSimError(f"cannot create output folder {folder}: {exc.strerror}") from exc
    if not os.access(folder, os.W_OK):
        raise GestureSimError(f"cannot write to {folder}: permission denied")


def run(args: argparse.Namespace) -> int:
    use_egl_when_headless()
    from scipy.io import wavfile

    from gesture_sim.app.video import frames_for_duration, render_video
    from gesture_sim.errors import GestureSimError
    from gesture_sim.sim.humanoid import load_model

    if not EXAMPLE_SPEECH.is_file():
        raise GestureSimError(f"example speech missing: {EXAMPLE_SPEECH} (reinstall gesture_sim)")
    rate, samples = wavfile.read(EXAMPLE_SPEECH)
    duration = len(samples) / float(rate)
    n_frames = frames_for_duration(duration, args.fps)

    _check_output_folder(args.output)  # fail before the simulation, not after it
    model = load_model()
    t0 = time.perf_counter()
    qpos = simulate_poses(model, n_frames, args.fps, seed=args.seed,
                          show_progress=not args.json)
    sim_s = time.perf_counter() - t0
    result = render_video(
        model, qpos, args.output, fps=args.fps, audio=EXAMPLE_SPEECH, width=args.width,
        height=args.height, camera=args.camera, workers=args.workers, quality=args.quality,
        show_progress=not args.json,
    )
    total_s = time.perf_counter() - t0
    summary = {
        "path": str(result.path),
        "duration_s": round(result.duration_s, 3),
        "audio_duration_s": round(duration, 3),
        "frames": result.n_frames,
        "fps": result.fps,
        "size": [result.width, result.height],
        "camera": args.camera,
        "workers": result.workers,
        "simulate_s": round(sim_s, 3),
        "render_s": round(result.wall_s, 3),
        "render_realtime_factor": round(result.realtime_factor, 3),
        "total_realtime_factor": round(result.duration_s / total_s, 3),
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"wrote {result.path}: {result.n_frames} frames, {result.duration_s:.2f} s, "
              f"{result.width}x{result.height} @ {result.fps:g} fps, speech muxed in; "
              f"simulated in {sim_s:.1f} s, rendered at {result.realtime_factor:.2f}x real time "
              f"({result.workers} workers)")
    return 0
