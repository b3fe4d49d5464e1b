"""Praat TextGrid reader and the stressed vowels of a forced alignment.

* :func:`read_textgrid` reads Praat's text formats — the long ("ooTextFile" with ``key = value``
  lines, as Praat's *Save as text file* writes) and the short one (*Save as short text file*:
  the same values without labels), in UTF-8 or UTF-16 — into a :class:`TextGrid`: a dict
  ``tier name -> list[Interval]`` in file order. Interval tiers give their intervals; point
  (text) tiers give one zero-length :class:`Interval` ``(t, t, mark)`` per point.
* :func:`stressed_vowels` gives the (t_start, t_end) of the ARPAbet vowels of a phone tier with
  lexical stress 1 (``AY1``; also 2 with ``include_secondary``), optionally only those inside
  content words of a word tier (:data:`FUNCTION_WORDS` are left out).

Times are seconds, as in the file. A file that is not a TextGrid, is cut short, or lacks the
tier asked for raises a one-line :class:`~gesture_sim.errors.GestureSimError` naming the file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from gesture_sim.errors import GestureSimError

__all__ = ["FUNCTION_WORDS", "Interval", "TextGrid", "read_textgrid", "stressed_vowels",
           "timed_items"]


@dataclass(frozen=True)
class Interval:
    """One labelled interval (s). A point of a text tier has ``xmin == xmax``."""

    xmin: float
    xmax: float
    text: str


class TextGrid(dict):
    """``tier name -> list[Interval]`` (file order), with the file it came from in ``source``
    and the grid's time range in ``xmin``, ``xmax`` (s)."""

    def __init__(self, tiers: dict[str, list[Interval]], source: str, xmin: float,
                 xmax: float) -> None:
        super().__init__(tiers)
        self.source = source
        self.xmin = xmin
        self.xmax = xmax

    def tier(self, name: str) -> list[Interval]:
        """The tier called ``name``; a one-line error naming the file when there is none."""
        if name not in self:
            have = ", ".join(repr(k) for k in self) or "none"
            raise GestureSimError(f"{self.source}: TextGrid has no tier {name!r} "
                                  f"(tiers: {have})")
        return self[name]


# Tokens of Praat's text format: quoted strings ("" escapes a quote), bracketed indices and
# labels (skipped), numbers, and the <exists>/<absent> flags.
_TOKEN = re.compile(r'"((?:[^"]|"")*)"|\[[^\]]*\]|<(exists|absent)>|([A-Za-z_][\w?]*)'
                    r'|([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|([=:?!]|\S)')


def _tokens(text: str) -> list[str | float]:
    out: list[str | float] = []
    for m in _TOKEN.finditer(text):
        s, flag, word, num, _ = m.groups()
        if s is not None:
            out.append(s.replace('""', '"'))
        elif flag is not None:
            out.append(f"<{flag}>")
        elif num is not None:
            out.append(float(num))
        # words, bracketed indices and punctuation are labels of the long format: skipped
    return out


