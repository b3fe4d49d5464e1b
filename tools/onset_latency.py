"""Voice onset (after silence) to the first visible stroke, with physics, several seeds.

    .venv/bin/python tools/onset_latency.py [--seeds 3] [--blend-frames N] [--sync KEY=VALUE ...]

Speech (espeak-ng), 2 s of silence, speech again; for each seed the time from the second voice
onset to (a) the timing layer's first stroke and (b) the first hand-speed peak of the simulated
body (the visible stroke), and the accent-to-stroke delay over the whole file.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))
import stimuli as st  # noqa: E402

from gesture_sim.feed import run_file  # noqa: E402
from gesture_sim.metrics import motion as mm  # noqa: E402
from gesture_sim.metrics.points import EVAL_FPS, POINT_NAMES, PointFK, trace_positions  # noqa: E402
from gesture_sim.pipeline import GesturePipeline  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--blend-frames", type=int, default=None,
                    help="the switch ramp's length in control steps (default: the pipeline's)")
    ap.add_argument("--sync", action="append", default=[], metavar="KEY=VALUE",
                    help="a SyncSettings field (a number), e.g. carry_s=0 (repeatable)")
    args = ap.parse_args()
    options: dict = {}
    sync = {k: float(v) for k, v in (item.split("=", 1) for item in args.sync)}
    if args.blend_frames is not None:
        options["blend_frames"] = args.blend_frames
        sync.setdefault("blend_s", args.blend_frames / 30.0)
    if sync:
        import dataclasses

        from gesture_sim.control.synchrony import SyncSettings
        options["sync"] = dataclasses.replace(SyncSettings(), **sync)
    a = st.say("I would like to tell you about the small town where I grew up", speed=160)
    b = st.say("it was a wonderful place full of music and stories", speed=160)
    x, starts = st.concat([a, st.silence(2.0), b])
    onset = starts[2]
    fk = PointFK()
    hands = [POINT_NAMES.index("left_hand"), POINT_NAMES.index("right_hand")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = st.write(Path(tmp) / "onset.wav", st.gain(x / np.abs(x).max(), -10.0))
        for seed in range(args.seeds):
            pipe = GesturePipeline.create(seed=seed, **options)
            run_file(pipe, path)
            pos = trace_positions(pipe.trace(), fk)
            speed = mm.joint_speeds(pos, EVAL_FPS)[:, hands].mean(axis=1)
            peaks = mm.speed_peaks(speed, EVAL_FPS)
            first_peak = peaks[peaks >= onset][0] - onset
            first_stroke = [t for t in pipe.log.strokes if t >= onset][0] - onset
            served = np.array([s - t for t, s in pipe.log.served])
            rows.append((first_stroke, first_peak, np.median(served)))
            print(f"seed {seed}: onset → timing-layer stroke {first_stroke * 1000:.0f} ms, "
                  f"→ first hand-speed peak of the body {first_peak * 1000:.0f} ms; "
                  f"accent → stroke median {np.median(served) * 1000:.0f} ms")
    r = np.array(rows)
    print(f"mean over seeds: {r[:, 0].mean() * 1000:.0f} ms / {r[:, 1].mean() * 1000:.0f} ms; "
          f"accent → stroke {r[:, 2].mean() * 1000:.0f} ms")


if __name__ == "__main__":
    main()
