"""The pose stream on its own clock (:class:`gesture_sim.app.pose_clock.ClockedStream`): a fixed
rate whatever the publisher does, the published state's time on each frame, a consistent copy,
the all-frames-failed flag, and no process left behind.

A stand-in sender puts (t, qpos[0], qpos[-1]) on a local UDP socket, so that the frames of the
forked child process are seen by the test process too. Rates are asserted loosely (a 60 Hz
clock must deliver >= 40 Hz over 1.5 s on a loaded 2-core machine; measured 60.0), never a
wall-clock bound on the test itself.
"""

from __future__ import annotations

import os
import socket
import struct
import time

import mujoco
import numpy as np
import pytest

from gesture_sim.app.pose_clock import ClockedStream
from gesture_sim.errors import GestureSimError

XML = """<mujoco><worldbody><body><freejoint/><geom size="0.1"/>
<body pos="0 0 0.3"><joint type="hinge"/><geom size="0.05"/></body></body></worldbody></mujoco>"""


class UdpStandIn:
    """A sender: (t, qpos[0], qpos[-1]) as three doubles to ``port``; or refuses every frame."""

    def __init__(self, port: int, refuse: bool = False) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.port, self.refuse = port, refuse
        self.address = f"127.0.0.1:{port}"
        self.sent = self.dropped = 0

    def send(self, model, qpos, t) -> bool:
        if self.refuse:
            self.dropped += 1
            return False
        self.sock.sendto(struct.pack("<3d", t, qpos[0], qpos[-1]), ("127.0.0.1", self.port))
        self.sent += 1
        return True

    def stats(self) -> dict:
        return {"frames_sent": self.sent, "frames_dropped": self.dropped, "last_error":
                "refused" if self.refuse else ""}

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def inbox():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    yield sock
    sock.close()


def drain(sock: socket.socket) -> list[tuple[float, float, float, float]]:
    """(arrival s, t, qpos[0], qpos[-1]) of every datagram waiting."""
    out = []
    while True:
        try:
            b = sock.recv(64)
        except TimeoutError:
            return out
        out.append((time.perf_counter(), *struct.unpack("<3d", b)))


def run_for(stream: ClockedStream, inbox, seconds: float, publish_hz: float):
    """Publish a pose whose every coordinate equals its time, at ``publish_hz``, for
    ``seconds``; return what arrived."""
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    stream.start(model, data)
    stream.child_pid = stream._pid        # for the test: the child must be gone after stop
    got: list = []
    t_end = time.perf_counter() + seconds
    try:
        while time.perf_counter() < t_end:
            data.time += 1.0 / publish_hz
            data.qpos[:] = data.time          # a torn copy would mix two times
            stream.publish(data)
            got += drain_nowait(inbox)
            time.sleep(1.0 / publish_hz)
    finally:
        stream.stop()
    time.sleep(0.1)
    return got + drain(inbox)


def drain_nowait(sock: socket.socket) -> list:
    sock.setblocking(False)
    out = []
    try:
        while True:
            try:
                b = sock.recv(64)
            except BlockingIOError:
                return out
            out.append((time.perf_counter(), *struct.unpack("<3d", b)))
    finally:
        sock.settimeout(0.05)


@pytest.mark.parametrize("mode", ["process", "thread"])
def test_the_stream_keeps_its_own_rate_whatever_the_publisher_does(inbox, mode) -> None:
    port = inbox.getsockname()[1]
    stream = ClockedStream(UdpStandIn(port), rate_hz=60.0, mode=mode)
    got = run_for(stream, inbox, 1.5, publish_hz=12.0)        # a 12 fps "viewer"
    st = stream.stats()
    assert st["mode"] == mode and st["rate_hz"] == 60.0
    arrival = np.array([g[0] for g in got])
    t = np.array([g[1] for g in got])
    assert len(got) == st["frames_sent"]
    rate = (len(got) - 1) / (arrival[-1] - arrival[0])
    assert rate >= 40.0, rate                 # the clock's rate, not the publisher's 12 Hz
    assert st["sent_rate_hz"] >= 40.0
    assert np.all(np.diff(t) >= 0.0) and st["sim_t_backwards"] == 0
    # each frame is one published state, never a mix of two (the sequence lock)
    assert all(g[1] == g[2] == g[3] for g in got[1:])
    # five clock ticks per published state: most frames repeat the last pose
    assert st["frames_repeated"] > 0.5 * len(got)
    assert 0.0 < st["gap_max_ms"] < 1000.0 and 12.0 < st["gap_mean_ms"] <= 25.0   # 60 Hz: 16.7
    assert not st["failed"]
    if mode == "process":
        assert stream.child_pid is not None
        with pytest.raises(ChildProcessError):      # the child is reaped: none left behind
            os.waitpid(stream.child_pid, os.WNOHANG)


def test_a_stream_whose_every_frame_fails_says_so(inbox) -> None:
    port = inbox.getsockname()[1]
    stream = ClockedStream(UdpStandIn(port, refuse=True), rate_hz=60.0, fail_after_s=0.3)
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    assert not stream.failed                        # nothing tried yet
    stream.start(model, data)
    try:
        deadline = time.perf_counter() + 10.0
        while not stream.failed and time.perf_counter() < deadline:
            time.sleep(0.02)
        assert stream.failed
    finally:
        stream.stop()
    st = stream.stats()
    assert st["frames_sent"] == 0 and st["frames_dropped"] > 0 and st["failed"]


def test_a_bad_rate_or_mode_is_one_line() -> None:
    for rate in (0.0, -5.0, float("nan"), 1e6):
        with pytest.raises(GestureSimError, match="stream rate"):
            ClockedStream(UdpStandIn(9), rate_hz=rate)
    with pytest.raises(GestureSimError, match="stream mode"):
        ClockedStream(UdpStandIn(9), mode="fibre")
