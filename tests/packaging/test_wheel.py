"""The package works installed: sdist -> wheel -> fresh venv -> `demo` and `render` elsewhere.

The source tree is copied (without .git, .venv, tests, tools) to a temporary folder; the sdist is
built there with setuptools' own build hooks (so MANIFEST.in is exercised) and the wheel is
built from the unpacked sdist, as ``python -m build`` does, with ``--no-build-isolation`` so that
nothing is downloaded (setuptools comes from the dev extra). The wheel goes into a new venv that
sees this environment's site-packages only through a ``.pth`` line (the dependencies; not the
editable install of the checkout), and the commands run in an empty temporary folder.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import time
import wave
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
#: Top-level entries of the checkout not copied for the build.
NOT_COPIED = {".git", ".venv", "tests", "tools", "docs", "out", "build", "dist", ".ci",
              ".pytest_cache", ".ruff_cache", "MUJOCO_LOG.TXT"}

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("packaging")]


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env.setdefault("MUJOCO_GL", "egl")
    return env


def _run(cmd: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    result = subprocess.run([str(c) for c in cmd], cwd=cwd, env=_env(), capture_output=True,
                            text=True, timeout=timeout)
    assert result.returncode == 0, (
        f"{' '.join(map(str, cmd))} failed ({result.returncode}):\n{result.stdout[-3000:]}\n"
        f"{result.stderr[-3000:]}")
    return result


def _ignore(folder: str, names: list[str]) -> set[str]:
    skip = {n for n in names if n == "__pycache__" or n.endswith(".egg-info")
            or n.startswith(".tmp-")}
    if Path(folder) == REPO:
        skip |= NOT_COPIED & set(names)
    return skip


def _build_wheel(tmp: Path) -> Path:
    src = tmp / "src"
    shutil.copytree(REPO, src, ignore=_ignore)
    sdist_dir, wheel_dir = tmp / "sdist", tmp / "wheel"
    sdist_dir.mkdir()
    _run([sys.executable, "-c",
          f"from setuptools import build_meta; build_meta.build_sdist({str(sdist_dir)!r})"], src)
    (sdist,) = sdist_dir.glob("gesture_sim-*.tar.gz")
    with tarfile.open(sdist) as tar:
        if hasattr(tarfile, "data_filter"):     # Python >= 3.11.4
            tar.extractall(tmp / "unpacked", filter="data")
        else:
            tar.extractall(tmp / "unpacked")
    (unpacked,) = (tmp / "unpacked").iterdir()
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
          "-q", "-w", wheel_dir, unpacked], tmp)
    (wheel,) = wheel_dir.glob("gesture_sim-*.whl")
    return wheel


def _venv_with_wheel(tmp: Path, wheel: Path) -> Path:
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], tmp)
    python = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index",
          "-q", wheel], tmp)
    site = subprocess.run([str(python), "-c", "import sysconfig; "
                           "print(sysconfig.get_paths()['purelib'])"], capture_output=True,
                          text=True, check=True, env=_env()).stdout.strip()
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (Path(site) / "zz_test_dependencies.pth").write_text("\n".join(sorted(deps)) + "\n")
    return venv


def _short_wav(source: Path, target: Path, seconds: float) -> None:
    with wave.open(str(source)) as w:
        params = w.getparams()
        frames = w.readframes(int(seconds * w.getframerate()))
    with wave.open(str(target), "wb") as out:
        out.setparams(params)
        out.writeframes(frames)


def test_installed_wheel_renders_from_another_folder(tmp_path: Path) -> None:
    t0 = time.perf_counter()
    wheel = _build_wheel(tmp_path)
    t_build = time.perf_counter() - t0
    venv = _venv_with_wheel(tmp_path, wheel)
    t_install = time.perf_counter() - t0 - t_build
    work = tmp_path / "elsewhere"
    work.mkdir()

    where = json.loads(_run([venv / "bin" / "python", "-c",
                             "import gesture_sim as g, json; print(json.dumps([g.__file__, "
                             "str(g.DATA_DIR), str(g.DEFAULT_LIBRARY_DIR), str(g.MJCF_DIR), "
                             "str(g.EXAMPLE_SPEECH)]))"], work).stdout)
    package, data, library, mjcf, speech = map(Path, where)
    assert venv in package.parents, f"imported {package}, not the installed wheel"
    assert data == package.parent / "_data"
    assert (library / "manifest.json").is_file() and (library / "model" / "model.json").is_file()
    assert (mjcf / "humanoid.xml").is_file() and (mjcf / "scene.xml").is_file()
    assert speech.is_file()

    _short_wav(speech, work / "speech.wav", 1.5)
    small = ["--quality", "fast", "--width", "160", "--height", "120", "--workers", "1",
             "--json"]
    gesture_sim = venv / "bin" / "gesture-sim"
    render = _run([gesture_sim, "render", "speech.wav", "-o", "out/speech.mp4", "--bvh",
                   "out/speech.bvh", "--npz", "out/speech.npz", *small], work)
    summary = json.loads(render.stdout)
    assert summary["frames"] == 45 and summary["physics"]["fell"] is False
    assert (work / "out" / "speech.mp4").stat().st_size > 1000
    bvh_text = (work / "out" / "speech.bvh").read_text()
    assert bvh_text.startswith("HIERARCHY\nROOT Hips") and "Frames: 45\n" in bvh_text
    _run([venv / "bin" / "python", "-c",
          "import numpy as np; from gesture_sim.motion.bvh import read_bvh; "
          "m = read_bvh('out/speech.bvh'); d = np.load('out/speech.npz'); "
          "assert m.fps == 30 and m.positions.shape[0] == 45; "
          "assert d['qpos'].ndim == 2 and len(d['decision_t']) >= 1"], work)

    demo = _run([gesture_sim, "demo", "-o", "demo/demo.mp4", *small], work)
    assert json.loads(demo.stdout)["duration_s"] > 10.0
    for name in ("demo.mp4", "demo_timeline.png", "demo_metrics.json"):
        assert (work / "demo" / name).stat().st_size > 1000
    t_total = time.perf_counter() - t0
    print(f"wheel {wheel.stat().st_size / 1e6:.1f} MB; build {t_build:.1f} s, install "
          f"{t_install:.1f} s, build+install+render+demo {t_total:.1f} s")
