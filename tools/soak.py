"""Soak test of the live path: ``gesture-sim live --audio FILE --loop`` under Xvfb for N minutes.

What it runs is what ``gesture-sim live --audio FILE --loop --mute`` runs — the real passive
MuJoCo viewer, the shipped pipeline (``record=False``, a bounded log), the file played through
the live path in real time as a fake microphone, looping — in a child process on a private
Xvfb display. While it runs, a sampler thread inside the child records every
``--every`` seconds:

* resident memory (``VmRSS``, MiB),
* NaN/inf checks of the simulated state (``qpos``, ``qvel``, actuator controls) and of the
  pipeline's belief, made after every ``advance`` of the loop (counted, first one reported),
* the loop's clock slips (``LiveStats.slipped_s``: seconds of live time given up because the
  physics fell more than ``max_lag_s`` behind), frames and audio pushed.

The result (JSON, ``--json PATH``) has the samples and the figures the issue asks for: the RSS
slope after the first minute (MiB per minute, least squares), the NaN count and the slips.

    python tools/soak.py --minutes 30 --audio assets/audio/jfk.wav --json soak.json

Not a test (it takes minutes); its figures go to BENCHMARKS.md, "## Soak".
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_AUDIO = ROOT / "assets" / "audio" / "jfk.wav"


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _load() -> float:
    return os.getloadavg()[0]


def child(audio: Path, minutes: float, every: float, out: Path) -> int:
    """Run the live loop in this process (under the DISPLAY given) and write the samples."""
    import numpy as np

    from gesture_sim.app.live import LiveLoop, LiveOptions
    from gesture_sim.app.viewer import check_display, mujoco_of
    from gesture_sim.audio.feeds import FileFeed
    from gesture_sim.pipeline import GesturePipeline

    check_display()
    feed = FileFeed(str(audio), loop=True, speakers=False)
    pipeline = GesturePipeline.create(seed=0, style=0.5, record=False)
    model, data = mujoco_of(pipeline)
    bad = {"count": 0, "first": None, "checks": 0}
    original = pipeline.advance

    def checked_advance(t: float):
        result = original(t)
        bad["checks"] += 1
        finite = (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()
                  and np.isfinite(data.ctrl).all())
        belief = getattr(pipeline.status(), "belief", None)
        if belief is not None:
            finite = finite and bool(np.isfinite(np.asarray(belief, dtype=float)).all())
        if not finite:
            bad["count"] += 1
            if bad["first"] is None:
                bad["first"] = float(data.time)
        return result

    pipeline.advance = checked_advance  # type: ignore[method-assign]
    opts = LiveOptions(duration=60.0 * minutes, print_keys=False, out=sys.stderr)
    loop = LiveLoop(pipeline, feed, opts)
    samples: list[dict] = []
    stop = threading.Event()
    t0 = time.monotonic()

    def sampler() -> None:
        while not stop.wait(every):
            st = loop.stats
            samples.append({
                "t_s": round(time.monotonic() - t0, 2), "rss_mb": round(_rss_mb(), 2),
                "frames": st.frames, "slipped_s": round(st.slipped_s, 4),
                "audio_pushed_s": round(st.audio_pushed_s, 2), "nan_states": bad["count"],
                "sim_s": round(st.sim_s, 2), "load1": round(_load(), 2)})

    th = threading.Thread(target=sampler, daemon=True)
    th.start()
    stats = loop.run()
    stop.set()
    th.join(timeout=5)
    out.write_text(json.dumps({"samples": samples, "nan": bad, "stats": stats.to_dict(),
                               "rss_at_start_mb": samples[0]["rss_mb"] if samples else None},
                              indent=1))
    return 0


def summarise(doc: dict, minutes: float) -> dict:
    """Figures of a soak run: RSS slope after the first minute, NaN count, slips."""
    import numpy as np

    s = doc["samples"]
    t = np.array([x["t_s"] for x in s])
    rss = np.array([x["rss_mb"] for x in s])
    after = t >= 60.0
    slope = float(np.polyfit(t[after], rss[after], 1)[0] * 60.0) if after.sum() >= 3 else None
    st = doc["stats"]
    slips = [b["slipped_s"] - a["slipped_s"] for a, b in zip(s[:-1], s[1:], strict=True)]
    return {
        "minutes": minutes, "wall_s": st.get("wall_s"), "frames": st.get("frames"),
        "fps": st.get("fps"), "rss_first_minute_end_mb": float(rss[after][0]) if after.any()
        else None, "rss_end_mb": float(rss[-1]) if len(rss) else None,
        "rss_slope_after_1min_mb_per_min": slope, "nan_states": doc["nan"]["count"],
        "nan_checks": doc["nan"]["checks"], "first_nan_sim_t": doc["nan"]["first"],
        "slipped_s_total": s[-1]["slipped_s"] if s else None,
        "slip_events": int(sum(1 for d in slips if d > 0)),
        "percent_real_time": st.get("percent_real_time"),
        "audio_pushed_s": s[-1]["audio_pushed_s"] if s else None,
        "load1_mean": float(np.mean([x["load1"] for x in s])) if s else None,
        "exit_reason": st.get("exit_reason"),
    }


def _start_xvfb() -> tuple[subprocess.Popen, str]:
    from gesture_sim.testing.processes import start_xvfb

    if shutil.which("Xvfb") is None:
        raise SystemExit("soak: Xvfb is not installed (apt-get install xvfb)")
    started = start_xvfb(range(150, 200))
    if started is None:
        raise SystemExit("soak: could not start Xvfb")
    return started


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--audio", type=Path, default=DEFAULT_AUDIO)
    ap.add_argument("--every", type=float, default=5.0, help="sampling period (s)")
    ap.add_argument("--json", type=Path, default=None, help="write samples and summary here")
    ap.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        return child(args.audio, args.minutes, args.every, args.child)
    xvfb, display = _start_xvfb()
    raw = Path(args.json or "soak.json").with_suffix(".raw.json")
    try:
        env = dict(os.environ, DISPLAY=display, MUJOCO_GL="egl")
        proc = subprocess.run([sys.executable, __file__, "--child", str(raw), "--minutes",
                               str(args.minutes), "--audio", str(args.audio), "--every",
                               str(args.every)], env=env, cwd=ROOT,
                              timeout=60 * args.minutes + 600, check=False)
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)
    if proc.returncode != 0:
        print(f"soak: the live child failed (exit {proc.returncode})", file=sys.stderr)
        return 1
    doc = json.loads(raw.read_text())
    summary = summarise(doc, args.minutes)
    doc["summary"] = summary
    if args.json:
        args.json.write_text(json.dumps(doc, indent=1))
    raw.unlink()
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
