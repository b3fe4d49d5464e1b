"""A folder of sign-annotated takes (``gesture-sim train --signs TAKES_DIR``): what is in it,
its readers, and the :class:`~gesture_sim.inference.sign_model.LabelledTake` of each take.

**Layout.** One take per stem, all files side by side in ``TAKES_DIR`` (subfolders are not
read; files whose name starts with ``README`` are ignored)::

    TAKES_DIR/
      take1.wav           the speech (.wav, or any format load_audio reads: .flac, .mp3, ...)
      take1.TextGrid      the words: a tier named "words" (phones tier not needed)
      take1.signs.csv     the sign annotations: start,end,sign (s; header optional)
      take2.wav
      take2.txt           or the words as a plain transcript (force-aligned to the audio)
      take2.TextGrid      ... and the sign annotations as a tier named "signs"

**Words** (exactly one source per take): the ``words`` tier of ``STEM.TextGrid``, or
``STEM.txt``, a plain transcript aligned to the audio with
:func:`gesture_sim.audio.phones.align_transcript`.

**Sign annotations** (exactly one source per take), times in seconds on the audio's clock:

* ``STEM.signs.csv``: rows ``start,end,sign``; a header row is optional (``start``/``start_s``/
  ``begin``, ``end``/``end_s``, ``sign``/``value`` in any order; without one the columns are in
  that order); blank lines and lines starting with ``#`` are skipped. Times are ``12.5`` or
  ``[hh:]mm:ss.ms``.
* ``STEM.signs.txt`` (or ``.tsv``): an ELAN tab-delimited export (File > Export As >
  Tab-delimited Text; :func:`gesture_sim.motion.signs.read_sign_annotations`).
* a tier named ``signs`` in ``STEM.TextGrid`` or in ``STEM.signs.TextGrid`` (empty intervals
  are not annotations).

Sign values are matched by :func:`gesture_sim.motion.signs.canonical_sign` (one of the 14
signs; case, spaces, underscores and "Everything" for Whole forgiven). A missing or unreadable
file, a bad time, a value that names no sign, a span past the end of the audio, an annotation
or words file without its audio: one :class:`~gesture_sim.errors.GestureSimError` line naming
the file (and the line).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from gesture_sim.errors import GestureSimError
from gesture_sim.units import parse_seconds

#: Audio suffixes (lower case) taken as a take's speech.
AUDIO_SUFFIXES: tuple[str, ...] = (".wav", ".flac", ".mp3", ".ogg", ".opus", ".m4a", ".aac",
                                   ".aif", ".aiff")
#: Tier names in a TextGrid.
WORDS_TIER = "words"
SIGNS_TIER = "signs"
#: The suffixes of a sign annotation file after ``STEM.signs`` (lower case) and their kind.
SIGN_FILES: dict[str, str] = {".csv": "csv", ".txt": "elan", ".tsv": "elan",
                              ".textgrid": "textgrid"}

Span = tuple[float, float, str]


@dataclass(frozen=True)
class TakeFiles:
    """The files of one take.

    Attributes:
        name: the stem; audio: the speech file.
        words: the TextGrid (``words_kind == "textgrid"``) or the transcript
            (``"transcript"``) the words come from.
        signs: the annotation file; signs_kind: ``"csv"``, ``"elan"`` or ``"textgrid"``.
    """

    name: str
    audio: Path
    words: Path
    words_kind: str
    signs: Path
    signs_kind: str

    def files(self) -> list[Path]:
        return list(dict.fromkeys([self.audio, self.words, self.signs]))


# --- readers -----------------------------------------------------------------------------------


def _sign(path: Path, where: str, value: str) -> str:
    from gesture_sim.motion.signs import canonical_sign

    try:
        return canonical_sign(value)
    except GestureSimError as exc:
        raise GestureSimError(f"{path}:{where}: {exc}") from None


def _span(path: Path, where: str, a: float, b: float) -> None:
    if not (math.isfinite(a) and math.isfinite(b)) or a < 0 or b <= a:
        raise GestureSimError(f"{path}:{where}: bad times {a:g}..{b:g} s "
                              "(need 0 <= start < end)")


def _text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise GestureSimError(f"cannot read {what} {path}: {why}") from None


_START = ("start", "start_s", "begin", "begin_s", "from")
_END = ("end", "end_s", "stop", "to")
_VALUE = ("sign", "value", "label", "annotation")


def read_signs_csv(path: str | Path) -> list[Span]:
    """``(start_s, end_s, sign)`` spans of a ``start,end,sign`` CSV (module docstring)."""
    p = Path(path)
    text = _text(p, "sign annotations")
    cols: tuple[int, int, int] | None = None
    out: list[Span] = []
    for n, rec in enumerate(csv.reader(text.splitlines()), start=1):
        cells = [c.strip() for c in rec]
        if not "".join(cells) or cells[0].startswith("#"):
            continue
        if cols is None:
            head = [c.lower() for c in cells]
            found = [next((i for i, h in enumerate(head) if h in names), None)
                     for names in (_START, _END, _VALUE)]
            if all(i is not None for i in found):
                cols = (found[0], found[1], found[2])   # type: ignore[assignment]
                continue
            try:
                parse_seconds(cells[0])
            except ValueError:
                raise GestureSimError(
                    f"{p}:{n}: a header needs start, end and sign columns (got "
                    f"{','.join(cells)}); or give rows start,end,sign without one") from None
            cols = (0, 1, 2)
        if len(cells) <= max(cols):
            raise GestureSimError(f"{p}:{n}: expected start,end,sign (got {len(cells)} "
                                  "column(s))")
        try:
            a, b = parse_seconds(cells[cols[0]]), parse_seconds(cells[cols[1]])
        except ValueError:
            raise GestureSimError(f"{p}:{n}: start and end must be times in seconds "
                                  f"(got {cells[cols[0]]!r}, {cells[cols[1]]!r})") from None
        _span(p, str(n), a, b)
        out.append((a, b, _sign(p, str(n), cells[cols[2]])))
    if not out:
        raise GestureSimError(f"{p}: no sign annotations in it")
    return out


def read_signs_elan(path: str | Path) -> list[Span]:
    """Spans of an ELAN tab-delimited export (every tier; the value is the sign)."""
    from gesture_sim.motion.signs import read_sign_annotations

    p = Path(path)
    text = _text(p, "sign annotations")
    first = next((ln for ln in text.splitlines() if ln.strip()), "")
    if "\t" not in first:
        raise GestureSimError(f"{p}: not an ELAN tab-delimited export (no tabs in its first "
                              "line); a start,end,sign table goes in a .signs.csv file")
    spans = [(a.start_s, a.end_s, a.sign) for a in read_sign_annotations(p)]
    if not spans:
        raise GestureSimError(f"{p}: no sign annotations in it")
    return spans


def read_signs_tier(path: str | Path, tier: str = SIGNS_TIER) -> list[Span]:
    """Spans of the non-empty intervals of a TextGrid's ``signs`` tier."""
    from gesture_sim.audio.textgrid import read_textgrid

    p = Path(path)
    grid = read_textgrid(p)
    out: list[Span] = []
    for k, iv in enumerate(grid.tier(tier), start=1):
        if not iv.text.strip():
            continue
        where = f"tier {tier!r} interval {k}"
        _span(p, f" {where}", float(iv.xmin), float(iv.xmax))
        out.append((float(iv.xmin), float(iv.xmax), _sign(p, f" {where}", iv.text)))
    if not out:
        raise GestureSimError(f"{p}: tier {tier!r} has no sign annotations")
    return out


