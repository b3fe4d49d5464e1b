"""The validation layer and the multi-output commit, in process (fast)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from gesture_sim import validation as v
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_outputs

from . import badfiles


@pytest.mark.parametrize("x", [math.nan, math.inf, -math.inf, 0.0, 241.0, "30"])
def test_fps_refuses_what_is_not_a_sane_rate(x) -> None:
    with pytest.raises(GestureSimError, match=r"--fps must be a number from 1 to 240"):
        v.fps("--fps", x)


def test_numbers_in_range_pass_through() -> None:
    assert v.fps("--fps", 30) == 30.0
    assert v.style("--style", 1) == 1.0
    assert v.seed("--seed", 2**32 - 1) == 2**32 - 1
    assert v.frame_size(1280, 720) == (1280, 720)
    assert v.workers("--workers", None) is None


def test_style_message_is_in_user_units() -> None:
    with pytest.raises(GestureSimError) as e:
        v.style("--style", 5)
    assert "from 0 to 1" in str(e.value) and "5" in str(e.value) and "[-1, 1]" not in str(e.value)


def test_integer_refuses_bools_floats_and_odd_sizes() -> None:
    for bad in (True, 1.5, math.nan):
        with pytest.raises(GestureSimError):
            v.integer("--n", bad, 0, 10)
    with pytest.raises(GestureSimError, match="even"):
        v.frame_size(1281, 720)


def test_labels_past_the_end_are_refused() -> None:
    assert v.labels("--label", [(1.0, "wave")], duration_s=4.0) == ((1.0, "wave"),)
    for t in (-1.0, math.nan, math.inf, 4.5):
        with pytest.raises(GestureSimError, match="--label"):
            v.labels("--label", [(t, "wave")], duration_s=4.0)


def test_check_outputs_resolves_symlinks_and_hard_links(tmp_path: Path) -> None:
    inp = tmp_path / "in.wav"
    inp.write_bytes(b"speech")
    os.link(inp, tmp_path / "hard.mp4")
    (tmp_path / "soft.mp4").symlink_to(inp)
    for name in ("hard.mp4", "soft.mp4"):
        with pytest.raises(GestureSimError, match="is the input file"):
            v.check_outputs([v.Output("-o", tmp_path / name, v.VIDEO_EXTENSIONS)], [inp])
    target = tmp_path / "real.mp4"
    target.write_bytes(b"previous video")   # a dangling link is refused (sweep defect 17)
    (tmp_path / "link.mp4").symlink_to(target)
    (out,) = v.check_outputs([v.Output("-o", tmp_path / "link.mp4", v.VIDEO_EXTENSIONS)], [inp])
    assert out == target.resolve()   # writing there keeps the link, pointing at the new file


def test_check_outputs_refuses_duplicates_folders_and_special_files(tmp_path: Path) -> None:
    (tmp_path / "d.json").mkdir()
    os.mkfifo(tmp_path / "f.mp4")
    cases = [
        ([v.Output("-o", tmp_path / "a.mp4"), v.Output("--m", tmp_path / "x" / ".." / "a.mp4")],
         "is also the path of -o"),
        ([v.Output("--m", tmp_path / "d.json", v.JSON_EXTENSIONS)], "is an existing folder"),
        ([v.Output("-o", tmp_path / "f.mp4", v.VIDEO_EXTENSIONS)], "is a FIFO"),
        ([v.Output("-o", tmp_path / "a.gif", v.VIDEO_EXTENSIONS)], "unsupported file type"),
        ([v.Output("-o", "/dev/null")], "is a device"),
    ]
    for outputs, match in cases:
        with pytest.raises(GestureSimError, match=match):
            v.check_outputs(outputs)
    assert not (tmp_path / "a.mp4").exists()


def test_atomic_outputs_commit_together_or_not_at_all(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mp4", tmp_path / "b.json"
    a.write_text("old a")
    b.write_text("old b")
    with pytest.raises(RuntimeError), atomic_outputs(a, None, b) as (ta, none, tb):
        assert none is None
        ta.write_text("new a")
        raise RuntimeError("the second output failed")
    assert (a.read_text(), b.read_text()) == ("old a", "old b")
    with pytest.raises(KeyboardInterrupt), atomic_outputs(a, b) as (ta, tb):
        ta.write_text("new a")
        tb.write_text("new b")
        raise KeyboardInterrupt
    assert (a.read_text(), b.read_text()) == ("old a", "old b")
    with atomic_outputs(a, b) as (ta, tb):
        ta.write_text("new a")
        tb.write_text("new b")
    assert (a.read_text(), b.read_text()) == ("new a", "new b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mp4", "b.json"]


def test_damaged_policy_files_are_one_line(tmp_path: Path) -> None:
    from gesture_sim.control.policy import Policy

    models = badfiles.make_models(tmp_path)
    for name in ("policy_truncated", "policy_garbage", "policy_keys"):
        path = models[name] / "policy.npz"
        with pytest.raises(GestureSimError) as e:
            Policy.load(path)
        assert str(path) in str(e.value) and "\n" not in str(e.value)
