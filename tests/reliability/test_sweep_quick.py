"""``tools/reliability_sweep.py --quick`` runs its handful of seeded cases (hostile command
lines, a SIGTERM and a SIGKILL at random moments) and every one holds (issue 49)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_quick_sweep_holds(tmp_path: Path) -> None:
    out = tmp_path / "sweep.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT), MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl")
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "reliability_sweep.py"),
                           "--quick", "--json", str(out)], env=env, capture_output=True,
                          text=True, timeout=600)
    report = json.loads(out.read_text())
    summary = report["summary"]
    assert summary["cases"] == len(report["cases"]) >= 6
    assert summary["signal_cases"] >= 2
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert summary["fails"] == 0 and summary["holds"] == summary["cases"]
    for case in report["cases"]:
        assert {"rc", "one_line", "traceback", "leftovers", "orphans"} <= set(case)


def test_the_full_sweep_has_enough_cases() -> None:
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import reliability_sweep as rs
    finally:
        sys.path.remove(str(ROOT / "tools"))
    every = rs.cases(49, quick=False)
    assert len(every) >= 300 and len({c.id for c in every}) == len(every)
    assert sum(c.kind == "signal" for c in every) >= rs.N_SIGNALS
    assert rs.cases(49, quick=False)[0].id == every[0].id      # seeded
