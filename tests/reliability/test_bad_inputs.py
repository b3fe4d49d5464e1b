"""Bad inputs of the newer commands and options get one line, exit status 2, before any work.

Each case reproduces one finding of the hostile-input sweep of issue 49 (a wrong or damaged
sign model, an export that would need terabytes, duplicate skeleton joints, side files whose
times lie outside the audio, contradictory options, unreadable telephony WAVs, raw messages)
with the cheapest input that triggers it. Every case fails before the pipeline is built, so the
file runs in seconds.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gesture_sim import cli

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
SPEECH = DATA / "audio" / "arctic_a0007.wav"         # 4 s of read speech, mono 16 kHz
SMPLX = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
BVH = DATA / "motion" / "dataset-1_bow_active_001.bvh"  # 4.3 s
TEXTGRID = DATA / "textgrids" / "2_scott_0_1_1.TextGrid"  # 64 s of aligned words
LIBRARY = ROOT / "motion_library" / "default"
SIGNS = LIBRARY / "model"
RO = ["--width", "320", "--height", "180", "--quality", "fast"]


def fails_cleanly(capsys: pytest.CaptureFixture[str], argv: list, *needles: str) -> str:
    """Run the CLI in-process; assert exit 2 and exactly one ``error:`` line on stderr (no
    traceback, no warning lines) holding every needle; return that line."""
    capsys.readouterr()
    try:
        status = cli.main([str(a) for a in argv])
    except SystemExit as exc:   # a usage error of the argument parser
        status = exc.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert status == 2, (status, err[-2000:])
    assert len(lines) == 1, err[-2000:]
    assert "Traceback" not in err and "Warning" not in err, err[-2000:]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# ------------------------------------------------------------------ 1. a wrong --sign-model


def _sign_model(tmp_path: Path, case: str) -> Path:
    d = tmp_path / "signs"
    if case == "library":
        return LIBRARY
    d.mkdir()
    npz, js = SIGNS / "signs.npz", SIGNS / "signs.json"
    if case == "empty":
        return d
    if case in ("only_json", "bad_json", "json_list", "format_99", "truncated_npz",
                "no_inventory"):
        shutil.copy(js, d / "signs.json")
    if case in ("only_npz", "bad_json", "json_list", "format_99", "no_inventory"):
        shutil.copy(npz, d / "signs.npz")
    if case == "truncated_npz":
        (d / "signs.npz").write_bytes(npz.read_bytes()[:2000])
    if case == "bad_json":
        (d / "signs.json").write_text('{"format": "1.0", "signs": [', encoding="utf-8")
    if case == "json_list":
        (d / "signs.json").write_text("[1, 2, 3]", encoding="utf-8")
    if case in ("format_99", "no_inventory"):
        meta = json.loads(js.read_text(encoding="utf-8"))
        if case == "format_99":
            meta["format"] = "99.0"
        else:
            del meta["dcnf"]
        (d / "signs.json").write_text(json.dumps(meta), encoding="utf-8")
    return d


@pytest.mark.parametrize("case, needle", [
    ("empty", "signs.npz and signs.json missing"),
    ("only_json", "signs.npz missing"),
    ("only_npz", "signs.json missing"),
    ("truncated_npz", "signs.npz: damaged sign model (truncated"),
    ("bad_json", "signs.json: damaged sign model settings (invalid JSON"),
    ("json_list", "a JSON list, not an object"),
    ("format_99", "format '99.0'"),
    ("no_inventory", "missing entry 'dcnf'"),
    ("library", "motion library"),
])
def test_a_wrong_sign_model_folder_is_one_line_before_any_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, needle: str) -> None:
    folder = _sign_model(tmp_path, case)
    out = tmp_path / "out.mp4"
    fails_cleanly(capsys, ["render", SPEECH, "-o", out, "--method", "chiu14", "--sign-model",
                           folder, *RO], "--sign-model", str(folder), needle)
    assert not out.exists()


@pytest.mark.parametrize("method", ["random", "levine09"])
def test_a_gpdm_transition_for_a_method_with_its_own_timing_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], method: str) -> None:
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", "--method", method,
                           "--transition", "gpdm", *RO],
                  "--transition gpdm", f"--method {method} has its own timing", "controller")


def test_a_sign_model_for_a_method_without_signs_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", "--method", "random",
                           "--sign-model", SIGNS, *RO], "--sign-model", "chiu14")


# ------------------------------------------------------------------ 2. export's size, names


def _motion_npz(path: Path, time_s: list[float], nq: int = 10) -> Path:
    np.savez(path, format=np.array("gesture_sim.motion_npz"), version=np.array(1),
             time=np.asarray(time_s, dtype=float), qpos=np.zeros((len(time_s), nq)))
    return path


def test_export_of_a_motion_spanning_a_million_seconds_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two rows 1e6 s apart were resampled to 3e7 frames (a 25 GiB MemoryError)."""
    motion = _motion_npz(tmp_path / "m.npz", [0.0, 1e6])
    out = tmp_path / "o.bvh"
    fails_cleanly(capsys, ["export", motion, "--format", "bvh", "-o", out],
                  str(motion), "span 1e+06 s", "1,000,000")
    assert not out.exists()


