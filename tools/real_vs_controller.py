#!/usr/bin/env python3
"""The real take and the controller on the same audio, side by side: one mp4 with the speech,
and a contact sheet of frames to look at.

    .venv/bin/python tools/real_vs_controller.py TAKE.wav TAKE.npz -o OUT.mp4 \\
        [--start 20] [--seconds 12] [--sheet OUT.png] [--every 1.5] [--seed 0] \\
        [--width 640] [--height 480]

Left: the take's own motion capture (retargeted, legs at the standing pose, tracked by the
same physics: the eval's ``real`` method). Right: the shipped controller with its defaults on
the take's audio. Both are drawn with the human look from the front camera; the clip shown is
``--start`` .. ``--start + --seconds`` of the take.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _qpos_real(audio: Path, motion: Path, seed: int, duration: float, fps: float):
    from gesture_sim.app.evaluation import EVAL_FPS, Evaluator
    from gesture_sim.app.video import frames_for_duration, resample_qpos
    from gesture_sim.sim.targets import TargetStream
    from gesture_sim.sim.tracking import HumanoidSim

    q = Evaluator(physics=True).retarget_reference(motion)
    sim = HumanoidSim(seed=seed)
    sim.reset()
    dur = min(duration, (len(q) - 1) / EVAL_FPS)
    trace = sim.run(TargetStream(q, rate=EVAL_FPS), duration=dur)
    return resample_qpos(sim.model, trace.time, trace.qpos, fps,
                         n_frames=frames_for_duration(dur, fps))


def _qpos_controller(audio: Path, seed: int, fps: float):
    from gesture_sim.app.video import frames_for_duration, resample_qpos
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method="controller", seed=seed)
    run = run_file(pipe, audio)
    trace = pipe.trace()
    return resample_qpos(pipe.sim.model, trace.time, trace.qpos, fps,
                         n_frames=frames_for_duration(run.duration, fps)), run.duration


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("audio", type=Path)
    ap.add_argument("motion", type=Path, help="the take's motion capture (BEAT2 .npz, BVH)")
    ap.add_argument("-o", "--output", type=Path, required=True, help="the side-by-side mp4")
    ap.add_argument("--start", type=float, default=20.0, help="clip start (s, default 20)")
    ap.add_argument("--seconds", type=float, default=12.0, help="clip length (s, default 12)")
    ap.add_argument("--sheet", type=Path, default=None, help="also a PNG contact sheet")
    ap.add_argument("--every", type=float, default=1.5, help="sheet frame spacing (s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    args = ap.parse_args(argv)
    import imageio_ffmpeg

    from gesture_sim.app.video import render_video
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.sim.humanoid import load_model

    fps = 30.0
    q_ctl, duration = _qpos_controller(args.audio, args.seed, fps)
    q_real = _qpos_real(args.audio, args.motion, args.seed, duration, fps)
    a = int(round(args.start * fps))
    b = min(a + int(round(args.seconds * fps)), len(q_ctl), len(q_real))
    if b - a < 2:
        ap.error(f"--start {args.start} is past the end of the take ({duration:.1f} s)")
    samples, _ = load_audio(args.audio)
    clip = np.asarray(samples[int(a / fps * SAMPLE_RATE):int(b / fps * SAMPLE_RATE)],
                      dtype=np.float32)
    model = load_model(look="human")
    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    with tempfile.TemporaryDirectory() as tmp:
        left, right = Path(tmp) / "real.mp4", Path(tmp) / "controller.mp4"
        for q, out in ((q_real, left), (q_ctl, right)):
            render_video(model, q[a:b], out, fps=fps, audio=clip, width=args.width,
                         height=args.height, camera="front", workers=1, quality="fast",
                         show_progress=False)
        args.output.parent.mkdir(parents=True, exist_ok=True)
        tmp_out = Path(tmp) / "both.mp4"
        subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(left), "-i", str(right),
                        "-filter_complex", "[0:v][1:v]hstack=inputs=2[v]", "-map", "[v]",
                        "-map", "0:a", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-c:a",
                        "aac", str(tmp_out)], check=True)
        tmp_out.replace(args.output)
        if args.sheet is not None:
            n = max(1, int((b - a) / fps / args.every))
            subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(args.output), "-vf",
                            f"fps=1/{args.every},scale={args.width}:-2,tile=2x{(n + 1) // 2}",
                            "-frames:v", "1", str(args.sheet)], check=True)
    print(f"wrote {args.output} ({(b - a) / fps:.1f} s from {args.start:g} s: real left, "
          f"controller right)" + (f" and {args.sheet}" if args.sheet else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
