"""``gesture-sim train --corpus DIR -o MODEL_DIR`` (issue 35 item 1): one command trains the
library, the inference model and the policy from a corpus folder; the result renders; the
per-file cache resumes an interrupted run to the same result; ``--jobs 2`` gives what
``--jobs 1`` gives; broken files stop or are skipped; outputs never replace an input.

The corpus is built in a temporary folder from the real 10 s BEAT2 pair of the test data (and a
7 s crop of it as a second speaker). Every run uses ``--states 3`` (no state selection) to stay
quick; the shared cache makes the later runs train only.
"""

from __future__ import annotations

import json
import shutil
import signal
import wave
from pathlib import Path

import numpy as np
import pytest

from gesture_sim import cli, corpus
from gesture_sim.interrupt import Interrupted

DATA = Path(__file__).resolve().parents[1] / "data"
NPZ = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
WAV = DATA / "eval" / "2_scott_0_1_1_first10s.wav"
TEXTGRID = DATA / "textgrids" / "2_scott_0_1_1.TextGrid"
BVH = DATA / "motion" / "dataset-1_bow_active_001.bvh"
FAST = ["--states", "3"]
#: One worker builds the module's corpus and clean run (they are module fixtures).
pytestmark = pytest.mark.xdist_group("train-corpus")


def _crop_npz(src: Path, dst: Path, seconds: float) -> None:
    with np.load(src) as d:
        arrays = {k: d[k] for k in d.files}
    n = int(seconds * float(arrays["mocap_frame_rate"]))
    for k in ("poses", "expressions", "trans"):
        arrays[k] = arrays[k][:n]
    np.savez(dst, **arrays)


def _crop_wav(src: Path, dst: Path, seconds: float) -> None:
    with wave.open(str(src), "rb") as r:
        params = r.getparams()
        frames = r.readframes(int(seconds * r.getframerate()))
    with wave.open(str(dst), "wb") as w:
        w.setparams(params)
        w.writeframes(frames)


def _crop_textgrid(src: Path, dst: Path, seconds: float) -> None:
    """The intervals of ``src`` that start before ``seconds``, cut there (the take's own
    alignment of the cropped audio: a longer one is refused as another recording's)."""
    from gesture_sim.audio.textgrid import read_textgrid

    grid = read_textgrid(src)
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0",
             f"xmax = {seconds}", "tiers? <exists>", f"size = {len(grid)}", "item []:"]
    for k, (name, items) in enumerate(grid.items(), start=1):
        kept = [(a, min(b, seconds), t) for a, b, t in
                ((iv.xmin, iv.xmax, iv.text) for iv in items) if a < seconds]
        lines += [f"    item [{k}]:", '        class = "IntervalTier"',
                  f'        name = "{name}"', "        xmin = 0", f"        xmax = {seconds}",
                  f"        intervals: size = {len(kept)}"]
        for j, (a, b, t) in enumerate(kept, start=1):
            text = t.replace('"', '""')
            lines += [f"        intervals [{j}]:", f"            xmin = {a}",
                      f"            xmax = {b}", f'            text = "{text}"']
    dst.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _beat2(root: Path) -> Path:
    """BEAT2 layout: 2_scott_0_1_1 (10 s, with its TextGrid) and 4_lawrence_0_2_2 (7 s)."""
    for sub in ("smplxflame_30", "wave16k", "textgrid"):
        (root / sub).mkdir(parents=True)
    shutil.copy(NPZ, root / "smplxflame_30" / "2_scott_0_1_1.npz")
    shutil.copy(WAV, root / "wave16k" / "2_scott_0_1_1.wav")
    _crop_textgrid(TEXTGRID, root / "textgrid" / "2_scott_0_1_1.TextGrid", 10.0)
    _crop_npz(NPZ, root / "smplxflame_30" / "4_lawrence_0_2_2.npz", 7.0)
    _crop_wav(WAV, root / "wave16k" / "4_lawrence_0_2_2.wav", 7.0)
    return root


