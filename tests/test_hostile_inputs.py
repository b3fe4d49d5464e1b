"""Hostile inputs get one clear line on stderr, exit status 2 and no traceback.

Each test reproduces one finding of a hostile-input sweep (the number in its docstring) with
the cheapest input that triggers it; most fail before any pipeline work.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from gesture_sim import cli
from gesture_sim.errors import GestureSimError

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
SPEECH = DATA / "audio" / "arctic_a0007.wav"         # 4 s of read speech, mono 16 kHz
SMPLX = DATA / "motion" / "2_scott_0_1_1_first10s.npz"  # 10 s of SMPL-X motion
BVH = DATA / "motion" / "dataset-1_bow_active_001.bvh"  # 4.3 s
LONG_SPEECH = DATA / "inference" / "beat2_scott_0_3_3_first20s.wav"
TEXTGRID = DATA / "textgrids" / "2_scott_0_1_1.TextGrid"  # 64 s of aligned words
LIBRARY = ROOT / "motion_library" / "default"
RO = ["--width", "320", "--height", "180", "--quality", "fast"]


def fails_cleanly(capsys: pytest.CaptureFixture[str], argv: list[str], *needles: str) -> str:
    """Run the CLI in-process; assert exit 2 and one ``gesture-sim...: error:`` line on stderr
    holding every needle; return that line."""
    capsys.readouterr()
    try:
        status = cli.main([str(a) for a in argv])
    except SystemExit as exc:   # a usage error of the argument parser
        status = exc.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert status == 2, (status, err[-2000:])
    assert len(lines) == 1, err[-2000:]
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# ------------------------------------------------------------------------------------ 13


def test_damaged_fgd_extractor_names_the_file_and_the_remedy(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """13: a truncated ``fgd_extractor.npz`` in a library was a BadZipFile traceback."""
    lib = tmp_path / "lib"
    shutil.copytree(LIBRARY, lib)
    extractor = lib / "fgd_extractor.npz"
    extractor.write_bytes(extractor.read_bytes()[:3000])
    line = fails_cleanly(capsys, ["eval", "motion", SPEECH, "--library", lib, "--no-physics",
                                  "--methods", "controller", "--seeds", "1"],
                         str(extractor), "damaged FGD feature extractor",
                         "fit_fgd_extractor.py")
    assert "delete it" in line


# ------------------------------------------------------------------------------------ 14


def _smplx_with_rate(path: Path, rate: object) -> Path:
    with np.load(SMPLX) as d:
        arrays = {k: d[k] for k in d.files}
    arrays["mocap_frame_rate"] = np.asarray(rate)
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize("rate, holds", [("thirty", "text 'thirty'"),
                                         ([30.0, 60.0], "shape (2,)")])
def test_smplx_frame_rate_that_is_not_one_number_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], rate: object, holds: str) -> None:
    """14: a text or multi-element ``mocap_frame_rate`` was a ValueError/TypeError traceback."""
    path = _smplx_with_rate(tmp_path / "take.npz", rate)
    fails_cleanly(capsys, ["library", "build", path, "-o", tmp_path / "lib"],
                  str(path), "'mocap_frame_rate' must be one number", holds)


def test_smplx_frame_rate_of_one_element_is_its_value(tmp_path: Path) -> None:
    """14: a one-element array is taken as the frame rate it holds."""
    from gesture_sim.motion.smplx import read_smplx

    motion = read_smplx(_smplx_with_rate(tmp_path / "take.npz", [30.0]))
    assert motion.fps == 30.0


# ------------------------------------------------------------------------------------ 15


def _chain_bvh(path: Path, n_joints: int, n_frames: int) -> Path:
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for i in range(1, n_joints):
        lines += [f"JOINT j{i}", "{", "OFFSET 0 0.1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 0.1 0", "}"] + ["}"] * n_joints
    row = " ".join(["0"] * (6 + 3 * (n_joints - 1)))
    lines += ["MOTION", f"Frames: {n_frames}", "Frame Time: 0.0333333"] + [row] * n_frames
    path.write_text("\n".join(lines) + "\n")
    return path


def test_bvh_with_a_3000_joint_chain_parses(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """15: a 3000-joint chain was a RecursionError traceback; the parser is iterative now."""
    from gesture_sim.motion.bvh import read_bvh

    path = _chain_bvh(tmp_path / "chain.bvh", 3000, 40)
    motion = read_bvh(path)
    assert len(motion.names) == 3001 and motion.names[-1] == "j2999_End"
    assert list(motion.parents[:4]) == [-1, 0, 1, 2]
    # the command then refuses the skeleton for what it is, in one line
    fails_cleanly(capsys, ["library", "build", path, "-o", tmp_path / "lib"], str(path),
                  "unknown skeleton")


# ------------------------------------------------------------------------------------ 16


def test_invalid_mujoco_gl_says_which_values_work(tmp_path: Path) -> None:
    """16: ``MUJOCO_GL=nonsense`` was mujoco's RuntimeError traceback (a fresh process: the
    variable is read when mujoco is first imported)."""
    env = {**os.environ, "MUJOCO_GL": "nonsense",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(
        [sys.executable, "-c", "import sys; from gesture_sim.cli import main; "
         "sys.exit(main(['bench', 'physics', '--duration', '0.1', '--json']))"],
        env=env, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "MUJOCO_GL='nonsense'" in lines[0]
    for value in ("egl", "osmesa", "glfw"):
        assert value in lines[0]


# ------------------------------------------------------------------------------------ 19


def test_transcript_words_after_the_end_are_refused(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """19: words at 100 s of a 4 s recording were accepted silently."""
    tr = tmp_path / "words.txt"
    tr.write_text("0.5 0.9 hello\n100.0 100.4 wave\n")
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", *RO, "--transcript", tr],
                  str(tr), "word 'wave' at 100 s", "after the audio ends")
    assert not (tmp_path / "o.mp4").exists()


def test_signals_after_the_end_are_refused(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """19: a ``--signals`` label at 999 s of a 4 s recording was accepted silently."""
    sig = tmp_path / "signals.txt"
    sig.write_text("1.0 nod\n999 nod\n")
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", *RO, "--signals", sig],
                  str(sig), "at 999 s", "after the audio ends")


def test_eval_textgrid_of_another_recording_is_refused(
        capsys: pytest.CaptureFixture[str]) -> None:
    """19: a TextGrid of a 64 s take scored against a 4 s file was accepted silently."""
    fails_cleanly(capsys, ["eval", "motion", SPEECH, "--textgrid", TEXTGRID, "--no-physics",
                           "--methods", "controller", "--seeds", "1"],
                  str(TEXTGRID), "after the audio ends")


def test_eval_reference_of_another_length_is_refused(
        capsys: pytest.CaptureFixture[str]) -> None:
    """19: a 10 s reference motion for a 4 s file was accepted silently."""
    fails_cleanly(capsys, ["eval", "motion", SPEECH, "--reference", SMPLX, "--no-physics",
                           "--methods", "real", "--seeds", "1"],
                  str(SMPLX), "lasts 10.0 s", "same take")


def test_reference_and_textgrid_times_of_the_same_take_pass(tmp_path: Path) -> None:
    """19: the checks leave a take's own motion and alignment alone."""
    from gesture_sim.audio.textgrid import read_textgrid
    from gesture_sim.metrics.inputs import check_reference_length, check_textgrid_times

    check_reference_length(SMPLX, "take.wav", 10.0)
    check_reference_length(SMPLX, "take.wav", 10.9)       # within 1 s
    check_textgrid_times(read_textgrid(TEXTGRID), TEXTGRID, 64.1)
    with pytest.raises(GestureSimError, match="lasts 10.0 s"):
        check_reference_length(SMPLX, "take.wav", 12.0)


