"""The same input, seed and settings give byte-identical outputs: mp4, metrics JSON (with the
decision log) and timeline figure, from two separate ``gesture-sim render`` processes."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SPEECH = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("reliability-render")]


def _render(out: Path, tmp: Path) -> dict[str, bytes]:
    out.mkdir()
    env = dict(os.environ, MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl", TMPDIR=str(tmp))
    cmd = [sys.executable, "-m", "gesture_sim.cli", "render", str(SPEECH),
           "-o", str(out / "a.mp4"), "--metrics", str(out / "a.json"),
           "--timeline", str(out / "a.png"), "--width", "320", "--height", "240",
           "--workers", "2", "--seed", "7", "--style", "0.7", "--label", "1.5:wave",
           "--quality", "fast"]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600,
                          cwd=out.parent)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {p.name: p.read_bytes() for p in sorted(out.iterdir())}


def _json_diff(a, b, path: str = "") -> str:
    """The first few paths where two JSON documents differ (for the failure message)."""
    if type(a) is not type(b):
        return f"{path}: {a!r} != {b!r}; "
    if isinstance(a, dict):
        return "".join(_json_diff(a.get(k), b.get(k), f"{path}/{k}")
                       for k in sorted(set(a) | set(b)))[:2000]
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path}: {len(a)} != {len(b)} items; "
        return "".join(_json_diff(x, y, f"{path}[{i}]") for i, (x, y) in
                       enumerate(zip(a, b, strict=True)))[:2000]
    return "" if a == b else f"{path}: {a!r} != {b!r}; "


def test_same_input_same_bytes(tmp_path: Path) -> None:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    # the same output paths both times (the metrics name them); the first run's files are kept
    first = _render(tmp_path / "run", tmp)
    (tmp_path / "run").rename(tmp_path / "first")
    second = _render(tmp_path / "run", tmp)
    assert sorted(first) == ["a.json", "a.mp4", "a.png"]
    assert sorted(second) == sorted(first)
    for name in first:
        where = _json_diff(json.loads(first[name]), json.loads(second[name])) \
            if name.endswith(".json") and first[name] != second[name] else ""
        assert hashlib.sha256(first[name]).hexdigest() == \
            hashlib.sha256(second[name]).hexdigest(), f"{name} differs between runs {where}"
    doc = json.loads(first["a.json"])
    assert doc["decision_log"], "no decisions logged"
    assert doc["seed"] == 7
    assert list(tmp.iterdir()) == []
