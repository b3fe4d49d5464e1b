"""`render --phones/--text` (where the lips' phones come from) and the listeners' options
(`--listener`, `--interest`): checked before any work, and a render that says what the mouth
used."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SPEECH = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"      # 4 s of read speech
SMALL = ["--width", "160", "--height", "90", "--quality", "fast", "--workers", "1"]


@pytest.mark.parametrize("extra, says", [
    (["--interest", "0.5"], "a listener is one of the two people"),
    (["--listener", "okwechime"], "a listener is one of the two people"),
    (["--two", "--listener-motion", "envelope"], "for the audio-driven listener"),
    (["--two", "--listener", "okwechime", "--listener-motion", "mimic"], "invalid choice"),
    (["--interest", "1.5"], "expected X or X,Y"),
    (["--interest", "a,b"], "expected X or X,Y"),
    (["--text", "{d}/missing.txt"], "missing.txt"),
    (["--phones", "lips"], "invalid choice"),
])
def test_face_and_listener_options_are_checked_before_any_work(tmp_path: Path, capsys,
                                                               extra, says) -> None:
    from gesture_sim import cli

    argv = ["render", str(SPEECH), "-o", str(tmp_path / "r.mp4"), *SMALL,
            *(a.format(d=tmp_path) for a in extra)]
    try:
        code = cli.main(argv)
    except SystemExit as exc:       # argparse's own errors exit from parse_args
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert "error: " in err and says in err, err
    assert len(err.strip().splitlines()) <= 3          # argparse prints usage + one line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_render_says_where_the_mouths_phones_came_from(tmp_path: Path, capsys) -> None:
    from gesture_sim import cli

    text = tmp_path / "text.txt"
    text.write_text("author of the danger trail philip steels et cetera\n", encoding="utf-8")
    runs = {"off": ["--phones", "off"], "text": ["--text", str(text)]}
    for name, extra in runs.items():
        out = tmp_path / f"{name}.mp4"
        assert cli.main(["render", str(SPEECH), "-o", str(out), *SMALL, *extra,
                         "--json"]) == 0, capsys.readouterr().err
        mouth = json.loads(capsys.readouterr().out)["mouth"]
        if name == "off":
            assert mouth["phones"] is None and mouth["source"].startswith("loudness")
        else:
            assert mouth["phones"] > 20 and "aligned" in mouth["source"]


@pytest.mark.parametrize("extra, says", [
    (["--interest", "0.5"], "for an avatar that listens"),
    (["--listen", "--interest", "2"], "--interest must be"),
    (["--listen", "--listener-motion", "graph"], "for the audio-driven listener"),
])
def test_live_listener_options_are_checked_first(capsys, extra, says) -> None:
    from gesture_sim import cli

    assert cli.main(["live", "--audio", str(SPEECH), "--duration", "1", *extra]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1, err