# ------------------------------------------------------------------------------------ 20


def test_eval_real_without_reference_is_a_usage_error(
        capsys: pytest.CaptureFixture[str]) -> None:
    """20: ``--methods real`` without ``--reference`` exited 0 with "0 runs"."""
    fails_cleanly(capsys, ["eval", "motion", SPEECH, "--no-physics", "--methods", "real",
                           "--seeds", "1"], "--reference")


def test_eval_mismatched_with_one_file_is_a_usage_error(
        capsys: pytest.CaptureFixture[str]) -> None:
    """20: ``--methods mismatched`` with a single file was scored anyway."""
    fails_cleanly(capsys, ["eval", "motion", SPEECH, "--no-physics", "--methods",
                           "mismatched", "--seeds", "1"], "mismatched")


# ------------------------------------------------------------------------------------ 21


def test_two_with_rttm_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """21: ``--two --rttm`` silently ignored ``--two``."""
    rttm = tmp_path / "turns.rttm"
    rttm.write_text("SPEAKER f 1 0.0 1.0 <NA> <NA> A <NA> <NA>\n")
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", *RO, "--two",
                           "--rttm", rttm], "--two and --rttm")


def test_keyword_table_with_a_label_the_library_lacks_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """21: a ``--keywords`` table asking for a label the library lacks was accepted silently
    (while ``--label`` of that label is refused)."""
    table = tmp_path / "table.txt"
    table.write_text("wave hello\nflap goodbye\n")
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", *RO, "--keywords",
                           table], str(table), "flap", "lacks")
    assert not (tmp_path / "o.mp4").exists()


def test_shipped_keyword_table_with_labels_the_library_lacks_warns(
        capsys: pytest.CaptureFixture[str]) -> None:
    """21: for the shipped table (not given by the user) one warning line, and no error."""
    from gesture_sim.audio.keywords import KeywordTable, check_keyword_labels

    table = KeywordTable.load(None)
    labels = ("wave", "bow")
    missing = check_keyword_labels(table, labels, explicit=False)
    err = capsys.readouterr().err
    assert missing and "wave" not in missing
    assert err.count("\n") == 1 and err.startswith("gesture-sim: warning: the shipped keyword")
    assert check_keyword_labels(table, sorted({e.label for e in table.entries}),
                                explicit=True) == []


