"""Words and phrases that call for a gestural sign (Chiu 2014), and timed sign cues from words.

Chiu (2014, §3.2) built the 14-sign inventory from a dictionary drawn from Kipp (2004), Calbris
(2011) and Marsella et al. (2013) and then learnt words -> signs from annotated video (the DCNF).
Where no annotated data is at hand this lexicon stands in for the learnt part: a phrase in the
transcript gives a :class:`SignCue` over the phrase's time span. Each row says where it comes
from (the ``source`` of :data:`LEXICON`):

* ``"chiu2014"`` -- the thesis's Table 3.1 itself (as the project's digest of it gives): Whole
  "with 'all', 'everything', 'never', 'completely'", Shrug with the "I don't know" face.
* ``"issue33"`` -- the example of this project's issue 33: "I / me / my" -> Deictic.Self.
* ``"analogy"`` -- added here by analogy with those rows and with the kinds of rule the three
  source works are known for (pointing words -> deictics, totality -> Whole, negation -> a
  horizontal Wipe, approximation -> More-or-less, stopping -> Block, affirmation -> Head-nod,
  ongoing action -> Process, "forget it" -> Dismiss, precision -> Frame, presenting ->
  Palm-face-up).
  The digest does not list those works' own word tables, so none of these rows is quoted from
  them: treat them as this project's choices.

Some words call for a sign only as one part of speech (:attr:`Entry.pos`, Penn tag prefixes):
"that" points (DT, a demonstrative) but not as a complementiser (IN, "said that ..."), "right" and
"well" agree or present as interjections (UH/JJ) but not as "right now" (RB); the tags come from
:mod:`gesture_sim.audio.pos`. Beats and Rest have no words: they follow prosody and silence.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

#: The 14 sign names (the same tuple as :data:`gesture_sim.motion.signs.SIGNS`; the stages are
#: kept apart, the test checks they agree).
SIGNS: tuple[str, ...] = (
    "Rest", "Palm-face-up", "Head-nod", "Wipe", "Whole", "Frame", "Dismiss", "Block", "Shrug",
    "More-or-less", "Process", "Deictic.Other", "Deictic.Self", "Beats")


@dataclass(frozen=True)
class Entry:
    """One lexicon row: the words of ``phrase`` (lower case, Penn tokens joined by spaces, e.g.
    ``"do n't know"``) call for ``sign``.

    Attributes:
        phrase: the words, lower case, space separated.
        sign: one of :data:`SIGNS`.
        source: ``"chiu2014"``, ``"issue33"`` or ``"analogy"`` (module docstring).
        pos: Penn tag prefixes the phrase's first word must have (empty: any).
    """

    phrase: str
    sign: str
    source: str
    pos: tuple[str, ...] = ()


def _rows(sign: str, source: str, phrases: str, pos: tuple[str, ...] = ()) -> list[Entry]:
    return [Entry(p.strip(), sign, source, pos) for p in phrases.split("|") if p.strip()]


#: The lexicon (longest phrases are matched first).
LEXICON: tuple[Entry, ...] = tuple([
    *_rows("Whole", "chiu2014", "all|everything|never|completely"),
    *_rows("Whole", "analogy", "everyone|everybody|always|entire|entirely|whole|totally|"
                               "every single|all of them|the whole thing"),
    *_rows("Shrug", "chiu2014", "i do n't know|i dunno"),
    *_rows("Shrug", "analogy", "do n't know|who knows|maybe|perhaps|i guess|whatever|"
                               "not sure"),
    *_rows("Deictic.Self", "issue33", "i|me|my"),
    *_rows("Deictic.Self", "analogy", "mine|myself|we|us|our|ourselves"),
    *_rows("Deictic.Other", "analogy", "you|your|yours|yourself|he|she|they|them|him|her|"
                                       "over there|there|that one|this one"),
    *_rows("Deictic.Other", "analogy", "that|this|those|these", ("DT",)),
    *_rows("Wipe", "analogy", "no|not|n't|nothing|none|nobody|neither|nor|no one|no way"),
    *_rows("Block", "analogy", "stop|wait|hold on|hang on"),
    *_rows("More-or-less", "analogy", "more or less|sort of|kind of|roughly|approximately|"
                                      "somewhat|around", ()),
    *_rows("More-or-less", "analogy", "about", ("RB",)),
    *_rows("Process", "analogy", "process|continue|keep going|over and over|develop|"
                                 "going on|again and again|step by step"),
    *_rows("Dismiss", "analogy", "forget it|forget about it|get rid of|anyway|never mind"),
    *_rows("Frame", "analogy", "exactly|precisely|specifically|particular|specific|"
                               "important|the point"),
    *_rows("Head-nod", "analogy", "yes|yeah|yep|okay|ok|sure|of course|agree"),
    *_rows("Head-nod", "analogy", "right", ("UH", "JJ")),
    *_rows("Palm-face-up", "analogy", "you know|i mean|so|here is|look"),
    *_rows("Palm-face-up", "analogy", "well", ("UH",)),
])


@dataclass(frozen=True)
class SignCue:
    """A sign called for by words: ``sign`` over ``[start_s, end_s]`` (s).

    Attributes:
        start_s, end_s: the span of the words (s, the words' clock).
        sign: one of :data:`SIGNS`.
        text: the words as they were spoken.
        phrase: the lexicon phrase that matched.
        source: the lexicon row's source.
        pos: the Penn tags of the words' tokens.
    """

    start_s: float
    end_s: float
    sign: str
    text: str
    phrase: str
    source: str
    pos: tuple[str, ...] = ()


def _timed(word: Any) -> tuple[float, float, str]:
    """(start_s, end_s, text) of a :class:`gesture_sim.audio.phones.Word`-like object or a
    ``(start_s, end_s, text)`` tuple."""
    if isinstance(word, tuple | list):
        a, b, t = word
        return float(a), float(b), str(t)
    return float(word.start_s), float(word.end_s), str(word.text)


def sign_cues(words: Sequence[Any], *, lexicon: Sequence[Entry] = LEXICON,
              tagger: str | None = None, use_pos: bool = True) -> list[SignCue]:
    """Timed sign cues of timed words.

    Args:
        words: the transcript in order: :class:`gesture_sim.audio.phones.Word` objects (or
            anything with ``start_s``, ``end_s``, ``text``) or ``(start_s, end_s, text)`` tuples.
        lexicon: the rows to match (default :data:`LEXICON`).
        tagger: the POS backend of :func:`gesture_sim.audio.pos.tag_words` (default: the best
            available).
        use_pos: check the rows' part-of-speech conditions (False: ignore them, no tagging).

    Returns:
        Cues in time order, one per matched phrase; the longest phrase wins where phrases
        overlap, and each word is used once.
    """
    from gesture_sim.audio.pos import split_word, tag_words

    timed = [_timed(w) for w in words]
    texts = [t for _, _, t in timed]
    tags = tag_words(texts, tagger) if use_pos and texts else [() for _ in texts]
    # Penn tokens (lower case, punctuation dropped) with the word each came from
    toks: list[tuple[str, int, str]] = []
    for k, (t, tg) in enumerate(zip(texts, tags, strict=True)):
        pieces = split_word(t)
        ptags = list(tg) if len(tg) == len(pieces) else [""] * len(pieces)
        for p, pt in zip(pieces, ptags, strict=True):
            if any(ch.isalnum() for ch in p):
                toks.append((p.lower(), k, pt))
    by_first: dict[str, list[tuple[list[str], Entry]]] = {}
    for e in lexicon:
        w = e.phrase.split()
        by_first.setdefault(w[0], []).append((w, e))
    for v in by_first.values():
        v.sort(key=lambda item: -len(item[0]))
    cues: list[SignCue] = []
    i = 0
    while i < len(toks):
        hit = None
        for w, e in by_first.get(toks[i][0], ()):
            if [t[0] for t in toks[i:i + len(w)]] != w:
                continue
            if use_pos and e.pos and not toks[i][2].startswith(e.pos):
                continue
            hit = (w, e)
            break
        if hit is None:
            i += 1
            continue
        w, e = hit
        first, last = toks[i][1], toks[i + len(w) - 1][1]
        cues.append(SignCue(
            start_s=timed[first][0], end_s=timed[last][1], sign=e.sign,
            text=" ".join(texts[first:last + 1]), phrase=e.phrase, source=e.source,
            pos=tuple(t[2] for t in toks[i:i + len(w)])))
        # the next match starts after the last word used
        j = i + len(w)
        while j < len(toks) and toks[j][1] == last:
            j += 1
        i = j
    return cues