def test_export_of_an_smplx_npz_says_what_the_file_is(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """numpy's ``'format is not a file in the archive'`` was all it said."""
    fails_cleanly(capsys, ["export", SMPLX, "--format", "bvh", "-o", tmp_path / "o.bvh"],
                  str(SMPLX), "an SMPL-X", "render --npz", "what export reads")


@pytest.mark.parametrize("argv", [
    ["export", SMPLX, "--format", "bvh", "-o"],
    ["render", SPEECH, *RO, "-o"],
    ["render", SPEECH, *RO, "-o", "/tmp/x.mp4", "--timeline"],
], ids=["export", "render", "render-timeline"])
def test_an_output_name_over_255_bytes_is_refused_up_front(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list) -> None:
    """``File name too long`` came at the first write, after the work."""
    name = "n" * 300 + (".png" if argv[-1] == "--timeline" else
                        ".bvh" if argv[0] == "export" else ".mp4")
    argv = [*argv, tmp_path / name]
    if argv[-2] == "--timeline":
        argv[argv.index("/tmp/x.mp4")] = tmp_path / "x.mp4"
    fails_cleanly(capsys, argv, "304 bytes", "over the 255")


# ------------------------------------------------------------------ 7. G.711 telephony WAVs


@pytest.mark.skipif(shutil.which("sox") is None, reason="needs sox")
@pytest.mark.parametrize("encoding", ["a-law", "u-law"])
def test_alaw_and_mulaw_wavs_are_read(tmp_path: Path, encoding: str) -> None:
    """Valid telephony WAVs were refused as "broken header". Known answer: sox writes a 440 Hz
    tone at half scale as G.711; the samples read equal sox's own decoding to 16-bit PCM, and
    the tone (sox without dither) within G.711's quantisation."""
    import subprocess

    from scipy.io import wavfile

    from gesture_sim.audio.sources import load_audio, read_wav_checked

    g711, pcm = tmp_path / "tone.wav", tmp_path / "pcm.wav"
    subprocess.run(["sox", "-D", "-n", "-r", "8000", "-c", "1", "-e", encoding, str(g711),
                    "synth", "0.5", "sine", "440", "vol", "0.5"], check=True)
    subprocess.run(["sox", str(g711), "-e", "signed", "-b", "16", str(pcm)], check=True)
    x, rate, fmt = read_wav_checked(g711)
    assert rate == 8000 and fmt == ("alaw" if encoding == "a-law" else "mulaw")
    _, ref = wavfile.read(pcm)
    np.testing.assert_array_equal(x, ref.astype(np.float32) / 32768)
    tone = 0.5 * np.sin(2 * np.pi * 440 * np.arange(len(x)) / 8000)
    # half of G.711's top step (1024 / 32768); sox's synth starts at 0.018, not 0: skipped
    assert np.max(np.abs(x - tone)[1:]) < 1 / 60
    y, info = load_audio(g711)       # and through the one reader every command uses
    assert info.source_rate == 8000 and abs(info.duration_s - 0.5) < 1e-3
    assert abs(float(np.sqrt(np.mean(y[400:-400] ** 2))) - 0.5 / np.sqrt(2)) < 0.01


def test_a_wav_header_of_four_gigahertz_is_a_damaged_header(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 4e9 Hz rate was resampled to nothing and reported as silence."""
    import struct

    raw = bytearray(SPEECH.read_bytes())
    raw[24:28] = struct.pack("<I", 4_000_000_000)
    bad = tmp_path / "rate.wav"
    bad.write_bytes(bytes(raw))
    fails_cleanly(capsys, ["prosody", bad], str(bad), "4,000,000,000 samples per second",
                  "damaged header")


# ------------------------------------------------------------------ 9. stale help


def test_train_help_points_at_render_sign_model(capsys: pytest.CaptureFixture[str]) -> None:
    """``train --help`` said render had no option for a trained sign model."""
    with pytest.raises(SystemExit):
        cli.main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--sign-model my_signs" in text
    assert "no option for it" not in text


@pytest.mark.parametrize("command", ["render", "export"])
def test_help_does_not_send_bvh_to_unity_or_unreal(
        capsys: pytest.CaptureFixture[str], command: str) -> None:
    """Unity and Unreal import no BVH; the help said they map the Mixamo BVH."""
    with pytest.raises(SystemExit):
        cli.main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Unity and Unreal import no BVH" in text
    assert "Blender, Unity and Unreal map" not in text and "Blender, Unity, Unreal" not in text


# ------------------------------------------------------ 6. methods that serve no labels


@pytest.mark.parametrize("method", ["random", "levine09", "chiu14"])
def test_a_method_without_labels_says_so_not_that_the_library_has_none(
        capsys: pytest.CaptureFixture[str], method: str) -> None:
    """The shipped library has nine labels; these methods serve none. The warning said the
    library "has: none"."""
    from gesture_sim.audio.keywords import KeywordTable, check_keyword_labels
    from gesture_sim.methods import no_labels_note
    from gesture_sim.motion.library import MotionLibrary

    library = MotionLibrary.load(LIBRARY)
    check_keyword_labels(KeywordTable.load(None), (), explicit=False,
                         none=no_labels_note(method, library))
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "warning:" in err
    assert f"--method {method} serves no semantic labels" in err
    assert "this library has 9: beckon, bow" in err and "controller, dcnf, mimic" in err
    assert "has: none" not in err


def test_a_label_for_random_names_the_method(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", "--method", "random",
                           "--label", "1.0:wave", "--no-keywords", *RO],
                  "unknown semantic label(s) wave", "--method random serves no semantic labels")


# ------------------------------------------------------------------ 4. side files' times

TEN_S = DATA / "eval" / "2_scott_0_1_1_first10s.wav"   # 10 s of BEAT2 speech


def test_train_corpus_refuses_a_textgrid_of_another_length(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 64 s TextGrid beside 10 s of audio passed without a word."""
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    shutil.copy(SMPLX, corpus / "take.npz")
    shutil.copy(TEN_S, corpus / "take.wav")
    shutil.copy(TEXTGRID, corpus / "take.TextGrid")
    out = tmp_path / "lib"
    fails_cleanly(capsys, ["train", "--corpus", corpus, "-o", out],
                  str(corpus / "take.TextGrid"),
                  "'words' interval 'better' at 61.89 s (to 62.42 s)",
                  "after its audio take.wav ends (10.000 s", "by 0.5 s at most")
    assert not (out / "library.npz").exists()


def _signs_take(folder: Path, samples: np.ndarray | None = None,
                grid: Path | None = None, spans: str = "0.0,2.0,Beats\n") -> Path:
    from scipy.io import wavfile

    folder.mkdir()
    if samples is None:
        shutil.copy(TEN_S, folder / "take.wav")
    else:
        wavfile.write(folder / "take.wav", 16000, samples)
    shutil.copy(grid or TEXTGRID, folder / "take.TextGrid")
    (folder / "take.signs.csv").write_text("start,end,sign\n" + spans, encoding="utf-8")
    return folder


def _short_grid(path: Path, end_s: float = 9.0) -> Path:
    path.write_text(
        'File type = "ooTextFile"\nObject class = "TextGrid"\n\nxmin = 0\nxmax = 10\n'
        'tiers? <exists>\nsize = 1\nitem []:\n    item [1]:\n        class = "IntervalTier"\n'
        '        name = "words"\n        xmin = 0\n        xmax = 10\n'
        '        intervals: size = 2\n        intervals [1]:\n            xmin = 0\n'
        f'            xmax = 1\n            text = "hello"\n        intervals [2]:\n'
        f'            xmin = 1\n            xmax = {end_s}\n            text = "there"\n',
        encoding="utf-8")
    return path


@pytest.mark.parametrize("case, needles", [
    ("long_grid", ("take.TextGrid", "word 'better' at 61.89 s",
                   "after the audio take.wav ends (10.000 s")),
    ("late_spans", ("take.signs.csv", "sign 'Beats' at 100 s (to 200 s)",
                    "after the audio take.wav ends")),
    ("silence", ("take.wav", "silent (peak -240 dBFS)", "no speech to learn")),
])
def test_train_signs_refuses_side_files_past_the_audio_and_silence(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str,
        needles: tuple[str, ...]) -> None:
    """A 64 s TextGrid beside 10 s of audio passed; so did 10 s of digital silence (which
    render refuses)."""
    grid = None if case == "long_grid" else _short_grid(tmp_path / "short.TextGrid")
    spans = "100.0,200.0,Beats\n" if case == "late_spans" else "0.0,2.0,Beats\n"
    samples = np.zeros(160000, np.int16) if case == "silence" else None
    takes = _signs_take(tmp_path / "takes", samples, grid, spans)
    fails_cleanly(capsys, ["train", "--signs", takes, "-o", tmp_path / "m"], *needles)
    assert not (tmp_path / "m").exists()


# ------------------------------------------------------------------ 5. contradictory options


def test_a_garbage_physics_worker_variable_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``GESTURE_SIM_PHYSICS_WORKER=garbage`` meant "off" without a word."""
    monkeypatch.setenv("GESTURE_SIM_PHYSICS_WORKER", "garbage")
    fails_cleanly(capsys, ["render", SPEECH, "-o", tmp_path / "o.mp4", *RO],
                  "GESTURE_SIM_PHYSICS_WORKER='garbage'", "process, thread, off")
    for ok in ("thread", " OFF ", ""):
        monkeypatch.setenv("GESTURE_SIM_PHYSICS_WORKER", ok)
        from gesture_sim.validation import physics_worker_env

        assert physics_worker_env() == (ok.strip().lower() or None)


def test_live_no_words_without_a_method_that_hears_words_is_refused(
        capsys: pytest.CaptureFixture[str]) -> None:
    fails_cleanly(capsys, ["live", "--audio", SPEECH, "--no-words", "--duration", "1"],
                  "--no-words", "only --method chiu14", "--method controller hears none")


def _grid(path: Path, tiers: dict[str, list[tuple[float, float, str]]], xmax: float = 4.0
          ) -> Path:
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0",
             f"xmax = {xmax}", "tiers? <exists>", f"size = {len(tiers)}", "item []:"]
    for k, (name, items) in enumerate(tiers.items(), start=1):
        lines += [f"    item [{k}]:", '        class = "IntervalTier"',
                  f'        name = "{name}"', "        xmin = 0", f"        xmax = {xmax}",
                  f"        intervals: size = {len(items)}"]
        for j, (a, b, t) in enumerate(items, start=1):
            lines += [f"        intervals [{j}]:", f"            xmin = {a}",
                      f"            xmax = {b}", f'            text = "{t}"']
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("case, needles", [
    ("negative", ("'phones' interval 'HH'", "at -2 s starts before the audio")),
    ("empty_tiers", ("no labelled interval in any tier", "tiers: 'words', 'phones'")),
    ("two_grids", ("2 TextGrid files", "for the one audio file arctic_a0007.wav",
                   "give one --textgrid per audio file")),
])
def test_eval_textgrid_with_impossible_times_or_no_stress_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str,
        needles: tuple[str, ...]) -> None:
    """Negative times or empty tiers made the stress figures "–" without a word; two
    TextGrids for one audio "matched no audio file by name"."""
    words = [(0.5, 1.0, "hello"), (1.0, 1.6, "world")]
    phones = [(-2.0, 0.6, "HH"), (0.6, 1.0, "AH1")] if case == "negative" else \
        [(0.5, 0.6, "HH"), (0.6, 1.0, "AH1")]
    tiers = {"words": words, "phones": phones}
    if case == "empty_tiers":
        tiers = {"words": [], "phones": []}
    grid = _grid(tmp_path / "arctic_a0007.TextGrid", tiers)
    extra = ["--textgrid", _grid(tmp_path / "other.TextGrid", {"words": words,
                                                               "phones": phones})] \
        if case == "two_grids" else []
    fails_cleanly(capsys, ["eval", "motion", SPEECH, "--textgrid", grid, *extra,
                           "--no-physics", "--methods", "controller", "--seeds", "1"], *needles)


@pytest.mark.parametrize("case", ["no_phones", "unstressed"])
def test_eval_textgrid_without_stressed_vowels_warns_once_before_the_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        case: str) -> None:
    """A words-only TextGrid still gives chiu14 its words, but the stress figures would be "–"
    without a word: one warning line, before the stack loads."""
    import gesture_sim.app.evaluation as ev

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    monkeypatch.setattr(ev, "Evaluator", stop)
    words = [(0.5, 1.0, "hello"), (1.0, 1.6, "world")]
    tiers = {"words": words} if case == "no_phones" else \
        {"words": words, "phones": [(0.5, 0.6, "HH"), (0.6, 1.0, "AH0")]}
    grid = _grid(tmp_path / "arctic_a0007.TextGrid", tiers)
    capsys.readouterr()
    with pytest.raises(Stop):
        cli.main(["eval", "motion", str(SPEECH), "--textgrid", str(grid), "--no-physics",
                  "--methods", "controller", "--seeds", "1"])
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"gesture-sim: warning: --textgrid {grid}: ")
    assert ("no 'phones' tier" if case == "no_phones" else "no stressed vowel") in err
    assert "stay '–'" in err and "its words are still used" in err


def test_an_rttm_turn_far_past_the_audio_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A turn ending 98 s after a 4 s audio, of another recording, passed (it was cut)."""
    rttm = tmp_path / "talk.rttm"
    rttm.write_text("SPEAKER other_take 1 0.5 1.0 <NA> <NA> A <NA> <NA>\n"
                    "SPEAKER other_take 1 1.8 100.2 <NA> <NA> B <NA> <NA>\n", encoding="utf-8")
    fails_cleanly(capsys, ["render", SPEECH, "--rttm", rttm, "-o", tmp_path / "o.mp4", *RO],
                  str(rttm), "turn of person 1 at 1.8 s (to 102 s)", "after the audio ends",
                  "recording 'other_take'")


def test_library_build_signs_past_the_clip_are_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Sign spans at 100-200 s of a 4.3 s clip passed (and labelled nothing)."""
    csv = tmp_path / "signs.csv"
    csv.write_text(f"clip,start_s,end_s,sign\n{BVH.stem},0.5,1.5,Beats\n"
                   f"{BVH.stem},100,200,Beats\n", encoding="utf-8")
    out = tmp_path / "lib"
    fails_cleanly(capsys, ["library", "build", BVH, "-o", out, "--signs", csv],
                  f"{csv}:3", "the Beats span at 100 s (to 200 s)", f"the clip {BVH.stem} ends")
    assert not out.exists()


# ------------------------------------------------------ 3. --to-skeleton, duplicate joints


def _bvh_with(tmp_path: Path, case: str) -> Path:
    text = BVH.read_text(encoding="utf-8")
    if case == "duplicate":
        text = text.replace("JOINT Spine\n", "JOINT Hips\n", 1)
    elif case == "nan":
        text = text.replace("OFFSET 15.7357 0 0", "OFFSET nan 0 inf", 1)
    path = tmp_path / f"{case}.bvh"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("case, needle", [
    ("duplicate", "two joints are named 'Hips' (lines 6 and 10)"),
    ("nan", "has the OFFSET nan 0 inf; offsets must be finite"),
])
def test_a_skeleton_the_exporter_cannot_take_is_refused_before_the_render(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, needle: str) -> None:
    """Duplicate joint names failed after the whole render, naming neither the file nor the
    option; NaN offsets said "cannot detect BVH units" without the file."""
    skeleton = _bvh_with(tmp_path, case)
    out = tmp_path / "o.mp4"
    fails_cleanly(capsys, ["render", SPEECH, "-o", out, *RO, "--to-skeleton", skeleton,
                           tmp_path / "o.bvh"], "--to-skeleton", str(skeleton), needle)
    assert not out.exists()


def test_a_batch_checks_the_shared_skeleton_once_before_the_first_render(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import gesture_sim.app.batch as batch

    def no_jobs(*args, **kwargs):
        raise AssertionError("a render started before the skeleton was checked")

    monkeypatch.setattr(batch, "run_jobs", no_jobs)
    second = tmp_path / "b.wav"
    shutil.copy(SPEECH, second)
    skeleton = _bvh_with(tmp_path, "duplicate")
    fails_cleanly(capsys, ["render", SPEECH, second, "-o", tmp_path / "out", *RO,
                           "--to-skeleton", skeleton, tmp_path / "skel"],
                  "--to-skeleton", str(skeleton), "two joints are named 'Hips'")


def test_library_build_refuses_a_bvh_with_two_joints_of_one_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A BVH with two joints named Hips was built into a library."""
    bad = _bvh_with(tmp_path, "duplicate")
    out = tmp_path / "lib"
    fails_cleanly(capsys, ["library", "build", bad, "-o", out], str(bad),
                  "two joints are named 'Hips'")
    assert not out.exists()


# ------------------------------------------------------------------ 8. raw messages


def test_text_alignment_notes_are_one_warning_line_naming_the_file(
        capsys: pytest.CaptureFixture[str]) -> None:
    """``--text`` problems came out as Python ``UserWarning`` lines with a source line."""
    import warnings

    from gesture_sim.app.render import _aligned
    from gesture_sim.audio.sources import load_audio

    samples, _ = load_audio(SPEECH)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = cli.one_line_warning
        # (not the text of the recording: no alignment path)
        _aligned(samples, "author of the danger trail philip steels zqxwv",
                 "/x/take.txt (aligned to the audio)")
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("gesture-sim: warning: /x/take.txt: PocketSphinx could not align "
                          "the transcript"), err
    assert "the lips use the phones recognised in the audio instead" in err
    assert "UserWarning" not in err and "warnings.warn" not in err and "align_transcript" \
        not in err


def test_another_librarys_warning_is_one_line_with_its_category(
        capsys: pytest.CaptureFixture[str]) -> None:
    cli.one_line_warning(RuntimeWarning("invalid value\nencountered"), RuntimeWarning,
                         "/usr/lib/python3/site-packages/numpy/core/_methods.py", 12)
    assert capsys.readouterr().err == ("gesture-sim: warning: RuntimeWarning in _methods: "
                                       "invalid value encountered\n")


@pytest.mark.parametrize("case", ["text", "truncated"])
def test_a_corpus_npz_that_is_not_an_archive_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str) -> None:
    """A text file named .npz got numpy's ``allow_pickle`` advice; a truncated one a raw
    ``BadZipFile``."""
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    motion = corpus / "take.npz"
    if case == "text":
        motion.write_text("hello\n", encoding="utf-8")
    else:
        motion.write_bytes(SMPLX.read_bytes()[:3000])
    shutil.copy(TEN_S, corpus / "take.wav")
    for extra in ([], ["--on-error", "skip"]):
        line = fails_cleanly(capsys, ["train", "--corpus", corpus, "-o", tmp_path / "m",
                                      *extra], str(motion), "not a NumPy .npz archive",
                             "another kind of file named .npz")
        assert "pickle" not in line and "BadZipFile" not in line


def test_a_full_disk_in_listener_mine_names_the_output_not_the_temporary(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import errno
    import pathlib

    src = tmp_path / "talk.csv"
    src.write_text("start,end,signal,person\n0,20,talking,A\n"
                   + "".join(f"{t},{t + 0.2},nod,A\n{t + 0.2},{t + 0.3},nod,B\n"
                             for t in range(0, 20, 2)), encoding="utf-8")
    real = pathlib.Path.write_text

    def full(self, *args, **kwargs):
        if self.name.startswith(".tmp-"):
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "write_text", full)
    out = tmp_path / "rules.json"
    line = fails_cleanly(capsys, ["listener", "mine", src, "-o", out],
                         f"cannot write {out}: No space left on device")
    assert ".tmp-" not in line
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".tmp")]
