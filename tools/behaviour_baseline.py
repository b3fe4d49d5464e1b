"""Capture, or compare, the behaviour of the whole system for fixed seeds (issue 28: a refactor
must leave it unchanged, or explain every difference).

``capture DIR``: runs, with the CLI as a user would, and writes one metrics JSON per run into
DIR (wall-clock figures removed, the folder written as ``OUT``):

* ``render`` of every real recording in the repository (JFK, CMU ARCTIC a0007, two BEAT2 takes)
  with each selection method (``controller``, ``dcnf``, ``mimic``, ``levine09``), seed 0, at a
  small frame size (the metrics do not depend on it);
* ``render --two`` of the espeak-ng dialogue of :mod:`gesture_sim.testing.dialogue` (stereo,
  seed 0);
* ``eval motion`` of the two BEAT2 takes (one seed, ``--json``).

``compare A B``: every JSON of A against the one of the same name in B; prints the first
differing keys of each pair and exits 1 if any differ::

    .venv/bin/python tools/behaviour_baseline.py capture /tmp/before
    ... refactor ...
    .venv/bin/python tools/behaviour_baseline.py capture /tmp/after
    .venv/bin/python tools/behaviour_baseline.py compare /tmp/before /tmp/after
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDINGS = [ROOT / "assets" / "audio" / "jfk.wav",
              ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav",
              ROOT / "tests" / "data" / "pipeline" / "beat2_scott_0_2_2.wav",
              ROOT / "tests" / "data" / "eval" / "2_scott_0_1_1_first10s.wav"]
METHODS = ("controller", "dcnf", "mimic", "levine09")
SMALL = ["--width", "160", "--height", "90", "--fps", "10", "--quality", "fast"]
#: Keys measured on the wall clock (they differ between any two runs).
WALL = {"timing_s", "pipeline_realtime_factor", "render_realtime_factor",
        "total_realtime_factor", "wall_s", "elapsed_s", "seconds", "realtime_factor", "cpu_s",
        "core_share", "lag_median_s", "lag_max_s", "timing"}


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
               PYOPENGL_PLATFORM=os.environ.get("PYOPENGL_PLATFORM", "egl"))
    return subprocess.run([sys.executable, "-m", "gesture_sim.cli", *args], env=env,
                          capture_output=True, text=True, check=True)


def _clean(value, out: str | None):
    """``value`` without wall-clock keys, the output folder ``out`` written as ``OUT`` and the
    checkout's root as ``REPO``."""
    if isinstance(value, dict):
        return {k: _clean(v, out) for k, v in value.items() if k not in WALL}
    if isinstance(value, list):
        return [_clean(v, out) for v in value]
    if isinstance(value, str):
        if out:
            value = value.replace(out, "OUT")
        return value.replace(str(ROOT), "REPO")   # a capture of another checkout compares
    return value


def _save(path: Path, doc, out: str) -> None:
    path.write_text(json.dumps(_clean(doc, out), indent=1, sort_keys=True), encoding="utf-8")


def capture(folder: Path) -> int:
    folder.mkdir(parents=True, exist_ok=True)
    work = folder / "work"
    work.mkdir(exist_ok=True)
    out = str(work)
    for wav in RECORDINGS:
        for method in METHODS:
            name = f"render_{wav.stem}_{method}"
            metrics = work / f"{name}.json"
            _cli("render", str(wav), "-o", str(work / f"{name}.mp4"), "--metrics", str(metrics),
                 "--method", method, "--seed", "0", *SMALL)
            _save(folder / f"{name}.json", json.loads(metrics.read_text()), out)
            print(name, flush=True)
    from gesture_sim.testing.dialogue import make_dialogue

    stereo = make_dialogue(seed=0).write(work)["stereo"]
    metrics = work / "conversation.json"
    _cli("render", str(stereo), "--two", "-o", str(work / "conversation.mp4"), "--metrics",
         str(metrics), "--seed", "0", *SMALL)
    _save(folder / "render_two_dialogue.json", json.loads(metrics.read_text()), out)
    print("render_two_dialogue", flush=True)
    proc = _cli("eval", "motion", *map(str, RECORDINGS[2:]), "--seeds", "1", "--json")
    _save(folder / "eval_motion.json", json.loads(proc.stdout), out)
    print("eval_motion", flush=True)
    return 0


def _diff(a, b, path: str = "") -> list[str]:
    if type(a) is not type(b):
        return [f"{path or '/'}: {type(a).__name__} vs {type(b).__name__}"]
    if isinstance(a, dict):
        out = [f"{path}/{k}: only in one" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            out += _diff(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} vs {len(b)} items"]
        out = []
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            out += _diff(x, y, f"{path}[{i}]")
        return out
    return [] if a == b else [f"{path}: {a!r} vs {b!r}"]


def compare(a: Path, b: Path) -> int:
    bad = 0
    for fa in sorted(a.glob("*.json")):
        fb = b / fa.name
        if not fb.exists():
            print(f"{fa.name}: missing in {b}")
            bad += 1
            continue
        d = _diff(_clean(json.loads(fa.read_text()), None),
                  _clean(json.loads(fb.read_text()), None))
        if d:
            bad += 1
            print(f"{fa.name}: {len(d)} differences, first: " + "; ".join(d[:5]))
        else:
            print(f"{fa.name}: identical")
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="mode", required=True)
    sub.add_parser("capture").add_argument("folder", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args()
    return capture(args.folder) if args.mode == "capture" else compare(args.a, args.b)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
