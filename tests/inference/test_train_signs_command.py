"""``gesture-sim train --signs TAKES_DIR -o MODEL_DIR``: a planted word -> sign mapping in
espeak-ng takes is learnt (a held-out take's keyword frames get the planted sign, which the
majority sign never is), the --json counts are the annotations', and a bad input (an unknown
sign, a missing annotation file, an output that is an input, unreadable audio) is one line
naming the file, exit status 2 and nothing written."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gesture_sim import cli
from gesture_sim.audio.sources import SAMPLE_RATE
from gesture_sim.inference import sign_model as sm
from gesture_sim.testing.dialogue import say

pytest.importorskip("scipy")

#: the keyword (in no lexicon row) and the sign planted on it; the rest is not annotated and
#: trained as OTHER (--unlabelled)
KEY, PLANTED, OTHER = "banana", "Head-nod", "Rest"
FILLER = ("red", "green", "table", "window", "paper", "garden", "river", "yellow")
#: per take: number of 1-s slots, the slots holding the keyword
TAKES = {"a": (16, (3, 10)), "b": (16, (4, 12)), "c": (12, (2, 8))}
HELD_OUT = "c"


def _take(n: int, keys: tuple[int, ...]) -> tuple[np.ndarray, list, list]:
    """One word per 1-s slot (0.25 s in); the keyword's slot and its neighbours are PLANTED (a
    gesture spans its word), the other slots OTHER. Returns (samples, words, spans: PLANTED
    only)."""
    x = np.zeros(n * SAMPLE_RATE, np.float32)
    words, labels = [], [OTHER] * n
    for k in range(n):
        w = KEY if k in keys else FILLER[(3 * k + len(keys)) % len(FILLER)]
        a = say(w)[: int(0.7 * SAMPLE_RATE)]
        i0 = k * SAMPLE_RATE + SAMPLE_RATE // 4
        x[i0:i0 + len(a)] = 0.5 * a
        words.append((i0 / SAMPLE_RATE, (i0 + len(a)) / SAMPLE_RATE, w))
        if k in keys:
            for j in (k - 1, k, k + 1):
                if 0 <= j < n:
                    labels[j] = PLANTED
    spans, start = [], 0
    for k in range(1, n + 1):
        if k == n or labels[k] != labels[start]:
            spans.append((float(start), float(k), labels[start]))
            start = k
    return x, words, [sp for sp in spans if sp[2] == PLANTED]


def _wav(path: Path, x: np.ndarray) -> None:
    import wave

    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(SAMPLE_RATE)
        w.writeframes((np.clip(x, -1, 1) * 32767).astype("<i2").tobytes())


def _textgrid(path: Path, duration: float, tiers: dict[str, list]) -> None:
    """A long-format TextGrid with interval tiers of (start, end, text) (gaps filled)."""
    out = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0",
           f"xmax = {duration}", "tiers? <exists>", f"size = {len(tiers)}", "item []:"]
    for t, (name, items) in enumerate(tiers.items(), start=1):
        full, at = [], 0.0
        for a, b, text in items:
            if a > at + 1e-9:
                full.append((at, a, ""))
            full.append((a, b, text))
            at = b
        if at < duration - 1e-9:
            full.append((at, duration, ""))
        out += [f"    item [{t}]:", '        class = "IntervalTier"', f'        name = "{name}"',
                "        xmin = 0", f"        xmax = {duration}",
                f"        intervals: size = {len(full)}"]
        for i, (a, b, text) in enumerate(full, start=1):
            out += [f"        intervals [{i}]:", f"            xmin = {a}",
                    f"            xmax = {b}", f'            text = "{text}"']
    path.write_text("\n".join(out) + "\n", encoding="utf-8")


def _main(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main(argv)
    return status, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """TAKES_DIR with takes a (TextGrid words + signs.csv with a header) and b (a plain
    transcript + a 'signs' TextGrid tier), the held-out take c, and the trained model."""
    root = tmp_path_factory.mktemp("signs")
    takes, held = root / "takes", {}
    takes.mkdir()
    for name, (n, keys) in TAKES.items():
        x, words, spans = _take(n, keys)
        if name == HELD_OUT:
            held = {"samples": x, "words": words, "spans": spans, "n": n, "keys": keys}
            continue
        _wav(takes / f"{name}.wav", x)
        if name == "a":
            _textgrid(takes / "a.TextGrid", float(n), {"words": words})
            (takes / "a.signs.csv").write_text(
                "start,end,sign\n" + "".join(f"{a},{b},{s}\n" for a, b, s in spans),
                encoding="utf-8")
        else:
            (takes / f"{name}.txt").write_text(" ".join(w for _, _, w in words) + "\n",
                                               encoding="utf-8")
            _textgrid(takes / f"{name}.TextGrid", float(n), {"signs": spans})
    out = root / "model"
    status, stdout, stderr = _main(["train", "--signs", str(takes), "-o", str(out),
                                    "--unlabelled", OTHER.lower(), "--l2", "0.02", "--json"])
    assert status == 0, stderr
    return {"takes": takes, "out": out, "summary": json.loads(stdout), "held": held,
            "root": root}


def test_the_model_learns_the_planted_keyword_sign(corpus) -> None:
    from gesture_sim.audio.prosody import analyze_samples

    assert sorted(p.name for p in corpus["out"].iterdir()) == ["signs.json", "signs.npz"]
    model = sm.SignModel.load(corpus["out"])          # what chiu14's sign_model= loads
    assert KEY in model.layout.vocabulary
    h = corpus["held"]
    syl = analyze_samples(h["samples"]).syllables
    x = sm.frame_inputs(model.layout, h["n"], syl, h["words"])
    pred = np.array(model.predict(x))
    truth = np.array(sm.frame_labels(h["spans"], h["n"], default=OTHER))
    majority = max(corpus["summary"]["sign_frames"], key=corpus["summary"]["sign_frames"].get)
    assert majority == OTHER
    keys = list(h["keys"])
    # the keyword's frames: the planted sign, which the majority baseline never predicts
    hits = float(np.mean(pred[keys] == PLANTED))
    assert hits >= 2 / 3 > float(majority == PLANTED), (pred, keys)
    # and over the whole take, better than always the majority sign
    acc = float(np.mean(pred == [sm.SIGNS[i] for i in truth]))
    assert acc > float(np.mean(truth == sm.SIGN_INDEX[majority])), pred
    # it runs as chiu14 runs it: the causal filter over the held-out take
    filt = model.new_filter(h["words"])
    b = filt.step(float(h["n"]), syl)
    assert b.shape == (sm.N_SIGNS,) and np.isclose(b.sum(), 1.0)


def test_chiu14_takes_the_folder_written(corpus) -> None:
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method="chiu14", physics=False, sign_model=corpus["out"])
    assert isinstance(pipe.filter, sm.SignFilter)
    assert KEY in pipe.filter.model.layout.vocabulary
    assert pipe.filter.model.info["labels_from"].startswith("sign annotations in ")


def test_json_summary_counts_are_the_annotations(corpus) -> None:
    s = corpus["summary"]
    expected: dict[str, int] = {PLANTED: 0, OTHER: 0}
    for name, (n, keys) in TAKES.items():
        if name != HELD_OUT:
            planted = int(sum(b - a for a, b, _ in _take(n, keys)[2]))
            expected[PLANTED] += planted
            expected[OTHER] += n - planted
    assert expected == {PLANTED: 12, OTHER: 20}
    assert s["sign_frames"] == expected
    assert s["frames"] == s["labelled_frames"] == sum(expected.values()) == 32
    by_name = {t["name"]: t for t in s["takes"]}
    assert set(by_name) == {"a", "b"}
    assert by_name["a"]["words_from"] == "textgrid" and by_name["a"]["signs_from"] == "csv"
    assert by_name["b"]["words_from"] == "transcript"
    assert by_name["b"]["signs_from"] == "textgrid"
    assert by_name["b"]["n_words"] == TAKES["b"][0]        # the transcript was aligned
    assert s["training"]["iterations"] > 0 and s["unlabelled"] == OTHER
    info = json.loads((corpus["out"] / "signs.json").read_text())["info"]
    assert info["label_counts"] == expected


def _copy(corpus, name: str) -> Path:
    d = corpus["root"] / name
    shutil.copytree(corpus["takes"], d)
    return d


def _refused(argv: list[str], out: Path, *named: str) -> str:
    status, stdout, stderr = _main(argv)
    assert status == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gesture-sim: error: "), stderr
    for n in named:
        assert n in lines[0], lines[0]
    assert not out.exists(), "something was written"
    return lines[0]


def test_an_unknown_sign_is_one_line_naming_the_file(corpus) -> None:
    d = _copy(corpus, "bad_sign")
    csv = d / "a.signs.csv"
    csv.write_text(csv.read_text() + "13.2,13.8,Pointing\n", encoding="utf-8")
    out = corpus["root"] / "bad_sign_out"
    line = _refused(["train", "--signs", str(d), "-o", str(out)], out, str(csv), "Pointing")
    assert f"{csv}:4:" in line           # header, two spans, then this one


def test_a_missing_annotation_file_is_one_line_naming_the_take(corpus) -> None:
    d = _copy(corpus, "no_signs")
    (d / "a.signs.csv").unlink()
    out = corpus["root"] / "no_signs_out"
    _refused(["train", "--signs", str(d), "-o", str(out)], out, str(d / "a.wav"),
             "a.signs.csv")


def test_an_output_that_is_an_input_is_refused(corpus) -> None:
    d = corpus["takes"]
    before = sorted(p.name for p in d.iterdir())
    status, _, stderr = _main(["train", "--signs", str(d), "-o", str(d)])
    assert status == 2 and len(stderr.strip().splitlines()) == 1 and str(d) in stderr
    status, _, stderr = _main(["train", "--signs", str(d), "-o", str(d / "a.wav")])
    assert status == 2 and len(stderr.strip().splitlines()) == 1
    assert str(d / "a.wav") in stderr
    assert sorted(p.name for p in d.iterdir()) == before


def test_unreadable_audio_is_one_line_naming_it(corpus) -> None:
    d = _copy(corpus, "bad_audio")
    (d / "a.wav").write_bytes(b"RIFF\x00\x00\x00\x00WAVEjunk")
    out = corpus["root"] / "bad_audio_out"
    _refused(["train", "--signs", str(d), "-o", str(out)], out, "a.wav")


def test_signs_options_need_signs() -> None:
    status, _, stderr = _main(["train", "--pair", "m.npz", "a.wav", "-o", "x",
                               "--unlabelled", "Rest"])
    assert status == 2 and "--unlabelled needs --signs" in stderr


def test_the_readers_take_headerless_csv_elan_and_a_signs_tier(tmp_path) -> None:
    from gesture_sim.inference import sign_annotations as sa

    csv = tmp_path / "t.signs.csv"
    csv.write_text("# a comment\n0.5,1.5,head nod\n00:00:02.0,00:00:03.5,Everything\n")
    assert sa.read_sign_spans(csv) == [(0.5, 1.5, "Head-nod"), (2.0, 3.5, "Whole")]
    elan = tmp_path / "t.signs.txt"
    elan.write_text("signs\t\t0.5\t1.5\t1.0\tdeictic other\n")
    assert sa.read_sign_spans(elan) == [(0.5, 1.5, "Deictic.Other")]
    grid = tmp_path / "t.signs.TextGrid"
    _textgrid(grid, 4.0, {"signs": [(1.0, 2.0, "Beats")]})
    assert sa.read_sign_spans(grid) == [(1.0, 2.0, "Beats")]
    csv.write_text("start,end,sign\n2,1,Beats\n")
    with pytest.raises(sa.GestureSimError, match=r"t\.signs\.csv:2: bad times"):
        sa.read_sign_spans(csv)


def test_the_help_lists_the_signs_and_the_model_defaults() -> None:
    from gesture_sim.commands import train_signs

    assert train_signs.HELP_SIGNS == sm.SIGNS
    d = sm.SignModelSettings()
    assert train_signs.SIGNS_ONLY["l2"] == d.l2
    assert train_signs.SIGNS_ONLY["prior_weight"] == d.prior_weight
    assert train_signs.SIGNS_ONLY["min_count"] == d.min_count
    assert "take1.signs.csv" in train_signs.layout_help()


def test_render_hands_its_sign_model_to_chiu14(corpus, monkeypatch, tmp_path) -> None:
    """``render --method chiu14 --sign-model DIR`` builds its pipeline with that folder; the
    option is refused for another method and for a missing folder."""
    from gesture_sim.errors import GestureSimError
    from gesture_sim.pipeline import GesturePipeline

    seen: dict = {}

    def create(*args, **kwargs):
        seen.update(kwargs)
        raise GestureSimError("stopped by the test")

    monkeypatch.setattr(GesturePipeline, "create", staticmethod(create))
    wav = corpus["takes"] / "a.wav"
    base = ["render", str(wav), "-o", str(tmp_path / "a.mp4"), "--width", "160", "--height",
            "90", "--quality", "fast", "--workers", "1"]
    status, _, err = _main([*base, "--method", "chiu14", "--sign-model", str(corpus["out"])])
    assert status == 2 and "stopped by the test" in err
    assert seen["method"] == "chiu14" and Path(seen["sign_model"]) == corpus["out"]
    status, _, err = _main([*base, "--sign-model", str(corpus["out"])])
    assert status == 2 and "--method chiu14" in err
    status, _, err = _main([*base, "--method", "chiu14", "--sign-model", str(tmp_path / "no")])
    assert status == 2 and "no" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.mp4").exists()
