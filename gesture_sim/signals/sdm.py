"""Okwechime 2011's Social Dynamics Model (thesis ch. 5): social signals, association rules
speaker => listener, and the interest dial.

**Signals** (:data:`SIGNALS`; per person, per frame, binary). The thesis labels seven kinds
(§5.1.3): voiced [V], talking [T], laughing [L], head shake [S], nod [N], body activity [A] and
gaze (at the partner [G-S] / [G-L], at the other listener [G-OL], at no one [G-N]). This module
adds ``smile`` and ``brow`` (brow raise), which the thesis does not label, because the project's
listener renders them; ``S`` is the thesis's head *shake* (not a smile). Thesis codes are accepted
as aliases (:data:`ALIASES`).

**Annotations → a signal table.** :class:`SignalTable`: ``data[person, signal, frame]`` (bool,
shape (n_persons, len(SIGNALS), n_frames)) at ``fps`` frames per second (default 25, the
thesis's video rate); frame ``k`` covers ``[k / fps, (k + 1) / fps)`` s. An interval
``[start, end)`` (s) marks every frame whose start lies in it (at least the frame containing
``start``); a point (``time``) marks the frame containing it. Two file formats:

* **CSV** (:func:`read_csv`), a header row then one annotation per row, columns in any order::

      start,end,signal,person        (intervals, s)
      time,signal,person             (points, s)

  A file may also have both ``start,end`` and ``time`` columns (empty cells where unused).
* **ELAN tab-delimited export** (:func:`read_elan`: File > Export As > Tab-delimited Text),
  one annotation per line: ``tier <TAB> [participant <TAB>] begin <TAB> end <TAB>
  [duration <TAB>] value``. Times are seconds (``12.345``) or ``hh:mm:ss.ms``. The tier names
  the person and the signal as ``person:signal`` or ``person_signal`` (``A:nod``, ``B_G-S``);
  a tier that is only a person's name takes the signal from the value (``A <TAB> 1.2 <TAB> 1.6
  <TAB> nod``). Blank lines and lines starting with ``#`` are skipped.

A bad file raises :class:`~gesture_sim.errors.GestureSimError` with one line naming the file
and the line.

**Mining** (:func:`mine`; thesis §5.1.4–5.1.5). An *instance* (transaction) is one
(speaker, listener) pair at one frame ``t`` at which the speaker talks (its ``talking`` signal;
``voiced`` if the speaker has no ``talking`` annotations; every frame if neither). Its items are
the speaker's signals at ``t`` (without ``voiced`` and ``talking``, which are always on, as in
the thesis's Table 5.3) and, by the **temporal bag** of ``s`` frames (default 10, 0.4 s at
25 fps), the listener's signals active at any frame in ``(t, t + s]``. Frames whose bag would run
past the end are not instances. Rules ``{speaker signals} => listener signal`` come from Apriori
(level-wise candidate generation with subset pruning on the speaker itemsets; anti-monotonicity
makes that complete, since ``sup(A ∪ c) <= sup(A)``):

* support (Eq. 5.1): ``sup(A => c) = sup(A ∪ {c})`` = the fraction of instances holding every
  item (0..1);
* confidence (Eq. 5.2): ``conf = sup(A ∪ {c}) / sup(A)``, an estimate of
  P(listener c within s frames | speaker A) — as a fraction 0..1 here (the thesis prints x100).

Rules below ``min_support`` or ``min_confidence`` are not returned. :func:`save_rules` /
:func:`load_rules` keep them as JSON.

**The interest dial** (:class:`ListenerTendencies`, thesis §5.3.1 and §6.4): per listener
response (:data:`RESPONSES`) a not-interested table (interest 0) and an interested table
(interest 1); :meth:`ListenerTendencies.at` interpolates between them geometrically (log-linear,
so that interest 0.5 is their geometric mean and the ratio int/not is kept). Two sources:

* :meth:`ListenerTendencies.from_thesis` (no corpus): the **published ratios of Table 5.4**
  (conf_int / conf_not, the "Avg" column) put around base rates: the table at interest ``i`` is
  ``base * ratio ** (i - 0.5)``. The default base rates are the current prosodic rule's own
  (:mod:`gesture_sim.signals.listener`; :data:`RULE_BASE_RATES`), so interest 0.5 is today's
  listener exactly. This is an adaptation, not the thesis's model: the thesis gives ratios and
  no absolute confidences for its corpus, and it has no smile or brow row (``smile`` uses the
  laugh row, 1.0; ``brow`` 1.0). The ``laugh`` response (the listener laughs back at a laugh of
  the speaker, rule [L] => [L]; the speaker's laugh is detected from its voice,
  :mod:`gesture_sim.audio.laughter`) has Table 5.4's [L] row, 1.0: laughing does not
  discriminate interest in the thesis.
* :meth:`ListenerTendencies.from_rules` (a user's corpus): the tables are the mean confidences
  of the single-antecedent rules ``speaker X => listener response`` mined from the user's
  interested and not-interested annotations (the Avg column of Table 5.4, computed on their
  data).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.units import parse_seconds

__all__ = [
    "ALIASES", "DEFAULT_BAG", "DEFAULT_FPS", "RESPONSES", "RULE_BASE_RATES", "SIGNALS",
    "TABLE_5_4_AVG", "ListenerTendencies", "Rule", "SignalTable", "canonical_signal",
    "load_rules", "mine", "read_annotations", "read_csv", "read_elan", "save_rules",
    "transactions",
]

#: The signals of a person (columns of :attr:`SignalTable.data`).
SIGNALS: tuple[str, ...] = (
    "voiced", "talking", "laugh", "smile", "shake", "nod", "brow", "activity",
    "gaze_partner", "gaze_other", "gaze_none",
)
#: Other accepted spellings (the thesis's codes, case-insensitive) -> a signal of SIGNALS.
ALIASES: dict[str, str] = {
    "v": "voiced", "t": "talking", "l": "laugh", "s": "shake", "n": "nod", "a": "activity",
    "g-s": "gaze_partner", "g-l": "gaze_partner", "gaze": "gaze_partner",
    "gaze_at": "gaze_partner", "gaze_speaker": "gaze_partner", "gaze_listener": "gaze_partner",
    "g-ol": "gaze_other", "g-n": "gaze_none", "headshake": "shake", "head_shake": "shake",
    "laughing": "laugh", "talk": "talking", "voice": "voiced", "brow_raise": "brow",
    "posture": "activity",
}
#: The thesis's video rate (frames/s) and temporal bag (frames).
DEFAULT_FPS = 25.0
DEFAULT_BAG = 10
#: Listener responses the dial sets (the project's listener renders these).
RESPONSES: tuple[str, ...] = ("nod", "smile", "brow", "voiced", "gaze_partner", "activity",
                              "laugh")
#: Table 5.4's "Avg" column: conf_int / conf_not of single-antecedent rules per listener
#: response (thesis §5.3.1). ``smile`` and ``brow`` have no row: 1.0 (smile: the laugh row).
TABLE_5_4_AVG: dict[str, float] = {
    "voiced": 1.5, "talking": 4.6, "laugh": 1.0, "shake": 1.2, "nod": 1.7, "activity": 1.1,
    "gaze_partner": 1.0, "gaze_other": 0.9, "gaze_none": 1.1, "smile": 1.0, "brow": 1.0,
}
#: The prosodic rule's own response probabilities (ListenerConfig defaults): ``nod`` = the
#: backchannel probability at an invited opportunity (``p_invited``; ``p_other`` scales with
#: it), ``brow`` = ``p_brow`` (per nod), ``voiced`` = ``p_voiced`` (per nod; the rule has no
#: voiced backchannel without the dial: an assumed base), ``activity`` = posture shifts per
#: minute of partner speech (60 / the mean gap of 14 s), ``gaze_partner`` = the attentive
#: posture's weight (1 = always while listening), ``smile`` = none rendered (0), ``laugh`` =
#: the probability that the listener laughs back (smile + small head and trunk bobs) at a laugh
#: it hears from the speaker (``ListenerConfig.p_laugh_back``; it always smiles). The thesis
#: finds speaker [L] => listener [L] with a large confidence in both its interested and
#: not-interested data (§5.3.1; Table 5.4's [L] row averages 1.0, so the dial leaves it alone)
#: but prints no absolute value: 0.5 is an assumed base.
#: Measured with ``tools/listener_figures.py`` (10 seeds): the rule as it is nods 29.9 times
#: per minute of partner speech on the two-voice test dialogue (pauses every few seconds; 50 %
#: at inviting pauses, 1 % after questions) and 7.9 per minute on a real 64 s BEAT2 take (86 %
#: in pauses); with the dial, interest 0 -> 1 moves those to 22.5 -> 33.8 and 6.0 -> 8.5.
RULE_BASE_RATES: dict[str, float] = {
    "nod": 0.9, "smile": 0.0, "brow": 0.35, "voiced": 0.3, "gaze_partner": 1.0,
    "activity": 60.0 / 14.0, "laugh": 0.5,
}
_SPEAKER_SKIP = ("voiced", "talking")
_SIG_INDEX = {s: i for i, s in enumerate(SIGNALS)}


def canonical_signal(name: str) -> str | None:
    """The :data:`SIGNALS` name of ``name`` (a signal, or an alias), or None if unknown."""
    key = name.strip().lower().replace(" ", "_")
    if key in _SIG_INDEX:
        return key
    return ALIASES.get(key)


# ---------------------------------------------------------------------- the table

@dataclass
class SignalTable:
    """Time-aligned binary signals.

    Attributes:
        fps: frames per second; frame ``k`` covers ``[k / fps, (k + 1) / fps)`` s.
        persons: person names, in the order of ``data``'s first axis.
        data: bool (len(persons), len(SIGNALS), n_frames).
        annotated: bool (len(persons), len(SIGNALS)): whether the person has any annotation
            of that signal (an unannotated ``talking`` is not "never talks").
    """

    fps: float
    persons: tuple[str, ...]
    data: np.ndarray
    annotated: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.annotated is None:
            self.annotated = self.data.any(axis=2)

    @property
    def n_frames(self) -> int:
        return int(self.data.shape[2])

    def signal(self, person: str, name: str) -> np.ndarray:
        """Bool (n_frames,) of ``person``'s signal ``name``."""
        if person not in self.persons:
            raise GestureSimError(f"no person {person!r} in the table (it has "
                                  f"{', '.join(self.persons)})")
        sig = canonical_signal(name)
        if sig is None:
            raise GestureSimError(f"unknown signal {name!r} (known: {', '.join(SIGNALS)})")
        return self.data[self.persons.index(person), _SIG_INDEX[sig]]

    @classmethod
    def from_intervals(cls, rows: Iterable[tuple[str, str, float, float | None]],
                       fps: float = DEFAULT_FPS, n_frames: int | None = None,
                       persons: Sequence[str] | None = None) -> SignalTable:
        """A table from ``(person, signal, start s, end s or None for a point)`` rows."""
        rows = list(rows)
        names = list(persons) if persons is not None else []
        for p, _, _, _ in rows:
            if p not in names:
                names.append(p)
        last = 0.0
        for _, _, a, b in rows:
            last = max(last, a if b is None else b)
        n = int(n_frames) if n_frames is not None else int(math.floor(last * fps)) + 1
        data = np.zeros((len(names), len(SIGNALS), n), bool)
        ann = np.zeros((len(names), len(SIGNALS)), bool)
        for p, s, a, b in rows:
            i, j = names.index(p), _SIG_INDEX[s]
            ann[i, j] = True
            k0 = int(math.floor(a * fps + 1e-9))
            if b is None:
                k1 = k0 + 1
            else:
                k1 = max(int(math.ceil(b * fps - 1e-9)), k0 + 1)
            data[i, j, max(k0, 0):min(k1, n)] = True
        return cls(float(fps), tuple(names), data, ann)


