"""The TextGrid reader: the four BEAT2 alignments, the short format, and malformed files."""

from __future__ import annotations

from pathlib import Path

import pytest

from gesture_sim.audio.textgrid import Interval, read_textgrid, stressed_vowels
from gesture_sim.errors import GestureSimError

DATA = Path(__file__).resolve().parents[1] / "data" / "textgrids"
TAKES = sorted(DATA.glob("*.TextGrid"))

SHORT = '''File type = "ooTextFile"
Object class = "TextGrid"

0
1.5
<exists>
2
"IntervalTier"
"phones"
0
1.5
4
0
0.3
""
0.3
0.6
"AY1"
0.6
1.0
"said ""so"""
1.0
1.5
"EH2"
"TextTier"
"marks"
0
1.5
1
0.75
"H*"
'''


def test_the_four_takes_read_with_both_tiers() -> None:
    assert len(TAKES) == 4
    for path in TAKES:
        tg = read_textgrid(path)
        assert list(tg) == ["words", "phones"]
        for tier in tg.values():
            assert all(a.xmax <= b.xmin + 1e-9 for a, b in zip(tier, tier[1:], strict=False))
            assert tier[0].xmin == pytest.approx(0.0) and tier[-1].xmax == pytest.approx(tg.xmax)
        assert 60.0 < tg.xmax < 70.0


def test_take_one_known_contents() -> None:
    tg = read_textgrid(DATA / "2_scott_0_1_1.TextGrid")
    assert tg.xmax == pytest.approx(64.097375)
    assert len(tg["words"]) == 220 and len(tg["phones"]) == 684
    assert tg["words"][:4] == [Interval(0.0, 1.42, ""), Interval(1.42, 1.52, "the"),
                               Interval(1.52, 1.78, "first"), Interval(1.78, 1.97, "thing")]
    sv = stressed_vowels(tg)
    assert len(sv) == 168
    assert len(stressed_vowels(tg, include_secondary=True)) == 184
    content = stressed_vowels(tg, content_words_only=True)
    assert 0 < len(content) < len(sv)
    # "first" (1.52-1.78) has a stressed vowel, "the" (1.42-1.52) none
    assert any(1.52 <= a and b <= 1.78 for a, b in sv)
    assert not any(1.42 <= a and b <= 1.52 for a, b in sv)
    assert all(a < b for a, b in sv) and sv == sorted(sv)


def test_short_format_escaped_quotes_and_point_tiers(tmp_path: Path) -> None:
    p = tmp_path / "short.TextGrid"
    p.write_text(SHORT)
    tg = read_textgrid(p)
    assert tg["phones"][2] == Interval(0.6, 1.0, 'said "so"')
    assert tg["marks"] == [Interval(0.75, 0.75, "H*")]
    assert stressed_vowels(tg) == [(0.3, 0.6)]
    assert stressed_vowels(tg, include_secondary=True) == [(0.3, 0.6), (1.0, 1.5)]
    p16 = tmp_path / "utf16.TextGrid"
    p16.write_bytes(SHORT.encode("utf-16"))
    assert read_textgrid(p16) == tg


@pytest.mark.parametrize("content, message", [
    ("", "file ends before file type"),
    ("hello world\n", "file ends before file type"),
    ('File type = "ooTextFile"\nObject class = "Pitch 1"\n', "header"),
    (SHORT[: SHORT.index('"EH2"')], "file ends before interval text"),
    (SHORT.replace('"IntervalTier"', '"Polygon"'), "unknown tier class"),
    (SHORT.replace("0.6\n1.0\n", "0.6\nx\n", 1), "expected interval xmax"),
])
def test_malformed_files_are_one_line_errors(tmp_path: Path, content: str, message: str) -> None:
    p = tmp_path / "bad.TextGrid"
    p.write_text(content)
    with pytest.raises(GestureSimError, match=message) as e:
        read_textgrid(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_missing_file_and_missing_tier(tmp_path: Path) -> None:
    with pytest.raises(GestureSimError, match="cannot read TextGrid"):
        read_textgrid(tmp_path / "nope.TextGrid")
    p = tmp_path / "short.TextGrid"
    p.write_text(SHORT)
    with pytest.raises(GestureSimError, match=r"short\.TextGrid: TextGrid has no tier 'words'"):
        stressed_vowels(read_textgrid(p), content_words_only=True)
    with pytest.raises(GestureSimError, match="no tier 'phonemes'"):
        stressed_vowels(read_textgrid(p), phone_tier="phonemes")