READERS: dict[str, Callable[[Path], list[Span]]] = {
    "csv": read_signs_csv, "elan": read_signs_elan, "textgrid": read_signs_tier}


def read_sign_spans(path: str | Path, kind: str | None = None) -> list[Span]:
    """The spans of a sign annotation file (``kind``: ``"csv"``, ``"elan"``, ``"textgrid"``;
    None: by its suffix)."""
    p = Path(path)
    if kind is None:
        kind = SIGN_FILES.get(p.suffix.lower(), "elan")
    return READERS[kind](p)


def textgrid_tiers(path: Path) -> set[str]:
    from gesture_sim.audio.textgrid import read_textgrid

    return set(read_textgrid(path))


def read_textgrid_words(path: str | Path, tier: str = WORDS_TIER) -> list[Span]:
    """``(start_s, end_s, text)`` of the non-empty intervals of a TextGrid's words tier (lower
    case; pause marks such as ``sp``/``sil``/``<p:>`` left out)."""
    from gesture_sim.audio.textgrid import read_textgrid

    grid = read_textgrid(path)
    out = []
    for iv in grid.tier(tier):
        t = iv.text.strip().lower()
        if t and t not in ("sp", "sil", "<p:>", "<sil>", "#") and iv.xmax > iv.xmin:
            out.append((float(iv.xmin), float(iv.xmax), t))
    return out


