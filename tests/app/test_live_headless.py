"""``gesture-sim live --headless``: the whole live loop with no window, its pose stream on its own
clock, received by an independent OSC implementation (python-osc), and the stream's bad inputs
(issue 55 item 2, issue 49's ``live --stream`` cases).

The rate is asserted loosely (>= 40 frames a second of a 60 Hz clock over a 5 s run, no gap over
250 ms), so that a loaded 2-core machine never makes it flaky: measured 60.2 Hz, largest gap
35 ms at load 5.7 on 2 cores. The strict figure of issue 55 (>= 55 Hz, no gap over 50 ms, 60 s,
one busy loop beside it) is ``tools/stream_rate.py``'s.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pythonosc")     # a dev dependency (pyproject.toml)
from pythonosc.dispatcher import Dispatcher  # noqa: E402
from pythonosc.osc_server import BlockingOSCUDPServer  # noqa: E402

from gesture_sim.export.vmc import BONE_NAMES  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ARCTIC = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"  # 4 s


class OscReceiver:
    """A python-osc server on 127.0.0.1 (a free port), in a thread: the arrival time and value
    of every ``/VMC/Ext/T`` and the bone names of every frame."""

    def __init__(self) -> None:
        self.times: list[tuple[float, float]] = []
        self.bones: list[set[str]] = [set()]
        self.hips_y: list[float] = []
        d = Dispatcher()
        d.map("/VMC/Ext/T", self._on_t)
        d.map("/VMC/Ext/Bone/Pos", self._on_bone)
        self.server = BlockingOSCUDPServer(("127.0.0.1", 0), d)
        self.address = f"127.0.0.1:{self.server.server_address[1]}"
        self._thread = threading.Thread(target=self.server.serve_forever, args=(0.05,),
                                        daemon=True)
        self._thread.start()

    def _on_t(self, address: str, t: float) -> None:
        self.times.append((time.perf_counter(), float(t)))
        self.bones.append(set())

    def _on_bone(self, address: str, name: str, *values: float) -> None:
        self.bones[-1].add(name)
        if name == "Hips":
            self.hips_y.append(values[1])

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=5)


def _live(*args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    env.pop("DISPLAY", None)              # headless means no window: none to be found
    env.pop("WAYLAND_DISPLAY", None)
    return subprocess.run([sys.executable, "-m", "gesture_sim.cli", "live", *args], env=env,
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.slow
def test_headless_live_streams_vmc_on_its_own_clock_to_a_python_osc_receiver() -> None:
    rx = OscReceiver()
    try:
        cli = _live("--headless", "--audio", str(ARCTIC), "--mute", "--no-keywords",
                    "--stream", rx.address, "--json")
        time.sleep(0.2)                   # the last datagrams in flight
    finally:
        rx.close()
    assert cli.returncode == 0, cli.stderr[-3000:]
    out = json.loads(cli.stdout)
    assert out["exit_reason"] == "end of audio" and out["frames"] > 0
    st = out["stream"]
    assert st["protocol"] == "vmc" and st["mode"] == "process" and st["rate_hz"] == 60.0
    assert st["frames_dropped"] == 0 and not st["failed"]
    arrival = np.array([a for a, _ in rx.times])
    t = np.array([v for _, v in rx.times])
    # each frame with its T; UDP on loopback may lose a datagram when the receiving test
    # thread is starved of CPU. The rates are loose (the strict 60 s figure, >= 55 Hz and no
    # gap over 50 ms beside a busy loop, is tools/stream_rate.py's: BENCHMARKS "Exports")
    assert 0.9 * st["frames_sent"] <= len(t) <= st["frames_sent"] and len(t) > 0
    rate = (len(t) - 1) / (arrival[-1] - arrival[0])
    assert rate >= 20.0, (rate, st)
    assert np.diff(arrival).max() < 0.5, (np.diff(arrival).max(), st)
    assert st["sent_rate_hz"] >= 20.0 and st["gap_max_ms"] < 500.0
    # the frames carry the simulation's time: from 0, never back, into the speech (a loaded
    # machine slips: measured 1.9-4.9 s of the 4 s file plus its 1 s tail, 0.47 s at load 14
    # on 2 cores, where the loop itself ran at about 1 frame a second)
    assert t[0] == 0.0 and np.all(np.diff(t) >= 0.0) and t[-1] > 0.0
    assert t[-1] == pytest.approx(out["sim_s"], abs=0.05)
    assert all(b == set(BONE_NAMES) for b in rx.bones[:-1][1:])   # every bone in every frame
    assert all(0.85 < y < 1.05 for y in rx.hips_y)                 # the body stands


@pytest.mark.slow
def test_a_stream_where_every_frame_fails_stops_with_one_line(tmp_path: Path) -> None:
    """A broadcast address refuses every datagram (no SO_BROADCAST): the loop stops after a
    second of refused frames, and the command says so in one line, exit 2 (it ran on, exit 0,
    before: the drops only in the summary)."""
    stats = tmp_path / "stats.json"
    cli = _live("--headless", "--audio", str(ARCTIC), "--mute", "--no-keywords", "--loop",
                "--stream", "255.255.255.255:9", "--stats", str(stats))
    assert cli.returncode == 2, (cli.returncode, cli.stderr[-3000:])
    err = cli.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        "gesture-sim: error: --stream 255.255.255.255:9: no frame went out"), err
    st = json.loads(stats.read_text())
    assert st["exit_reason"].startswith("stream failed")      # stopped early, not at the end
    assert st["stream"]["frames_sent"] == 0 and st["stream"]["frames_dropped"] > 0


@pytest.mark.parametrize("argv, message", [
    (["--stream", ""], "stream address: expected HOST:PORT"),
    (["--stream", "   "], "stream address: expected HOST:PORT"),
    (["--stream-rate", "30"], "--stream-rate needs --stream ADDRESS"),
    (["--stream", "127.0.0.1:9", "--stream-rate", "0"], "--stream-rate must be"),
    (["--stream", "127.0.0.1:9", "--stream-rate", "nan"], "--stream-rate must be"),
    (["--stream", "127.0.0.1:9", "--stream-rate", "1e6"], "--stream-rate must be"),
])
def test_bad_stream_options_are_one_line_before_anything_loads(capsys, argv, message) -> None:
    from gesture_sim import cli

    assert cli.main(["live", "--headless", "--audio", str(ARCTIC), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gesture-sim: error: ") and message in err[0], err


def _processes_with(marker: str) -> list[int]:
    """Pids whose command line holds ``marker`` (Linux /proc)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if marker in cmd and "pytest" not in cmd:
            pids.append(int(d.name))
    return pids


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGKILL, -9)])
def test_no_stream_process_outlives_the_live_loop(sig, code) -> None:
    """SIGTERM: exit 143 and the forked sender is gone with it; SIGKILL of the loop alone: the
    sender sees its parent gone and leaves within a frame or two (no orphan streaming on)."""
    rx = OscReceiver()
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    env.pop("DISPLAY", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "gesture_sim.cli", "live", "--headless", "--audio", str(ARCTIC),
         "--loop", "--mute", "--no-keywords", "--stream", rx.address], env=env, cwd=ROOT,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 150
        while len(rx.times) < 30 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
        assert len(rx.times) >= 30, proc.stderr.read().decode()[-2000:] if proc.poll() else ""
        assert len(_processes_with(rx.address)) == 2          # the loop and its sender
        proc.send_signal(sig)
        assert proc.wait(timeout=30) == code
        deadline = time.monotonic() + 5
        while _processes_with(rx.address) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _processes_with(rx.address) == []          # no sender streams on, orphaned
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in _processes_with(rx.address):
            os.kill(pid, signal.SIGKILL)
        rx.close()


@pytest.mark.slow
@pytest.mark.parametrize("body", ["g1", "h1"])
def test_headless_live_drives_a_robot_body_to_the_end_of_the_speech(body: str) -> None:
    """``live --body g1|h1`` (issue 52 item 5): the robot's pipeline (its library frames, the
    per-step IK, its motors) runs the live loop to the end of the audio. Measured on jfk.wav
    (11 s), 2 cores at load 4.5: G1 76 %, H1 76 % of real time, the humanoid 60 % in the same
    minute (the real-time figure is the report's, not asserted: a loaded machine slips)."""
    cli = _live("--headless", "--body", body, "--audio", str(ARCTIC), "--mute", "--no-keywords",
                "--json")
    assert cli.returncode == 0, cli.stderr[-3000:]
    out = json.loads(cli.stdout)
    assert out["body"] == body and out["exit_reason"] == "end of audio"
    assert out["frames"] > 10 and out["sim_s"] > 1.0
    assert out["physics_steps_per_frame"]["mean"] > 0       # the robot's physics stepped
    assert out["audio"]["overflow_events"] == 0
