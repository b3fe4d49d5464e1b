"""``gesture-sim render --signals FILE``: a bad file is one line and exit status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

WAV = Path(__file__).resolve().parents[1] / "data" / "audio" / "jfk.wav"


def test_bad_signals_file_is_one_line_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.txt"
    bad.write_text("1.0 nod\n2.0 frown\n", encoding="utf-8")
    p = subprocess.run([sys.executable, "-m", "gesture_sim.cli", "render", str(WAV), "-o",
                        str(tmp_path / "o.mp4"), "--signals", str(bad)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gesture-sim: error: ")
    assert "bad.txt:2" in lines[0] and "frown" in lines[0]
    assert not (tmp_path / "o.mp4").exists()