def _check_interval(path: Path, line: int, a: float, b: float | None) -> None:
    if not math.isfinite(a) or a < 0 or (b is not None and (not math.isfinite(b) or b < a)):
        raise GestureSimError(f"{path}: line {line}: bad times (need 0 <= start <= end)")


def read_csv(path: str | Path, fps: float = DEFAULT_FPS) -> SignalTable:
    """A :class:`SignalTable` from a CSV of annotations (module docstring).

    Raises:
        GestureSimError: unreadable file, missing columns, a bad time or an unknown signal
            (one line naming the file and the line).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise GestureSimError(f"cannot read annotations {path}: {exc}") from None
    reader = csv.reader(text.splitlines())
    header: list[str] | None = None
    rows: list[tuple[str, str, float, float | None]] = []
    for line, rec in enumerate(reader, start=1):
        if not rec or not "".join(rec).strip() or rec[0].lstrip().startswith("#"):
            continue
        if header is None:
            header = [h.strip().lower() for h in rec]
            if "signal" not in header or "person" not in header or not (
                    "time" in header or ("start" in header and "end" in header)):
                raise GestureSimError(f"{path}: line {line}: the header needs signal, person "
                                      "and time or start,end columns")
            continue
        cell = {h: (rec[i].strip() if i < len(rec) else "") for i, h in enumerate(header)}
        sig = canonical_signal(cell["signal"])
        if sig is None:
            raise GestureSimError(f"{path}: line {line}: unknown signal {cell['signal']!r} "
                                  f"(known: {', '.join(SIGNALS)})")
        if not cell["person"]:
            raise GestureSimError(f"{path}: line {line}: no person")
        try:
            if cell.get("start") and cell.get("end"):
                a, b = parse_seconds(cell["start"]), parse_seconds(cell["end"])
            elif cell.get("time"):
                a, b = parse_seconds(cell["time"]), None
            else:
                raise ValueError("no time")
        except ValueError:
            raise GestureSimError(f"{path}: line {line}: bad or missing time") from None
        _check_interval(path, line, a, b)
        rows.append((cell["person"], sig, a, b))
    if header is None:
        raise GestureSimError(f"{path}: line 1: empty annotation file")
    if not rows:
        raise GestureSimError(f"{path}: line {line}: no annotations")
    return SignalTable.from_intervals(rows, fps)


def _tier(tier: str, value: str) -> tuple[str, str | None]:
    """(person, signal or None) from an ELAN tier name and value."""
    for sep in (":", "_", " ", "-"):
        if sep in tier:
            head, tail = tier.split(sep, 1)
            sig = canonical_signal(tail)
            if sig is not None and head.strip():
                return head.strip(), sig
    return tier.strip(), canonical_signal(value) if value else None


def read_elan(path: str | Path, fps: float = DEFAULT_FPS) -> SignalTable:
    """A :class:`SignalTable` from an ELAN tab-delimited export (module docstring).

    Raises:
        GestureSimError: unreadable file, too few columns, a bad time or an unknown
            tier/signal (one line naming the file and the line).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise GestureSimError(f"cannot read annotations {path}: {exc}") from None
    rows: list[tuple[str, str, float, float | None]] = []
    last_line = 0
    for line, raw in enumerate(text.splitlines(), start=1):
        last_line = line
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        cols = [c.strip() for c in raw.split("\t")]
        if len(cols) < 3:
            raise GestureSimError(f"{path}: line {line}: need tier, begin, end[, value] "
                                  "separated by tabs")
        times: list[float] = []
        rest: list[str] = []
        for c in cols[1:]:
            try:
                times.append(parse_seconds(c))
            except ValueError:
                if times:
                    rest.append(c)
                elif not rest:          # the participant column before the times
                    rest.append("")
        value = rest[-1] if rest and rest[-1] else ""
        if len(times) < 2:
            raise GestureSimError(f"{path}: line {line}: need a begin and an end time")
        a, b = times[0], times[1]
        _check_interval(path, line, a, b)
        person, sig = _tier(cols[0], value)
        if sig is None:
            raise GestureSimError(f"{path}: line {line}: tier {cols[0]!r} value {value!r} "
                                  f"names no signal (known: {', '.join(SIGNALS)})")
        rows.append((person, sig, a, b))
    if not rows:
        raise GestureSimError(f"{path}: line {max(last_line, 1)}: no annotations")
    return SignalTable.from_intervals(rows, fps)


