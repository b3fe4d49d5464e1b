"""A failed or interrupted ``train --corpus`` removes the folders it created (the output and
its ``.cache``), never one that existed before (issue 49)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
AUDIO = DATA / "eval" / "2_scott_0_1_1_first10s.wav"
MOTION = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
ENV = dict(os.environ, PYTHONPATH=str(ROOT), MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl")


def _corpus(tmp: Path, broken: bool) -> Path:
    corpus = tmp / "corpus"
    corpus.mkdir()
    if broken:
        (corpus / "a.npz").write_bytes(os.urandom(3000))
    else:
        shutil.copy(MOTION, corpus / "a.npz")
    shutil.copy(AUDIO, corpus / "a.wav")
    return corpus


def _train(corpus: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gesture_sim.cli", "train", "--corpus",
                           str(corpus), "-o", str(out)], env=ENV, capture_output=True,
                          text=True, timeout=300)


def test_a_failed_run_leaves_no_folder(tmp_path: Path) -> None:
    corpus = _corpus(tmp_path, broken=True)
    proc = _train(corpus, tmp_path / "new" / "out")
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "new").exists()


def test_a_failed_run_keeps_a_folder_that_existed(tmp_path: Path) -> None:
    corpus = _corpus(tmp_path, broken=True)
    out = tmp_path / "out"
    out.mkdir()
    proc = _train(corpus, out)
    assert proc.returncode == 2, proc.stderr
    assert out.is_dir() and list(out.iterdir()) == []     # its own .cache is gone


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_run_leaves_no_folder(tmp_path: Path, signum: int) -> None:
    corpus = _corpus(tmp_path, broken=False)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "gesture_sim.cli", "train", "--corpus",
                             str(corpus), "-o", str(out)], env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 120
        while not (out / ".cache").is_dir() and time.monotonic() < end:
            assert proc.poll() is None, proc.communicate()[1]
            time.sleep(0.01)
        proc.send_signal(signum)
        _o, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 128 + signum, err
    assert "Traceback" not in err, err
    assert not out.exists(), sorted(str(p) for p in out.rglob("*"))
