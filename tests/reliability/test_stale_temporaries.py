"""Temporaries carry their owner's pid, and the next run removes those of dead owners (issue
49): a run killed outright (SIGKILL) leaves ``.tmp-*`` files beside its outputs and
``gesture-sim-video-*`` in the temp dir; the next run writing there removes them, and only them:
never a live process's, never a name that is not this package's."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import pytest

from gesture_sim import fileio
from gesture_sim.testing.processes import tagged_processes

ROOT = Path(__file__).resolve().parents[2]
SPEECH = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"
TAG = "GESTURE_SIM_FAULTS_TAG"


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _env(tmpdir: Path, tag: str = "x") -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT), MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl",
                TMPDIR=str(tmpdir), **{TAG: tag})


def test_every_temporary_name_holds_its_owner() -> None:
    me = os.getpid()
    for prefix in (fileio._tmp_prefix(Path("out/video.mp4")), fileio.temp_dir_prefix("video"),
                   fileio.owned_prefix(".tmp-probe-")):
        fd, name = tempfile.mkstemp(prefix=prefix, suffix=".mp4")
        os.close(fd)
        os.unlink(name)
        assert fileio.temp_owner(Path(name).name) == me, name
    long = Path("x" * 250 + ".json")
    assert len((fileio._tmp_prefix(long) + "abcdefgh.json.old").encode()) <= 255
    assert fileio.temp_owner(fileio._tmp_prefix(long) + "abcdefgh.json") == me
    for foreign in (".tmp-video-abcdefgh.mp4", "gesture_sim_kws_abcdefgh.list", "notes.txt",
                    f"other-pid{me}@{fileio._host_tag()}-abcdefgh",
                    f".tmp-x-pid{me}@000000-abcdefgh.mp4"):   # not ours, or another host's
        assert fileio.temp_owner(foreign) is None, foreign


def test_stale_temporaries_of_dead_owners_only_are_removed(tmp_path: Path) -> None:
    """A command that writes into a folder removes the dead runs' temporaries there and in the
    temp dir, and keeps a live process's and every name not this package's."""
    out, tmpdir = tmp_path / "out", tmp_path / "tmp"
    out.mkdir()
    tmpdir.mkdir()
    dead, live = _dead_pid(), os.getpid()
    stale = [out / (fileio.owned_prefix(".tmp-old-", dead) + "k2j3h4g5.mp4"),
             out / (fileio.owned_prefix(".tmp-rep-", dead) + "a1b2c3d4"),          # a stage
             tmpdir / (fileio.owned_prefix("gesture-sim-video-", dead) + "x7q1w2e3"),
             tmpdir / (fileio.owned_prefix("gesture-sim-kws-", dead) + "abcdefgh.list")]
    kept = [out / (fileio.owned_prefix(".tmp-old-", live) + "k2j3h4g5.mp4"),
            out / ".tmp-old-k2j3h4g5.mp4", out / "old.mp4",
            tmpdir / (fileio.owned_prefix("gesture-sim-video-", live) + "x7q1w2e3"),
            tmpdir / "gesture-sim-video-qwertyui", tmpdir / "someone-else.txt"]
    for p in stale + kept:
        if p.suffix:
            p.write_bytes(b"x")
        else:
            p.mkdir()
            (p / "chunk_000.mp4").write_bytes(b"x")
    proc = subprocess.run([sys.executable, "-m", "gesture_sim.cli", "prosody", str(SPEECH),
                           "--plot", str(out / "prosody.png")], env=_env(tmpdir),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert [p for p in stale if os.path.lexists(p)] == []
    assert [p for p in kept if not p.exists()] == []


@pytest.mark.slow
def test_a_killed_render_leaves_nothing_after_the_next_run(tmp_path: Path) -> None:
    out, tmpdir = tmp_path / "out", tmp_path / "tmp"
    out.mkdir()
    tmpdir.mkdir()
    tag = uuid.uuid4().hex
    cmd = [sys.executable, "-m", "gesture_sim.cli", "render", str(SPEECH), "-o",
           str(out / "v.mp4"), "--metrics", str(out / "m.json"), "--width", "160",
           "--height", "120", "--workers", "2"]
    proc = subprocess.Popen(cmd, env=_env(tmpdir, tag), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        end = time.monotonic() + 300
        while time.monotonic() < end and proc.poll() is None:
            cmds = list(tagged_processes(TAG, tag).values())
            if any(n.startswith(".tmp-") for n in os.listdir(out)) and any(
                    n.startswith("gesture-sim-video-") for n in os.listdir(tmpdir)) and sum(
                    "_worker_entry" in c for c in cmds) == 2 and any("ffmpeg" in c
                                                                    for c in cmds):
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the render ended before it could be killed"
        proc.kill()
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    end = time.monotonic() + 10                # its workers and their ffmpeg end with it
    while tagged_processes(TAG, tag) and time.monotonic() < end:
        time.sleep(0.1)
    left = tagged_processes(TAG, tag)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert left == {}, "orphaned render processes"
    assert any(n.startswith(".tmp-") for n in os.listdir(out))   # what SIGKILL leaves
    again = subprocess.run([sys.executable, "-m", "gesture_sim.cli", "prosody", str(SPEECH),
                            "--plot", str(out / "p.png")], env=_env(tmpdir),
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-2000:]
    assert sorted(os.listdir(out)) == ["p.png"]
    assert os.listdir(tmpdir) == []
