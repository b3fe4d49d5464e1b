"""The live pose stream's rate at a receiver, with a busy loop beside it (issue 55's figure).

    .venv/bin/python tools/stream_rate.py [--seconds 60] [--busy 1] [--audio FILE] [--json]

Runs ``gesture-sim live --headless --audio FILE --loop --mute --no-keywords --duration S
--stream 127.0.0.1:PORT`` with ``--busy`` processes spinning beside it (``while True: pass``),
and receives the VMC stream with python-osc (an independent OSC implementation). Prints the
frames received a second (over the receiving span), the gaps between arrivals (largest, p99,
how many over 50 ms), whether the ``/VMC/Ext/T`` stamps never go back, the loop's own figures
(viewer-less frames a second, real time, slips) and the load average when it ended.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--busy", type=int, default=1, help="busy-loop processes beside it")
    ap.add_argument("--audio", default=str(ROOT / "tests" / "data" / "audio" / "jfk.wav"))
    ap.add_argument("--rate", type=float, default=60.0, help="--stream-rate")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    arrivals: list[float] = []
    stamps: list[float] = []

    def on_t(address: str, t: float) -> None:
        arrivals.append(time.perf_counter())
        stamps.append(float(t))

    d = Dispatcher()
    d.map("/VMC/Ext/T", on_t)
    server = BlockingOSCUDPServer(("127.0.0.1", 0), d)
    # the receiver must not be what drops frames: a large buffer, and ahead of the busy loops
    # where the OS allows it (as the sender is: gesture_sim/app/pose_clock.py)
    server.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, 0, -10)
    th = threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True)
    th.start()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(args.busy)]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            stats_path = Path(tmp) / "stats.json"
            cmd = [sys.executable, "-m", "gesture_sim.cli", "live", "--headless", "--audio",
                   args.audio, "--loop", "--mute", "--no-keywords", "--duration",
                   str(args.seconds), "--stream", f"127.0.0.1:{server.server_address[1]}",
                   "--stream-rate", str(args.rate), "--stats", str(stats_path)]
            run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            if run.returncode != 0:
                sys.exit(f"live failed ({run.returncode}): {run.stderr[-2000:]}")
            live = json.loads(stats_path.read_text())
    finally:
        for p in busy:
            p.kill()
            p.wait()
        time.sleep(0.2)
        server.shutdown()
        server.server_close()
    load = os.getloadavg()
    a, t = np.array(arrivals), np.array(stamps)
    gaps = np.diff(a) * 1e3
    st = live["stream"]
    out = {
        "seconds": args.seconds, "busy_loops": args.busy, "rate_asked_hz": args.rate,
        "frames_received": int(len(a)),
        "received_rate_hz": round(float((len(a) - 1) / (a[-1] - a[0])), 2),
        "gap_max_ms": round(float(gaps.max()), 1),
        "gap_p99_ms": round(float(np.percentile(gaps, 99)), 1),
        "gaps_over_50ms": int(np.sum(gaps > 50.0)),
        "stamps_never_back": bool(np.all(np.diff(t) >= 0)),
        "sender": {k: st[k] for k in ("frames_sent", "frames_dropped", "sent_rate_hz",
                                      "gap_max_ms", "gap_p99_ms", "ticks_skipped",
                                      "frames_repeated", "send_ms_mean", "send_ms_max")},
        "loop": {"fps": live["fps"], "percent_real_time": live["percent_real_time"],
                 "slipped_s": live["slipped_s"]},
        "loadavg_1min_at_end": round(load[0], 2), "cpus": os.cpu_count(),
    }
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"received {out['frames_received']} frames in {args.seconds:.0f} s: "
              f"{out['received_rate_hz']} Hz (asked {args.rate:g}); largest gap "
              f"{out['gap_max_ms']} ms, p99 {out['gap_p99_ms']} ms, "
              f"{out['gaps_over_50ms']} over 50 ms; stamps never back: "
              f"{out['stamps_never_back']}; loop {live['fps']} fps, "
              f"{live['percent_real_time']}% real time; load {out['loadavg_1min_at_end']} "
              f"on {out['cpus']} CPUs with {args.busy} busy loop(s)")


if __name__ == "__main__":
    main()