def read_annotations(path: str | Path, fps: float = DEFAULT_FPS) -> SignalTable:
    """:func:`read_csv` for ``.csv`` files, :func:`read_elan` otherwise."""
    return read_csv(path, fps) if Path(path).suffix.lower() == ".csv" else read_elan(path, fps)


# ---------------------------------------------------------------------- mining

@dataclass(frozen=True)
class Rule:
    """One association rule ``{speaker antecedent} => listener consequent``.

    Attributes:
        antecedent: speaker signals (sorted names of SIGNALS), 1..max_antecedent of them.
        consequent: the listener signal.
        support: Eq. 5.1, fraction of instances (0..1).
        confidence: Eq. 5.2, fraction (0..1): P(consequent within the bag | antecedent).
        count: instances holding antecedent and consequent; antecedent_count: holding the
            antecedent.
    """

    antecedent: tuple[str, ...]
    consequent: str
    support: float
    confidence: float
    count: int
    antecedent_count: int

    def __str__(self) -> str:
        return (f"{{{', '.join(self.antecedent)}}} => {self.consequent} "
                f"(sup {self.support:.4f}, conf {self.confidence:.3f})")


def transactions(table: SignalTable, speaker: str, listener: str, bag: int = DEFAULT_BAG
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The instances of one (speaker, listener) pair (module docstring).

    Returns:
        (speaker items bool (n, len(SIGNALS)) — ``voiced``/``talking`` columns all False —,
        listener items bool (n, len(SIGNALS)): the listener's signals in (t, t + bag]).
    """
    if bag < 1:
        raise GestureSimError(f"the temporal bag must be at least 1 frame (got {bag})")
    si = table.persons.index(speaker)
    li = table.persons.index(listener)
    n = table.n_frames
    sp = table.data[si]
    if table.annotated[si, _SIG_INDEX["talking"]]:
        active = sp[_SIG_INDEX["talking"]].copy()
    elif table.annotated[si, _SIG_INDEX["voiced"]]:
        active = sp[_SIG_INDEX["voiced"]].copy()
    else:
        active = np.ones(n, bool)
    active[max(n - bag, 0):] = False
    frames = np.flatnonzero(active)
    spk = sp[:, frames].T.copy()
    for s in _SPEAKER_SKIP:
        spk[:, _SIG_INDEX[s]] = False
    lis = table.data[li].astype(np.int32)
    csum = np.concatenate([np.zeros((lis.shape[0], 1), np.int32), np.cumsum(lis, axis=1)],
                          axis=1)
    # any listener frame in (t, t + bag]: csum[t + bag + 1] - csum[t + 1] > 0
    lst = (csum[:, frames + bag + 1] - csum[:, frames + 1] > 0).T
    return spk, lst


def _apriori(items: np.ndarray, min_count: int, max_len: int) -> dict[tuple[int, ...], int]:
    """Frequent itemsets of the columns of ``items`` (bool (n, m)): {sorted column tuple: count}
    with count >= ``min_count`` and length <= ``max_len`` (level-wise, join + subset prune)."""
    counts = items.sum(axis=0)
    level = {(j,): int(counts[j]) for j in range(items.shape[1]) if counts[j] >= min_count}
    out = dict(level)
    g = 1
    while level and g < max_len:
        keys = sorted(level)
        cand: set[tuple[int, ...]] = set()
        for a, b in itertools.combinations(keys, 2):
            if a[:-1] == b[:-1]:
                c = a + (b[-1],) if a[-1] < b[-1] else b + (a[-1],)
                if all(sub in level for sub in itertools.combinations(c, g)):
                    cand.add(c)
        nxt = {}
        for c in sorted(cand):
            cnt = int(np.count_nonzero(items[:, list(c)].all(axis=1)))
            if cnt >= min_count:
                nxt[c] = cnt
        out.update(nxt)
        level = nxt
        g += 1
    return out


def mine(table: SignalTable, min_support: float = 0.005, min_confidence: float = 0.0,
         bag: int = DEFAULT_BAG, max_antecedent: int = 4,
         pairs: Sequence[tuple[str, str]] | None = None) -> list[Rule]:
    """Apriori rules speaker => listener over every (speaker, listener) pair (module
    docstring); instances of all pairs are pooled (person-independent, as the thesis).

    Args:
        min_support: minimum support (fraction 0..1 of instances) of antecedent ∪ consequent.
            The thesis's "0.5" is read as 0.5 % (digest §4.5): the default 0.005.
        min_confidence: minimum confidence (fraction 0..1).
        bag: the temporal bag ``s`` (frames).
        max_antecedent: longest antecedent (the thesis found up to 4).
        pairs: (speaker, listener) person pairs; default every ordered pair of the table.

    Returns:
        Rules sorted by consequent, then antecedent length, then descending confidence.
    """
    if not 0.0 <= min_support <= 1.0 or not 0.0 <= min_confidence <= 1.0:
        raise GestureSimError("min support and min confidence are fractions 0..1")
    if pairs is None:
        pairs = [(a, b) for a in table.persons for b in table.persons if a != b]
    spk_l, lst_l = [], []
    for sp, li in pairs:
        s, q = transactions(table, sp, li, bag)
        spk_l.append(s)
        lst_l.append(q)
    spk = np.concatenate(spk_l) if spk_l else np.zeros((0, len(SIGNALS)), bool)
    lst = np.concatenate(lst_l) if lst_l else np.zeros((0, len(SIGNALS)), bool)
    n = len(spk)
    if n == 0:
        return []
    min_count = max(int(math.ceil(min_support * n - 1e-9)), 1)
    frequent = _apriori(spk, min_count, max_antecedent)
    rules: list[Rule] = []
    for ante, a_cnt in frequent.items():
        rows = spk[:, list(ante)].all(axis=1)
        both = lst[rows].sum(axis=0)
        for j in range(len(SIGNALS)):
            cnt = int(both[j])
            conf = cnt / a_cnt
            if cnt >= min_count and conf >= min_confidence - 1e-12:
                rules.append(Rule(tuple(SIGNALS[i] for i in ante), SIGNALS[j], cnt / n, conf,
                                  cnt, a_cnt))
    rules.sort(key=lambda r: (r.consequent, len(r.antecedent), -r.confidence, r.antecedent))
    return rules


def save_rules(path: str | Path, rules: Sequence[Rule], **meta: object) -> None:
    """Write ``rules`` (and JSON-able ``meta``: fps, bag, interest, source) as JSON.

    An OSError of the write (a full disk) passes through: the command writes a temporary
    (:func:`gesture_sim.fileio.atomic_path`), whose error names the output, not the
    temporary."""
    doc = {"format": "gesture_sim.sdm.rules/1", "meta": meta,
           "rules": [asdict(r) for r in rules]}
    Path(path).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


def load_rules(path: str | Path) -> list[Rule]:
    """The rules of :func:`save_rules`.

    Raises:
        GestureSimError: unreadable or not a rules file.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format") != "gesture_sim.sdm.rules/1":
            raise ValueError("not a gesture_sim rules file")
        return [Rule(tuple(r["antecedent"]), str(r["consequent"]), float(r["support"]),
                     float(r["confidence"]), int(r["count"]), int(r["antecedent_count"]))
                for r in doc["rules"]]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise GestureSimError(f"cannot read rules {path}: {exc}") from None


# ---------------------------------------------------------------------- interest

@dataclass(frozen=True)
class ListenerTendencies:
    """The not-interested and interested tables of listener responses.

    Attributes:
        not_interested, interested: {response of RESPONSES: rate} at interest 0 and 1. Rates
            are probabilities (per opportunity / per nod) or, for ``activity``, a rate per
            minute; each is used relative to its own base by :meth:`scale`.
        source: ``"thesis Table 5.4 around the rule's base rates"`` or ``"mined rules"``.
    """

    not_interested: dict[str, float]
    interested: dict[str, float]
    source: str = ""

    @classmethod
    def from_thesis(cls, base: dict[str, float] | None = None,
                    ratios: dict[str, float] | None = None) -> ListenerTendencies:
        """No corpus: ``base * ratio ** (i - 0.5)`` at interest ``i`` (ratios: Table 5.4's
        Avg column, :data:`TABLE_5_4_AVG`; base: :data:`RULE_BASE_RATES`, the current rule's
        own rates). Probabilities are not clipped here (:meth:`at` clips them)."""
        base = dict(RULE_BASE_RATES if base is None else base)
        ratios = dict(TABLE_5_4_AVG if ratios is None else ratios)
        lo = {r: base.get(r, 0.0) / math.sqrt(ratios.get(r, 1.0)) for r in RESPONSES}
        hi = {r: base.get(r, 0.0) * math.sqrt(ratios.get(r, 1.0)) for r in RESPONSES}
        return cls(lo, hi, "thesis Table 5.4 ratios around the rule's base rates")

    @classmethod
    def from_rules(cls, interested: Sequence[Rule], not_interested: Sequence[Rule]
                   ) -> ListenerTendencies:
        """A user's corpus: per response, the mean confidence of its single-antecedent rules
        (speaker signals present in both sets; a response without rules in one set keeps the
        other's value, so ratio 1)."""
        def table(rules: Sequence[Rule]) -> dict[str, dict[str, float]]:
            out: dict[str, dict[str, float]] = {}
            for r in rules:
                if len(r.antecedent) == 1:
                    out.setdefault(r.consequent, {})[r.antecedent[0]] = r.confidence
            return out

        ti, tn = table(interested), table(not_interested)
        lo, hi = {}, {}
        for resp in RESPONSES:
            a, b = ti.get(resp, {}), tn.get(resp, {})
            common = sorted(set(a) & set(b))
            if common:
                hi[resp] = float(np.mean([a[s] for s in common]))
                lo[resp] = float(np.mean([b[s] for s in common]))
            else:
                v = float(np.mean(list(a.values()) or list(b.values()) or [0.0]))
                hi[resp] = lo[resp] = v
        return cls(lo, hi, "mined rules")

    def at(self, interest: float) -> dict[str, float]:
        """{response: rate} at ``interest`` (clipped to 0..1): geometric interpolation
        ``lo ** (1 - i) * hi ** i`` (linear where either is 0); probabilities (every
        response but ``activity``) clipped to 1."""
        i = min(max(float(interest), 0.0), 1.0)
        out = {}
        for r in RESPONSES:
            lo, hi = self.not_interested.get(r, 0.0), self.interested.get(r, 0.0)
            v = lo ** (1.0 - i) * hi ** i if lo > 0 and hi > 0 else (1.0 - i) * lo + i * hi
            out[r] = v if r == "activity" else min(v, 1.0)
        return out

    def scale(self, interest: float) -> dict[str, float]:
        """{response: factor} relative to the tables' geometric middle (interest 0.5),
        unclipped: ``(hi / lo) ** (i - 0.5)``; 1.0 exactly at interest 0.5 and for a response
        whose tables agree (or hold a 0)."""
        i = min(max(float(interest), 0.0), 1.0)
        out = {}
        for r in RESPONSES:
            lo, hi = self.not_interested.get(r, 0.0), self.interested.get(r, 0.0)
            out[r] = (hi / lo) ** (i - 0.5) if lo > 0 and hi > 0 and hi != lo else 1.0
        return out

    def ratios(self) -> dict[str, float]:
        """{response: interested / not interested} (1.0 where undefined)."""
        return {r: (self.interested[r] / self.not_interested[r]
                    if self.not_interested.get(r, 0) > 0 else 1.0) for r in RESPONSES}

