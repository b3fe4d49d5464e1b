"""Outputs are checked before the work, published all or nothing, and a refused write is one line.

Defects of the hostile-input sweep (numbers as in the sweep): 2 (an interrupted ``eval
--report`` or ``library graph --plot`` had replaced some outputs already), 3 (files inside the
report folder were not checked before the work), 9 (a full disk while writing: a traceback and
empty folders left), 10 (a rename the OS refuses showed up only at the end), 11 (a symlink loop
as an output: ``RuntimeError``), 17 (a dangling symlink was followed and its target folders
created), 24 (a replaced output lost its permission bits). Fast: unit tests of
:mod:`gesture_sim.fileio` and :mod:`gesture_sim.validation`, and in-process command lines whose
heavy parts are stubbed out.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import stat
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest

from gesture_sim import cli, fileio
from gesture_sim import validation as v
from gesture_sim.errors import GestureSimError

ROOT = Path(__file__).resolve().parents[1]
SPEECH = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"


def _enospc(*_args, **_kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1 and lines[0].startswith("gesture-sim: error: "), err
    return lines[0]


def _entries(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ------------------------------------------------------------------ 2: all or nothing


def test_atomic_outputs_put_back_what_they_replaced_when_a_rename_fails(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    a, b = tmp_path / "a.npz", tmp_path / "b.png"
    a.write_text("old a")
    b.write_text("old b")
    real = os.replace

    def replace(src, dst):
        if Path(dst) == b:
            raise PermissionError(errno.EPERM, os.strerror(errno.EPERM), str(src), str(dst))
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(GestureSimError, match=r"cannot replace .*b\.png.*nothing was replaced"):
        with fileio.atomic_outputs(a, b) as (ta, tb):
            ta.write_text("new a")
            tb.write_text("new b")
    assert (a.read_text(), b.read_text()) == ("old a", "old b")
    assert _entries(tmp_path) == ["a.npz", "b.png"]


def test_atomic_folder_publishes_every_file_together_or_none(tmp_path: Path) -> None:
    rep = tmp_path / "rep"
    (rep / "timelines").mkdir(parents=True)
    (rep / "report.json").write_text("old report")
    (rep / "timelines" / "x.png").write_text("old timeline")
    (rep / "mine.txt").write_text("not the report's")
    for exc in (KeyboardInterrupt, RuntimeError):
        with pytest.raises(exc), fileio.atomic_folder(rep) as stage:
            fileio.atomic_write_text(stage / "report.json", "new report")
            fileio.atomic_write_text(stage / "timelines" / "x.png", "new timeline")
            raise exc
        assert (rep / "report.json").read_text() == "old report"
        assert (rep / "timelines" / "x.png").read_text() == "old timeline"
        assert _entries(rep) == ["mine.txt", "report.json", "timelines", "timelines/x.png"]
    with fileio.atomic_folder(rep) as stage:
        fileio.atomic_write_text(stage / "report.json", "new report")
        fileio.atomic_write_text(stage / "timelines" / "x.png", "new timeline")
        fileio.atomic_write_text(stage / "timelines" / "y.png", "another")
    assert (rep / "report.json").read_text() == "new report"
    assert (rep / "timelines" / "x.png").read_text() == "new timeline"
    assert _entries(rep) == ["mine.txt", "report.json", "timelines", "timelines/x.png",
                             "timelines/y.png"]


def test_write_report_leaves_the_previous_report_when_a_figure_fails(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from gesture_sim.app import report

    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "report.json").write_text("old report")

    def files(result, folder, command="", timelines=True):
        fileio.atomic_write_text(Path(folder) / "report.json", "new report")
        with fileio.atomic_path(Path(folder) / "bars.png") as tmp:
            tmp.write_bytes(b"half a figure")
            _enospc()

    monkeypatch.setattr(report, "write_report_files", files)
    with pytest.raises(GestureSimError, match=r"cannot write .*rep/bars\.png: No space left"):
        report.write_report(None, rep)
    assert (rep / "report.json").read_text() == "old report"
    assert _entries(rep) == ["report.json"]


def _stub_evaluation(monkeypatch: pytest.MonkeyPatch, evaluate) -> None:
    from gesture_sim.app import evaluation as ev

    monkeypatch.setattr(ev, "Evaluator", lambda *a, **k: SimpleNamespace())
    monkeypatch.setattr(ev, "evaluate", evaluate)


def test_interrupted_eval_jobs_leave_the_previous_timelines(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """With --jobs the workers drew the timelines straight into DIR/timelines."""
    from gesture_sim.commands import eval as eval_cmd

    rep = tmp_path / "rep"
    (rep / "timelines").mkdir(parents=True)
    old = rep / "timelines" / f"{SPEECH.stem}_controller.png"
    old.write_bytes(b"my previous timeline")

    def draw(folder: Path, run) -> None:   # what a worker does, without the pipeline
        folder.mkdir(parents=True, exist_ok=True)
        fileio.atomic_write_text(folder / f"{SPEECH.stem}_controller.png", "new")

    def evaluate(*args, in_worker=None, **kwargs):
        assert in_worker is not None
        in_worker(None)
        raise KeyboardInterrupt   # Ctrl-C while the other runs go on

    monkeypatch.setattr(eval_cmd, "draw_timeline", draw)
    _stub_evaluation(monkeypatch, evaluate)
    status = cli.main(["eval", "motion", str(SPEECH), "--methods", "controller", "--seeds",
                       "1", "--jobs", "2", "--report", str(rep)])
    assert status == 130
    assert "interrupted" in capsys.readouterr().err
    assert old.read_bytes() == b"my previous timeline"
    assert _entries(rep) == ["timelines", f"timelines/{old.name}"]


def test_library_graph_keeps_the_previous_graph_when_the_plot_fails(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from gesture_sim.commands import mimic_graph
    from gesture_sim.control import inputs, mimic
    from gesture_sim.motion import library

    lib = tmp_path / "lib"
    lib.mkdir()
    graph_file, plot = tmp_path / "g.npz", tmp_path / "new" / "g.png"
    graph_file.write_bytes(b"my previous graph")
    graph = SimpleNamespace(save=lambda p: Path(p).write_bytes(b"new graph"), meta={})
    monkeypatch.setattr(library.MotionLibrary, "load", classmethod(lambda cls, f: None))
    monkeypatch.setattr(inputs.ControlLibrary, "from_motion_library",
                        classmethod(lambda cls, m: None))
    monkeypatch.setattr(mimic, "build_graph", lambda *a, **k: graph)

    def plot_graph(g, path) -> None:
        with fileio.atomic_path(path, suffix=".png") as tmp:
            tmp.write_bytes(b"half")
            _enospc()

    monkeypatch.setattr(mimic_graph, "plot_graph", plot_graph)
    status = cli.main(["library", "graph", str(lib), "-o", str(graph_file), "--plot",
                       str(plot)])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2
    assert f"cannot write {plot}: No space left on device" in line
    assert graph_file.read_bytes() == b"my previous graph"
    assert _entries(tmp_path) == ["g.npz", "lib"]   # no temporaries, no folder "new"


# ------------------------------------------------------------------ 3: report files first


def test_eval_report_checks_the_files_inside_before_the_work(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    rep = tmp_path / "rep"
    blocker = rep / "timelines" / f"{SPEECH.stem}_controller.png"
    blocker.mkdir(parents=True)
    (rep / "report.json").write_text("old report")

    def evaluate(*args, **kwargs):
        raise AssertionError("the evaluation started")

    from gesture_sim.app import evaluation as ev

    monkeypatch.setattr(ev, "Evaluator", evaluate)
    monkeypatch.setattr(ev, "evaluate", evaluate)
    status = cli.main(["eval", "motion", str(SPEECH), "--methods", "controller", "--seeds",
                       "1", "--report", str(rep)])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2
    assert str(blocker) in line and "is an existing folder" in line
    assert (rep / "report.json").read_text() == "old report"


def test_report_outputs_cover_repeated_stems(tmp_path: Path) -> None:
    from gesture_sim.commands.eval import report_outputs

    outs = report_outputs(tmp_path / "r", [Path("a/x.wav"), Path("b/x.wav")], ["controller",
                                                                                "real"], True)
    names = {Path(o.path).relative_to(tmp_path / "r").as_posix() for o in outs[1:]}
    assert {"report.json", "table.md", "bars.png", "velocity_hist.png", "timelines",
            "timelines/x_controller.png", "timelines/x_2_controller.png",
            "timelines/x_compare.png", "timelines/x_2_compare.png"} <= names


# ------------------------------------------------------------------ 9: a full disk


def test_a_full_disk_is_one_line_and_leaves_no_folder(tmp_path: Path) -> None:
    target = tmp_path / "new" / "sub" / "x.png"
    with pytest.raises(GestureSimError) as info, fileio.atomic_path(target) as tmp:
        tmp.write_bytes(b"half")
        _enospc()
    assert str(info.value) == f"cannot write {target}: No space left on device"
    assert _entries(tmp_path) == []
    # the same through atomic_outputs, the write nested in another atomic write (--bvh)
    a, b = tmp_path / "out" / "a.mp4", tmp_path / "out" / "m.bvh"
    with pytest.raises(GestureSimError) as info, fileio.atomic_outputs(a, b) as (ta, tb):
        ta.write_bytes(b"video")
        with fileio.atomic_path(tb) as inner:
            inner.write_bytes(b"half")
            raise OSError(errno.EDQUOT, os.strerror(errno.EDQUOT))
    assert str(info.value) == f"cannot write {b}: {os.strerror(errno.EDQUOT)}"
    assert _entries(tmp_path) == []


def test_a_refused_rename_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "x.png"

    def replace(src, dst):
        raise PermissionError(errno.EPERM, os.strerror(errno.EPERM), str(src), str(dst))

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(GestureSimError, match=r"cannot replace .*x\.png: Operation not perm"):
        with fileio.atomic_path(target) as tmp:
            tmp.write_bytes(b"figure")
    assert _entries(tmp_path) == []


def test_prosody_plot_on_a_full_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    import matplotlib.figure

    def savefig(self, fname, *args, **kwargs):
        Path(fname).write_bytes(b"\x89PNG half")
        _enospc()

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    plot = tmp_path / "new" / "sub" / "p.png"
    status = cli.main(["prosody", str(SPEECH), "--plot", str(plot)])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2
    assert line == f"gesture-sim: error: cannot write {plot}: No space left on device"
    assert _entries(tmp_path) == []


def test_library_subset_on_a_full_disk_leaves_no_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    monkeypatch.setattr(np, "savez_compressed", _enospc)
    out = tmp_path / "new" / "lib"
    status = cli.main(["library", "subset", str(ROOT / "motion_library" / "default"),
                       "--clips", "dataset-1_*", "-o", str(out)])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2
    assert "No space left on device" in line and str(out) in line
    assert _entries(tmp_path) == []


# ------------------------------------------------------------------ 10: renames the OS refuses


def test_outputs_where_no_file_can_be_created_are_refused_first() -> None:
    for path in ("/proc/gesture-sim-out.png", "/proc/self/new/x.png"):
        with pytest.raises(GestureSimError, match="cannot (create files in|write to) /proc"):
            v.check_outputs([v.Output("--plot", path, v.PNG_EXTENSIONS)])


def test_another_users_file_in_a_sticky_folder_is_refused_first(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sticky = tmp_path / "shared"
    sticky.mkdir()
    sticky.chmod(0o1777)
    (sticky / "x.png").write_bytes(b"theirs")
    (sticky / "x.png").chmod(0o666)
    me = os.geteuid() + 4242   # neither the file's owner nor the folder's
    monkeypatch.setattr(os, "geteuid", lambda: me)
    with pytest.raises(GestureSimError, match="another user in the sticky folder"):
        v.check_outputs([v.Output("--plot", sticky / "x.png", v.PNG_EXTENSIONS)])
    v.check_outputs([v.Output("--plot", sticky / "new.png", v.PNG_EXTENSIONS)])


@contextlib.contextmanager
def _immutable(path: Path):
    chattr = shutil.which("chattr")
    if chattr is None or subprocess.run([chattr, "+i", str(path)],
                                        capture_output=True).returncode:
        pytest.skip("chattr +i is not possible here")
    try:
        yield
    finally:
        subprocess.run([chattr, "-i", str(path)], check=True)


def test_an_immutable_output_is_refused_first(tmp_path: Path) -> None:
    f = tmp_path / "x.png"
    f.write_bytes(b"kept")
    with _immutable(f):
        with pytest.raises(GestureSimError, match=r"x\.png: is immutable"):
            v.check_outputs([v.Output("--plot", f, v.PNG_EXTENSIONS)])
        with pytest.raises(GestureSimError, match=r"cannot write to .*/d\b"):
            with _immutable_folder(tmp_path / "d") as d:
                v.check_outputs([v.Output("--plot", d / "y.png", v.PNG_EXTENSIONS)])


@contextlib.contextmanager
def _immutable_folder(d: Path):
    d.mkdir()
    with _immutable(d):
        yield d


def test_prosody_plot_into_proc_fails_before_the_analysis(
        capsys: pytest.CaptureFixture[str]) -> None:
    status = cli.main(["prosody", str(SPEECH), "--plot", "/proc/gesture-sim.png"])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2 and "/proc" in line


# ------------------------------------------------------------------ 11, 17: bad symlinks


def test_a_symlink_loop_as_output_is_one_line(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    la, lb = tmp_path / "la.png", tmp_path / "lb.png"
    lb.symlink_to(la.name)
    la.symlink_to(lb.name)
    with pytest.raises(GestureSimError, match="symbolic link loop"):
        v.check_outputs([v.Output("-o", la, v.PNG_EXTENSIONS)])
    with pytest.raises(GestureSimError, match="symbolic link loop"):
        v.check_outputs([v.Output("-o", la / "x.png", v.PNG_EXTENSIONS)])
    status = cli.main(["prosody", str(SPEECH), "--plot", str(la)])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2 and "symbolic link loop" in line
    assert la.is_symlink() and lb.is_symlink()


def test_a_dangling_symlink_in_an_output_path_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    link = tmp_path / "out.png"
    link.symlink_to(tmp_path / "nowhere" / "deep" / "x.png")
    folder_link = tmp_path / "d"
    folder_link.symlink_to(tmp_path / "gone")
    for path in (link, folder_link / "x.png", folder_link / "sub" / "x.png"):
        with pytest.raises(GestureSimError, match="broken symbolic link"):
            v.check_outputs([v.Output("--plot", path, v.PNG_EXTENSIONS)])
    status = cli.main(["prosody", str(SPEECH), "--plot", str(link)])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2 and "broken symbolic link" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "out.png"]  # nothing created


# ------------------------------------------------------------------ 24: permission bits


def test_a_replaced_output_keeps_its_permission_bits(tmp_path: Path) -> None:
    a, b = tmp_path / "a.json", tmp_path / "b.png"
    for p in (a, b):
        p.write_text("old")
        p.chmod(0o600)
    fileio.atomic_write_text(a, "new")
    with fileio.atomic_outputs(b) as (tb,):
        tb.write_text("new")
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "r.json").write_text("old")
    (rep / "r.json").chmod(0o640)
    with fileio.atomic_folder(rep) as stage:
        fileio.atomic_write_text(stage / "r.json", "new")
        fileio.atomic_write_text(stage / "fresh.json", "new")
    assert stat.S_IMODE(a.stat().st_mode) == 0o600
    assert stat.S_IMODE(b.stat().st_mode) == 0o600
    assert stat.S_IMODE((rep / "r.json").stat().st_mode) == 0o640
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((rep / "fresh.json").stat().st_mode) == 0o666 & ~umask
    assert a.read_text() == b.read_text() == (rep / "r.json").read_text() == "new"


def test_train_checks_the_model_files_before_the_work(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A folder where ``train -o DIR`` writes ``model.npz`` fails before any training."""
    from gesture_sim.inference import train as tr

    data = Path(__file__).resolve().parent / "data"
    pair = [str(data / "motion" / "2_scott_0_1_1_first10s.npz"),
            str(data / "eval" / "2_scott_0_1_1_first10s.wav")]

    def train_model(*args, **kwargs):
        raise AssertionError("the training started")

    monkeypatch.setattr(tr, "train_model", train_model)
    blocker = tmp_path / "model" / "model.npz"
    blocker.mkdir(parents=True)
    status = cli.main(["train", "--pair", *pair, "-o", str(tmp_path / "model")])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2
    assert str(blocker) in line and "is an existing folder" in line


def test_a_render_that_fails_before_writing_leaves_no_folder(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """No speech in the file: the render fails after the pipeline ran; the output folders it
    would have written into are not left behind."""
    import numpy as np
    from scipy.io import wavfile

    wav = tmp_path / "hiss.wav"   # room hiss at -50 dBFS: audio, but no speech
    hiss = np.random.default_rng(0).standard_normal(32000) * 10 ** (-50 / 20) * 32767
    wavfile.write(wav, 16000, hiss.astype(np.int16))
    status = cli.main(["render", str(wav), "-o", str(tmp_path / "new" / "v.mp4"),
                       "--timeline", str(tmp_path / "new2" / "t.png"), "--width", "160",
                       "--height", "90", "--quality", "fast", "--no-keywords"])
    line = _one_error_line(capsys.readouterr().err)
    assert status == 2 and "no speech" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hiss.wav"]
