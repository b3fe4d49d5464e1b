"""`gesture-sim prosody` and `gesture-sim bench prosody` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from gesture_sim.cli import main

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
ARCTIC = DATA / "arctic_a0007.wav"


def test_prosody_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "p.png"
    assert main(["prosody", str(ARCTIC), "--json", "--plot", str(png),
                 "--block-size", "4096"]) == 0
    out = json.loads(capsys.readouterr().out)
    s = out["summary"]
    assert out["speech_found"] and s["n_syllables"] == len(out["syllables"]) > 5
    assert s["duration_s"] == pytest.approx(4.0)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_prosody_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["prosody", str(ARCTIC)]) == 0
    out = capsys.readouterr().out
    assert "syllable rate" in out and "F0 range (p5-p95)" in out and "latency" in out


def test_silence_says_no_speech(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "silence.wav"
    wavfile.write(path, 16000, np.zeros(32000, dtype=np.int16))
    assert main(["prosody", str(path)]) == 0
    assert "no speech found" in capsys.readouterr().out


def test_broken_file_is_one_line_error(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "broken.wav"
    path.write_bytes(b"RIFF\x00\x00\x00\x00WAVEjunk")
    assert main(["prosody", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gesture-sim: error:") and "\n" not in err


def test_bench_prosody_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "prosody", "--json", "--repeat", "1", str(ARCTIC)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["files"] == 1 and out["syllables"] > 5
    assert 0 < out["latency_median_ms"] <= out["latency_p95_ms"] < 300
    assert out["per_file"][0]["syllables"] == out["syllables"]
    # the live path and the file path, timed in the same run
    assert out["realtime_factor"] > 0 and out["realtime_factor_file"] > 0
    assert out["file_to_live_cost"] > 0 and out["per_file"][0]["compute_s_file"] > 0
