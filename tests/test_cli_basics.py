"""The command line and shared helpers: one-line errors, atomic outputs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path, atomic_write_text


def test_help_lists_commands() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "gesture_sim.cli", "--help"], capture_output=True, text=True,
        check=True,
    ).stdout
    assert "bench" in out


def test_atomic_path_leaves_target_untouched_on_failure(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_write_replaces(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "x.json"
    atomic_write_text(target, "{}")
    assert target.read_text() == "{}"


def test_unwritable_folder_is_a_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")  # a file where a folder is needed: unwritable even for root
    with pytest.raises(GestureSimError, match="cannot create output folder"):
        with atomic_path(blocker / "sub" / "a.mp4"):
            pass


def test_usage_errors_are_one_line(capsys) -> None:
    """Issue 27, sweep defect 18: argparse's usage + error (up to 13 lines) is one line now."""
    import pytest as _pytest

    from gesture_sim import cli as _cli

    for argv in (["render", "--fps"], ["bench", "nosuch"], ["library", "build"],
                 ["eval", "motion", "--seeds", "x", "a.wav"]):
        with _pytest.raises(SystemExit) as info:
            _cli.main(argv)
        assert info.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("gesture-sim") and "error:" in err[0], err


def test_a_legal_249_character_output_name_is_written(tmp_path) -> None:
    """Issue 27, sweep defect 12: the temporary beside a 249-character name stayed > 255."""
    from gesture_sim.fileio import atomic_write_text

    target = tmp_path / ("n" * 244 + ".json")
    atomic_write_text(target, "{}")
    assert target.read_text() == "{}" and [p.name for p in tmp_path.iterdir()] == [target.name]
