"""The live pose stream's rate at a receiver, with a busy loop beside it (issue 55's figure).

    .venv/bin/python tools/stream_rate.py [--seconds 60] [--busy 1] [--audio FILE] [--json]

Runs ``gesture-sim live --headless --audio FILE --loop --mute --no-keywords --duration S
--stream 127.0.0.1:PORT`` with ``--busy`` processes spinning beside it (``while True: pass``, each
in a session of its own unless ``--busy-session same``),
and receives the VMC stream, decoded by python-osc (an independent OSC implementation), each
datagram timed by the kernel on arrival (``SO_TIMESTAMPNS``). Prints the
frames received a second (over the receiving span), the gaps between arrivals (largest, p99,
how many over 50 ms), whether the ``/VMC/Ext/T`` stamps never go back, the loop's own figures
(viewer-less frames a second, real time, slips) and the load average when it ended.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage

ROOT = Path(__file__).resolve().parents[1]
#: Linux's SO_TIMESTAMPNS (also the control message's type; Python's socket module lacks it)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--busy", type=int, default=1, help="busy-loop processes beside it")
    ap.add_argument("--audio", default=str(ROOT / "tests" / "data" / "audio" / "jfk.wav"))
    ap.add_argument("--rate", type=float, default=60.0, help="--stream-rate")
    ap.add_argument("--busy-session", choices=("own", "same"), default="own",
                    help="own (default): each busy loop in a session of its own, as a program "
                         "started beside it is (on Linux with autogroups, its own scheduling "
                         "group); same: in this tool's session, sharing the receiver's and the "
                         "live loop's group")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    arrivals: list[float] = []
    stamps: list[float] = []
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    # the receiver must not be what drops or delays frames: a large buffer, and each
    # datagram's arrival time from the kernel (SO_TIMESTAMPNS), not from when this process
    # got round to it
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.settimeout(0.05)
    stop = threading.Event()

    def receive() -> None:
        while not stop.is_set():
            try:
                data, anc, _, _ = sock.recvmsg(65536, 1024)
            except TimeoutError:
                continue
            arrival = time.time()
            for level, kind, raw in anc:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                    sec, nsec = struct.unpack("qq", raw[:16])
                    arrival = sec + 1e-9 * nsec
            if OscBundle.dgram_is_bundle(data):
                bundle = OscBundle(data)
                contents = [bundle.content(i) for i in range(bundle.num_contents)]
            else:
                contents = [OscMessage(data)]
            for content in contents:
                if isinstance(content, OscMessage) and content.address == "/VMC/Ext/T":
                    arrivals.append(arrival)
                    stamps.append(float(content.params[0]))

    th = threading.Thread(target=receive, daemon=True)
    th.start()
    port = sock.getsockname()[1]
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                             start_new_session=args.busy_session == "own")
            for _ in range(args.busy)]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            stats_path = Path(tmp) / "stats.json"
            cmd = [sys.executable, "-m", "gesture_sim.cli", "live", "--headless", "--audio",
                   args.audio, "--loop", "--mute", "--no-keywords", "--duration",
                   str(args.seconds), "--stream", f"127.0.0.1:{port}",
                   "--stream-rate", str(args.rate), "--stats", str(stats_path)]
            run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            if run.returncode != 0:
                sys.exit(f"live failed ({run.returncode}): {run.stderr[-2000:]}")
            live = json.loads(stats_path.read_text())
    finally:
        for p in busy:
            p.kill()
            p.wait()
        time.sleep(0.5)
        stop.set()
        th.join(timeout=5)
        sock.close()
    load = os.getloadavg()
    a, t = np.array(arrivals), np.array(stamps)
    gaps = np.diff(a) * 1e3
    st = live["stream"]
    out = {
        "seconds": args.seconds, "busy_loops": args.busy, "busy_session": args.busy_session,
        "rate_asked_hz": args.rate,
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