# ------------------------------------------------------------------------------------ 22


def _wav_bytes() -> bytes:
    return SPEECH.read_bytes()


def test_wav_chunk_past_the_end_is_said_so(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """22: a chunk running past the end of the file gave "cannot access local variable
    'data'"."""
    raw = _wav_bytes()
    fmt_end = 20 + struct.unpack("<I", raw[16:20])[0]
    path = tmp_path / "cut.wav"
    path.write_bytes(raw[:fmt_end] + b"LIST" + struct.pack("<I", 10**6) + b"abcd")
    line = fails_cleanly(capsys, ["prosody", path, "--json"], str(path), "'LIST' chunk",
                         "past the end")
    assert "local variable" not in line


def test_wav_with_zero_channels_is_said_so(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """22: a 0-channel WAV gave "integer division or modulo by zero"."""
    raw = bytearray(_wav_bytes())
    raw[22:24] = struct.pack("<H", 0)
    path = tmp_path / "none.wav"
    path.write_bytes(bytes(raw))
    line = fails_cleanly(capsys, ["prosody", path, "--json"], str(path), "0 channels")
    assert "division" not in line


def test_eval_inference_pair_of_bvh_and_long_speech_names_the_mismatch(
        capsys: pytest.CaptureFixture[str]) -> None:
    """22: a 4 s BVH paired with 20 s of speech said "fewer than 20 syllables"."""
    fails_cleanly(capsys, ["eval", "inference", "--pair", BVH, LONG_SPEECH, "--windows", "1"],
                  "the motion lasts 4.3 s but the speech 20.0 s")


def test_rttm_onset_of_300_digits_is_shortened(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """22: a 300-digit RTTM onset was echoed back in full."""
    for digits in ("1" * 300, "9" * 400):     # finite (after the end), and overflowing to inf
        rttm = tmp_path / "turns.rttm"
        rttm.write_text(f"SPEAKER f 1 {digits} 1.0 <NA> <NA> A <NA> <NA>\n")
        line = fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", *RO,
                                      "--rttm", rttm], str(rttm))
        assert len(line) < 300, line


def test_label_at_the_very_end_is_accepted() -> None:
    """22: ``--label`` at the end, as the message printed it, was refused with "from 0 to
    5.63444 ..., got 5.63444"; the end (to the 1/100 s shown) is accepted now and a time past
    it is refused with a bound that reads right."""
    from gesture_sim.app.render import check_label_times

    duration = 5.634437
    assert check_label_times([(5.63444, "wave"), (5.64, "bow")], duration) == (
        (duration, "wave"), (duration, "bow"))
    with pytest.raises(GestureSimError) as info:
        check_label_times([(5.65, "wave")], duration)
    assert "from 0 to 5.64" in str(info.value) and "got 5.65" in str(info.value)


def test_bad_tags_file_is_reported_under_its_own_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """22: a bad ``--tags`` file was reported under the BVH's path."""
    tags = tmp_path / "tags.json"
    tags.write_text("{not json")
    line = fails_cleanly(capsys, ["library", "build", BVH, "--tags", tags, "-o",
                                  tmp_path / "lib"], str(tags))
    assert str(BVH) not in line


@pytest.mark.parametrize("argv", [
    ["render", SPEECH, "-o", "", *RO],
    ["library", "build", BVH, "-o", ""],
    ["eval", "motion", SPEECH, "--report", ""],
])
def test_empty_output_path_is_called_empty(argv: list, capsys: pytest.CaptureFixture[str]
                                           ) -> None:
    """22: ``-o ''`` said "'.' is not a file name"."""
    line = fails_cleanly(capsys, argv, "empty path")
    assert "'.'" not in line


# ------------------------------------------------------------------------------------ 23


def test_cjk_file_name_draws_without_glyph_warnings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """23: a CJK audio file name made matplotlib warn once per missing glyph and draw."""
    audio = tmp_path / "日本語の音声.wav"
    shutil.copy(SPEECH, audio)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert cli.main(["prosody", str(audio), "--plot", str(tmp_path / "p.png"),
                         "--json"]) == 0
    captured = capsys.readouterr()
    assert not [w for w in caught if "Glyph" in str(w.message)]
    assert "Glyph" not in captured.err
    assert (tmp_path / "p.png").stat().st_size > 0


def test_drawable_replaces_only_what_the_fonts_lack() -> None:
    """23: figure titles keep what the default fonts draw and replace what they cannot."""
    from gesture_sim.audio.plot import drawable

    assert drawable("take_01.wav — controller") == "take_01.wav — controller"
    assert drawable("café") == "café"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        title = drawable("日本語.wav — controller")
    assert title.endswith(".wav — controller") and "日" not in title
    assert not caught