def _decode(raw: bytes) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return raw.decode("utf-16")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def read_textgrid(path: str | Path) -> TextGrid:
    """Read a Praat TextGrid (long or short text format) into a :class:`TextGrid`.

    Raises:
        GestureSimError: missing or unreadable file, not a TextGrid, or a malformed one.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise GestureSimError(f"{p}: cannot read TextGrid ({e.strerror or e})") from None
    toks = _tokens(_decode(raw))
    pos = 0

    def bad(why: str) -> GestureSimError:
        return GestureSimError(f"{p}: not a valid Praat TextGrid ({why})")

    def take(kind: type, what: str) -> str | float:
        nonlocal pos
        if pos >= len(toks):
            raise bad(f"file ends before {what}")
        tok = toks[pos]
        if not isinstance(tok, kind) or (kind is str and tok in ("<exists>", "<absent>")
                                         and what != "tiers flag"):
            raise bad(f"expected {what}, found {tok!r}")
        pos += 1
        return tok

    if take(str, "file type") != "ooTextFile" or take(str, "object class") != "TextGrid":
        raise bad('header is not File type = "ooTextFile", Object class = "TextGrid"')
    xmin, xmax = float(take(float, "xmin")), float(take(float, "xmax"))
    if take(str, "tiers flag") != "<exists>":
        return TextGrid({}, str(p), xmin, xmax)
    n_tiers = take(float, "number of tiers")
    if n_tiers < 0 or n_tiers != int(n_tiers):
        raise bad(f"bad number of tiers {n_tiers}")
    tiers: dict[str, list[Interval]] = {}
    for _ in range(int(n_tiers)):
        cls = take(str, "tier class")
        name = str(take(str, "tier name"))
        take(float, "tier xmin")
        take(float, "tier xmax")
        n = take(float, "number of intervals")
        if n < 0 or n != int(n):
            raise bad(f"bad interval count {n} in tier {name!r}")
        items: list[Interval] = []
        for _ in range(int(n)):
            if cls == "IntervalTier":
                a, b = float(take(float, "interval xmin")), float(take(float, "interval xmax"))
                if b < a:
                    raise bad(f"interval {a}..{b} ends before it starts in tier {name!r}")
                items.append(Interval(a, b, str(take(str, "interval text"))))
            elif cls == "TextTier":
                t = float(take(float, "point time"))
                items.append(Interval(t, t, str(take(str, "point mark"))))
            else:
                raise bad(f"unknown tier class {cls!r}")
        tiers[name] = items
    return TextGrid(tiers, str(p), xmin, xmax)


def timed_items(grid: TextGrid, tiers: tuple[str, ...] | None = None
                ) -> list[tuple[float, float, str]]:
    """``(xmin, xmax, "TIER interval 'TEXT'")`` (s) of the labelled (non-blank) intervals and
    points of ``tiers`` (default: every tier), latest end first: what
    :func:`gesture_sim.validation.side_file_times` compares with the audio's length (the
    latest item is the one a file of another recording fails on)."""
    out = [(iv.xmin, iv.xmax, f"{name!r} interval {iv.text.strip()[:30]!r}")
           for name, items in grid.items() if tiers is None or name in tiers
           for iv in items if iv.text.strip()]
    out.sort(key=lambda it: (it[0] >= 0, -it[1]))   # a negative start first, then the latest
    return out


#: English function words (articles, pronouns, auxiliaries, prepositions, conjunctions,
#: particles): their stressed vowels are left out by ``content_words_only``.
FUNCTION_WORDS = frozenset("""
a an the this that these those some any each every no
i me my mine myself you your yours yourself he him his himself she her hers herself it its
itself we us our ours ourselves they them their theirs themselves one
who whom whose which what where when why how there here
am is are was were be been being have has had having do does did doing
will would shall should can could may might must
i'm i've i'd i'll you're you've you'd you'll he's she's it's we're we've we'd we'll they're
they've they'd they'll that's there's what's isn't aren't wasn't weren't don't doesn't didn't
won't wouldn't can't couldn't shouldn't haven't hasn't hadn't let's
of to in on at by for with from up down out off over under into onto about as than
and or but nor so if then because while though although
not just also too very really um uh oh like yeah well
""".split())

_VOWEL = re.compile(r"^([A-Z]{2})([012])$")


def stressed_vowels(textgrid: TextGrid, include_secondary: bool = False,
                    content_words_only: bool = False, phone_tier: str = "phones",
                    word_tier: str = "words") -> list[tuple[float, float]]:
    """(t_start, t_end) in s of the stressed ARPAbet vowels of ``phone_tier``, in time order.

    A vowel is a phone label of two capitals and a stress digit (``AY1``); stress 1 counts,
    and 2 as well with ``include_secondary``. With ``content_words_only`` only vowels whose
    midpoint lies in a word of ``word_tier`` not in :data:`FUNCTION_WORDS` are kept.

    Raises:
        GestureSimError: a tier is missing (the message names the file).
    """
    keep = {"1", "2"} if include_secondary else {"1"}
    words = textgrid.tier(word_tier) if content_words_only else []
    out: list[tuple[float, float]] = []
    wi = 0
    for iv in textgrid.tier(phone_tier):
        m = _VOWEL.match(iv.text.strip().upper())
        if not m or m.group(2) not in keep:
            continue
        if content_words_only:
            mid = 0.5 * (iv.xmin + iv.xmax)
            while wi < len(words) and words[wi].xmax <= mid:
                wi += 1
            if wi >= len(words) or words[wi].xmin > mid:
                continue
            word = words[wi].text.strip().lower()
            if not word or word in FUNCTION_WORDS:
                continue
        out.append((iv.xmin, iv.xmax))
    out.sort()
    return out