# --- the folder --------------------------------------------------------------------------------


def _split(p: Path) -> tuple[str, str]:
    """(stem, role) of a file: role ``"audio"``, ``"textgrid"``, ``"transcript"``,
    ``"signs:<kind>"`` or ``""`` (not a take's file)."""
    name, suffix = p.name, p.suffix.lower()
    base = name[: len(name) - len(p.suffix)]
    if base.lower().endswith(".signs") and suffix in SIGN_FILES:
        return base[: -len(".signs")], "signs:" + SIGN_FILES[suffix]
    if suffix in AUDIO_SUFFIXES:
        return base, "audio"
    if suffix == ".textgrid":
        return base, "textgrid"
    if suffix == ".txt":
        return base, "transcript"
    return base, ""


def discover_takes(folder: str | Path) -> list[TakeFiles]:
    """The takes of ``folder`` (module docstring), by stem in sorted order.

    Raises:
        GestureSimError: no takes; a take without words or sign annotations, or with two
            sources of either; an annotation or words file without audio; two audio files of
            one stem.
    """
    root = Path(folder)
    by_stem: dict[str, dict[str, list[Path]]] = {}
    try:
        entries = sorted(root.iterdir())
    except OSError as exc:
        raise GestureSimError(f"--signs {root}: cannot list the folder: {exc.strerror}") from None
    for p in entries:
        if p.name.startswith(".") or p.name.upper().startswith("README") or not p.is_file():
            continue
        stem, role = _split(p)
        if role and stem:
            by_stem.setdefault(stem, {}).setdefault(role, []).append(p)
    takes: list[TakeFiles] = []
    for stem, roles in sorted(by_stem.items()):
        audio = roles.get("audio", [])
        if not audio:
            f = next(iter(roles.values()))[0]
            raise GestureSimError(f"{f}: no audio of take {stem!r} beside it (expected "
                                  f"{root / (stem + '.wav')} or another audio file of that stem)")
        if len(audio) > 1:
            raise GestureSimError(f"{audio[1]}: take {stem!r} has two audio files "
                                  f"({audio[0].name}, {audio[1].name}); keep one")
        grids = roles.get("textgrid", [])
        grid = grids[0] if grids else None
        tiers = textgrid_tiers(grid) if grid is not None else set()
        transcript = roles.get("transcript", [None])[0]
        if grid is not None and WORDS_TIER in tiers and transcript is not None:
            raise GestureSimError(f"{transcript}: take {stem!r} has its words twice (this "
                                  f"transcript and the {WORDS_TIER!r} tier of {grid.name}); "
                                  "keep one")
        if grid is not None and WORDS_TIER in tiers:
            words, words_kind = grid, "textgrid"
        elif transcript is not None:
            words, words_kind = transcript, "transcript"
        else:
            why = (f"; {grid.name} has no {WORDS_TIER!r} tier (tiers: "
                   f"{', '.join(sorted(tiers)) or 'none'})" if grid is not None else "")
            raise GestureSimError(
                f"{audio[0]}: no words for take {stem!r} (expected {stem}.TextGrid with a "
                f"{WORDS_TIER!r} tier or {stem}.txt, a plain transcript){why}")
        sources = [(p, role.split(":", 1)[1]) for role, ps in roles.items()
                   if role.startswith("signs:") for p in ps]
        if grid is not None and SIGNS_TIER in tiers:
            sources.append((grid, "textgrid"))
        if not sources:
            raise GestureSimError(
                f"{audio[0]}: no sign annotations for take {stem!r} (expected {stem}.signs.csv, "
                f"an ELAN export {stem}.signs.txt, or a {SIGNS_TIER!r} tier in {stem}.TextGrid)")
        if len(sources) > 1:
            names = ", ".join(p.name for p, _ in sources)
            raise GestureSimError(f"{sources[1][0]}: take {stem!r} has more than one source of "
                                  f"sign annotations ({names}); keep one")
        takes.append(TakeFiles(stem, audio[0], words, words_kind, *sources[0]))
    if not takes:
        raise GestureSimError(
            f"--signs {root}: no takes in the folder (a take is STEM.wav with STEM.TextGrid or "
            "STEM.txt and STEM.signs.csv; see gesture-sim train --help)")
    return takes