def _run(argv: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    rc = cli.main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


def _train(capsys, corpus_dir: Path, out: Path, *extra: str) -> dict:
    rc, stdout, err = _run(["train", "--corpus", str(corpus_dir), "-o", str(out), *FAST,
                            "--json", *extra], capsys)
    assert rc == 0, err
    return json.loads(stdout)


def _prints(s: dict) -> tuple[str, str, str]:
    return s["library_fingerprint"], s["model_fingerprint"], s["state_model_fingerprint"]


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("corpus")
    return {"corpus": _beat2(root / "beat2"), "cache": root / "cache", "root": root}


@pytest.fixture(scope="module")
def trained(base: dict) -> dict:
    """The clean run everything else is compared with (module-scoped: its output is captured
    with redirect_stdout, capsys being per test)."""
    import contextlib
    import io

    out = base["root"] / "stack"
    buf, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        rc = cli.main(["train", "--corpus", str(base["corpus"]), "-o", str(out), *FAST,
                       "--cache", str(base["cache"]), "--json"])
    assert rc == 0, err.getvalue()
    return {"out": out, "summary": json.loads(buf.getvalue())}


def test_beat2_corpus_trains_a_stack_that_renders(trained: dict) -> None:
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.feed import run_file
    from gesture_sim.loading import load_stack
    from gesture_sim.pipeline import GesturePipeline

    out, s = trained["out"], trained["summary"]
    assert s["layout"] == "beat2" and s["files"] == 2 and s["skipped"] == []
    assert s["speakers"] == {"lawrence": 1, "scott": 1}
    assert [p["name"] for p in s["pairs"]] == ["2_scott_0_1_1", "4_lawrence_0_2_2"]
    assert abs(s["seconds"] - 17.0) < 0.1 and s["segments"] > 10 and s["states"] == 3
    scott = s["pairs"][0]
    assert scott["textgrid"] and 0 < scott["words"] < 60   # the 63 s grid, cut to the 10 s take
    assert s["cache"] == {"dir": s["cache"]["dir"], "hits": 0, "misses": 2}
    assert {"analysis", "library", "kinematic HMM", "remapped CRF", "controller policy",
            "write"} <= set(s["stage_seconds"])
    for f in ("library.npz", "manifest.json", "README.md", "model/model.json",
              "model/model.npz", "model/policy.npz"):
        assert (out / f).is_file(), f
    readme = (out / "README.md").read_text()
    assert "2_scott_0_1_1" in readme and "lawrence" in readme and s["model_fingerprint"] in readme
    stack = load_stack(out)                      # finds <out>/model and its own policy
    assert stack.model_dir == out / "model" and not (out / "policies").exists()
    assert stack.library.fingerprint == s["library_fingerprint"]
    # both SMPL-X takes carry hand pose: their finger motion plays with their clips
    assert all(p["finger_track"] for p in s["pairs"])
    assert sorted(stack.finger_tracks) == [0, 1]
    for i, track in stack.finger_tracks.items():
        assert track.shape == (stack.library.clips[i].n_frames, 40)
        assert np.degrees(track.std(axis=0)).mean() > 1.0      # the fingers move
    pipe = GesturePipeline(stack.library, stack.model, stack.policy, physics=False,
                           control_library=stack.control_library)
    samples, _ = load_audio(DATA / "audio" / "jfk.wav")
    run = run_file(pipe, y=samples[: int(1.5 * SAMPLE_RATE)], sr=SAMPLE_RATE)
    assert len(run.pipeline.log.targets) > 0


def test_one_pair_corpus_is_the_pair_model(base: dict, trained: dict, tmp_path: Path,
                                           capsys) -> None:
    """``--speaker scott`` keeps one pair; its model is ``train --pair`` of that pair with the
    corpus library's normalisation: the same training data fingerprint."""
    s = _train(capsys, base["corpus"], tmp_path / "scott", "--cache", str(base["cache"]),
               "--speaker", "2")
    assert s["files"] == 1 and s["speakers"] == {"scott": 1} and s["cache"]["hits"] == 1
    rc, stdout, err = _run(["train", "--pair", str(NPZ), str(WAV), "-o", str(tmp_path / "m"),
                            *FAST, "--library", str(tmp_path / "scott"), "--json"], capsys)
    assert rc == 0, err
    assert json.loads(stdout)["fingerprint"] == s["model_fingerprint"]


def test_an_interrupted_run_resumes_to_the_same_result(base: dict, trained: dict,
                                                       tmp_path: Path, capsys,
                                                       monkeypatch) -> None:
    real = corpus.analyse_pair
    calls = []

    def flaky(*args):
        calls.append(args[3])
        if len(calls) == 2:
            raise Interrupted(signal.SIGINT)       # Ctrl-C during the second file
        return real(*args)

    monkeypatch.setattr(corpus, "analyse_pair", flaky)
    cache, out = tmp_path / "cache", tmp_path / "out"
    rc, _, err = _run(["train", "--corpus", str(base["corpus"]), "-o", str(out), *FAST,
                       "--cache", str(cache)], capsys)
    assert rc == 130 and "interrupted" in err
    assert len(list(cache.glob("*.npz"))) == 1 and not (out / "library.npz").exists()
    monkeypatch.setattr(corpus, "analyse_pair", real)
    s = _train(capsys, base["corpus"], out, "--cache", str(cache))
    assert s["cache"]["hits"] == 1 and s["cache"]["misses"] == 1
    assert _prints(s) == _prints(trained["summary"])


def test_two_jobs_give_what_one_gives(base: dict, trained: dict, tmp_path: Path,
                                      capsys) -> None:
    """Two worker processes; the cache holds a damaged entry for one file, which is analysed
    again rather than trusted."""
    cache = tmp_path / "c"
    cache.mkdir()
    entry = next(base["cache"].glob("2_scott*.npz"))
    (cache / entry.name).write_bytes(b"not an npz")
    s = _train(capsys, base["corpus"], tmp_path / "out", "--cache", str(cache), "--jobs", "2")
    assert s["cache"]["misses"] == 2
    assert _prints(s) == _prints(trained["summary"])


def test_dask_gives_what_one_job_gives(base: dict, trained: dict, tmp_path: Path,
                                      capsys) -> None:
    pytest.importorskip("distributed")
    s = _train(capsys, base["corpus"], tmp_path / "out", "--cache", str(tmp_path / "c"),
               "--dask", "local:1")
    assert s["cache"]["misses"] == 2
    assert _prints(s) == _prints(trained["summary"])


def test_a_broken_file_stops_or_is_skipped(base: dict, trained: dict, tmp_path: Path,
                                           capsys) -> None:
    bad_corpus = tmp_path / "beat2"
    shutil.copytree(base["corpus"], bad_corpus)
    bad = bad_corpus / "smplxflame_30" / "3_solomon_0_1_1.npz"
    bad.write_bytes(b"\x00garbage, not a zip archive" * 10)
    shutil.copy(WAV, bad_corpus / "wave16k" / "3_solomon_0_1_1.wav")
    args = ["train", "--corpus", str(bad_corpus), *FAST, "--cache", str(base["cache"])]
    rc, _, err = _run([*args, "-o", str(tmp_path / "stop")], capsys)
    assert rc == 2 and str(bad) in err and err.count("error:") == 1
    assert not (tmp_path / "stop" / "library.npz").exists()
    rc, stdout, err = _run([*args, "-o", str(tmp_path / "skip"), "--on-error", "skip",
                            "--json"], capsys)
    assert rc == 0, err
    s = json.loads(stdout)
    assert "warning" in err and str(bad) in err
    assert [k["file"] for k in s["skipped"]] == [str(bad)] and s["files"] == 2
    assert _prints(s) == _prints(trained["summary"])       # the rest, as without the bad file
    assert str(bad) in (tmp_path / "skip" / "README.md").read_text()


def test_folder_layout_speakers_and_unpaired(tmp_path: Path, capsys) -> None:
    root = tmp_path / "zeggs"
    (root / "alice").mkdir(parents=True)
    (root / "bob" / "day1").mkdir(parents=True)
    shutil.copy(NPZ, root / "alice" / "take.npz")
    shutil.copy(WAV, root / "alice" / "take.wav")
    shutil.copy(BVH, root / "bob" / "day1" / "take.bvh")
    shutil.copy(WAV, root / "bob" / "day1" / "take.wav")
    shutil.copy(TEXTGRID, root / "bob" / "day1" / "take.TextGrid")
    shutil.copy(BVH, root / "bob" / "lonely.bvh")              # no speech
    (root / ".hidden").mkdir()
    shutil.copy(BVH, root / ".hidden" / "x.bvh")
    c = corpus.discover(root)
    assert c.layout == "folder"
    assert [(i.name, i.speaker, i.textgrid is not None) for i in c.items] == [
        ("alice_take", "alice", False), ("bob_day1_take", "bob", True)]
    assert c.unpaired == [root / "bob" / "lonely.bvh"]
    assert c.speakers() == {"alice": {"pairs": 1, "unpaired": 0},
                            "bob": {"pairs": 1, "unpaired": 1}}
    rc, stdout, _ = _run(["train", "--corpus", str(root), "--list", "--speaker", "bob",
                          "--json"], capsys)
    assert rc == 0 and [p["name"] for p in json.loads(stdout)["pairs"]] == ["bob_day1_take"]
    # an output folder inside the corpus is not read as corpus
    assert corpus.discover(root, exclude=[root / "alice"]).items[0].speaker == "bob"


def test_bad_corpus_command_lines(base: dict, tmp_path: Path, capsys) -> None:
    c = str(base["corpus"])
    empty = tmp_path / "empty"
    empty.mkdir()
    for argv, msg in [
        (["--corpus", str(empty), "-o", str(tmp_path / "o")], "no motion/speech pair found"),
        (["--corpus", "/no/such/dir", "-o", str(tmp_path / "o")], "no such folder"),
        (["--corpus", c, "-o", c], "holds the input"),
        (["--corpus", c, "-o", f"{c}/wave16k"], "holds the input"),
        (["--corpus", c, "-o", str(tmp_path / "o"), "--cache", f"{c}/wave16k"],
         "holds the input"),
        (["--corpus", c, "-o", str(tmp_path / "o"), "--speaker", "nobody"],
         "speakers: lawrence (1 pairs), scott (1 pairs)"),
        (["--corpus", c], "-o/--output is required"),
        (["--corpus", c, "-o", str(tmp_path / "o"), "--library", c], "--library cannot"),
        (["--corpus", c, "-o", str(tmp_path / "o"), "--jobs", "0"], "--jobs must be"),
        (["--pair", str(NPZ), str(WAV), "-o", str(tmp_path / "o"), "--speaker", "x"],
         "--speaker needs --corpus"),
    ]:
        rc, _, err = _run(["train", *argv], capsys)
        assert rc == 2 and msg in err and err.count("error:") == 1, (argv, err)
    assert not (tmp_path / "o").exists()
    with pytest.raises(SystemExit) as exc:
        cli.main(["train", "--corpus", c, "--pair", str(NPZ), str(WAV), "-o", "x"])
    assert exc.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err