def check_take(take: TakeFiles) -> tuple[list[Span], str | None]:
    """Read the take's annotations (and a transcript's text) before any audio is analysed, so
    a bad file stops the run at once: (spans, transcript text or None)."""
    from gesture_sim import validation as v
    from gesture_sim.audio.sources import SAMPLE_RATE, check_not_silent, load_audio

    v.input_file("--signs", take.audio, "audio file")
    spans = read_sign_spans(take.signs, take.signs_kind)
    text = None
    words: list[Span] = []
    if take.words_kind == "transcript":
        text = _text(take.words, "transcript").strip()
        if not text:
            raise GestureSimError(f"{take.words}: the transcript is empty")
    else:
        words = read_textgrid_words(take.words)
    # the audio last: silence (render refuses it too) and side files of another recording
    samples, _ = load_audio(take.audio)
    check_not_silent(samples, str(take.audio), "no speech to learn the signs of")
    duration = len(samples) / SAMPLE_RATE
    for path, items, what in ((take.words, words, "word"), (take.signs, spans, "sign")):
        v.side_file_times("--signs", path,
                          sorted(((a, b, f"{what} {t[:30]!r}") for a, b, t in items),
                                 key=lambda it: (it[0] >= 0, -it[1])),
                          duration, f"the audio {take.audio.name}")
    return spans, text


def load_take(take: TakeFiles, spans: list[Span] | None = None, text: str | None = None):
    """The :class:`~gesture_sim.inference.sign_model.LabelledTake` of a take: its audio
    analysed by the prosody tracker, its words (the TextGrid's, or the transcript aligned),
    its annotations (``spans``/``text``: as :func:`check_take` read them)."""
    from gesture_sim.audio.prosody import analyze_samples
    from gesture_sim.audio.sources import SAMPLE_RATE, load_audio
    from gesture_sim.inference.sign_model import LabelledTake

    if spans is None:
        spans, text = check_take(take)
    samples, info = load_audio(take.audio)
    duration = len(samples) / SAMPLE_RATE
    late = [s for s in spans if s[0] >= duration]
    if late:
        raise GestureSimError(
            f"{take.signs}: the annotation {late[0][0]:g}..{late[0][1]:g} s {late[0][2]} starts "
            f"after the end of the audio {take.audio.name} ({duration:.2f} s)")
    if take.words_kind == "textgrid":
        words = read_textgrid_words(take.words)
    else:
        from gesture_sim.audio.phones import align_transcript

        try:
            tr = align_transcript(samples, SAMPLE_RATE, text or "")
        except GestureSimError as exc:
            raise GestureSimError(f"{take.words}: {exc}") from None
        words = [(w.start_s, w.end_s, w.text) for w in tr.words]
    an = analyze_samples(samples, info=info)
    return LabelledTake(take.name, duration, list(an.syllables), words, list(spans))
