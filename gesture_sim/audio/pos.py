"""Part-of-speech tags for transcript words (Penn Treebank tag set), with no download at run time.

Chiu (2014) feeds the DCNF word-level POS tags from an NLTK tagger; NLTK's taggers need the
``nltk_data`` download, which this project cannot make. Two tagger backends:

* ``"brill"`` (preferred): the Brill-style tagger of Pattern (De Smedt & Daelemans 2012) as
  vendored in the ``textblob`` wheel on PyPI -- a 100 k-word lexicon of Penn tags
  (``textblob/en/en-lexicon.txt``), Brill's lexical (suffix) rules for unknown words
  (``en-morphology.txt``) and contextual rules (``en-context.txt``), all files inside the wheel;
  nothing is downloaded (what ``textblob.en.parser.find_tags`` runs; TextBlob's own default
  tagger needs nltk_data and is not used). Installed with ``pip install textblob`` (MIT; it
  brings ``nltk``, which is neither imported here nor needs its data).
* ``"rules"`` (fallback, always there): closed-class word lists (pronouns, determiners,
  prepositions, conjunctions, auxiliaries, modals, common adverbs, interjections), suffix rules
  (``-ly`` RB, ``-ing`` VBG, ``-ed`` VBD, ``-s`` NNS, ``-tion``/``-ment``/``-ness`` NN,
  ``-ous``/``-ful``/``-ive``/``-able``/``-al`` JJ), three context rules (after ``to`` / a modal:
  VB; after a pronoun subject: verb form) and NN for the rest. A small hand-written tagger.

Accuracy of both on the hand-tagged sentences of ``tests/signals/test_sign_lexicon.py`` is
measured there (docs/SIGNS.md gives the figures).

Tokens: a transcript word such as ``"don't"`` is split as the Penn Treebank does (``do`` +
``n't``) for tagging; :func:`tag_words` gives each word the tags of its pieces.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from functools import lru_cache

#: The backends, in order of preference.
BACKENDS: tuple[str, ...] = ("brill", "rules")

_CONTRACTIONS = re.compile(r"(?i)^(.+?)(n't|'s|'re|'ve|'ll|'d|'m)$")


def split_word(word: str) -> list[str]:
    """Penn Treebank tokens of one transcript word (``"don't"`` -> ``["do", "n't"]``,
    ``"can't"`` -> ``["ca", "n't"]``, ``"I'm"`` -> ``["I", "'m"]``); punctuation around the word
    is split off."""
    w = word.strip().replace("\u2019", "'")
    if not w:
        return []
    lead = re.match(r"^[\"(\[]+", w)
    trail = re.search(r"[\"')\].,!?;:]+$", w)
    pre = list(lead.group(0)) if lead else []
    post = list(trail.group(0)) if trail and trail.group(0) != w else []
    core = w[len(lead.group(0)) if lead else 0: len(w) - len(trail.group(0))
             if trail and trail.group(0) != w else len(w)]
    m = _CONTRACTIONS.match(core)
    pieces = [m.group(1), m.group(2)] if m and len(m.group(1)) > 0 else [core]
    return [*pre, *[p for p in pieces if p], *post]


@lru_cache(maxsize=1)
def _brill():
    """The Pattern parser of the ``textblob`` wheel (its lexicon and rule files), or ``None``
    when textblob is not installed.

    ``textblob/_text.py`` (Pattern's tagger, standard library only) is loaded on its own from
    the installed package, without running ``textblob/__init__`` (which imports all of NLTK,
    4 s): the same code and files as ``textblob.en.parser.find_tags``.
    """
    import importlib.util
    from pathlib import Path

    spec = importlib.util.find_spec("textblob")
    if spec is None or not spec.submodule_search_locations:
        return None
    root = Path(next(iter(spec.submodule_search_locations)))
    en = root / "en"
    if not (root / "_text.py").is_file() or not (en / "en-lexicon.txt").is_file():
        return None
    text_spec = importlib.util.spec_from_file_location("_gesture_sim_pattern_text",
                                                       root / "_text.py")
    module = importlib.util.module_from_spec(text_spec)
    text_spec.loader.exec_module(module)
    lexicon = module.Lexicon(path=str(en / "en-lexicon.txt"),
                             morphology=str(en / "en-morphology.txt"),
                             context=str(en / "en-context.txt"),
                             entities=str(en / "en-entities.txt"), language="en")
    return module.Parser(lexicon=lexicon, default=("NN", "NNP", "CD"), language="en")


def available_backends() -> tuple[str, ...]:
    """The backends that can run here, in order of preference."""
    return tuple(b for b in BACKENDS if b != "brill" or _brill() is not None)


# --- the fallback: closed classes + suffixes -----------------------------------------------

_CLOSED: dict[str, str] = {}
for _tag, _words in {
    "PRP": "i me you he him she her it we us they them myself yourself himself herself itself "
           "ourselves themselves",
    "PRP$": "my your his its our their",
    "DT": "the a an this that these those all every each some any no another both either "
          "neither",
    "IN": "of in on at by for with from into onto about over under between through during "
          "before after since until against among without within upon because if whether "
          "than though although while like near",
    "TO": "to",
    "CC": "and or but nor yet",
    "MD": "can could will would shall should may might must ca wo",
    "VBZ": "is has does 's",
    "VBP": "are am have do 're 'm 've",
    "VBD": "was were had did said told got went made came took knew thought",
    "VB": "be",
    "VBN": "been done gone seen known",
    "VBG": "being",
    "RB": "not n't never always very really quite just also too so then now here there again "
          "maybe perhaps almost already still even ever often sometimes soon only well",
    "WP": "what who whom",
    "WRB": "how when where why",
    "WDT": "which",
    "UH": "yes yeah yep no oh okay ok uh um hmm wow hey",
    "EX": "",
    "NN": "everything everyone everybody nothing nobody someone somebody anything anyone "
          "something yesterday today tomorrow",
    "CD": "one two three four five six seven eight nine ten hundred thousand million",
    "JJ": "other same such own",
}.items():
    for _w in _words.split():
        _CLOSED.setdefault(_w, _tag)
_SUFFIX_RULES: tuple[tuple[str, str], ...] = (
    ("ness", "NN"), ("ment", "NN"), ("tion", "NN"), ("sion", "NN"), ("ity", "NN"),
    ("ous", "JJ"), ("ful", "JJ"), ("ive", "JJ"), ("able", "JJ"), ("ible", "JJ"), ("al", "JJ"),
    ("less", "JJ"), ("ly", "RB"), ("ing", "VBG"), ("ed", "VBD"), ("ss", "NN"), ("s", "NNS"),
)
_PUNCT = {",": ",", ".": ".", "?": ".", "!": ".", ";": ":", ":": ":", "\"": "``", "(": "(",
          ")": ")"}


def _rules_tag(tokens: Sequence[str]) -> list[str]:
    out: list[str] = []
    for k, tok in enumerate(tokens):
        low = tok.lower()
        prev = out[-1] if out else ""
        prev_tok = tokens[k - 1].lower() if k else ""
        if tok in _PUNCT:
            tag = _PUNCT[tok]
        elif re.fullmatch(r"[\d.,]+", tok):
            tag = "CD"
        elif low in _CLOSED:
            tag = _CLOSED[low]
            if low == "that" and prev.startswith(("VB", "NN")):
                tag = "IN"
            if low == "about" and k + 1 < len(tokens) and (
                    re.fullmatch(r"[\d.,]+", tokens[k + 1])
                    or _CLOSED.get(tokens[k + 1].lower()) == "CD"):
                tag = "RB"
        elif prev in ("TO", "MD"):
            tag = "VB"
        elif k > 0 and tok[:1].isupper():
            tag = "NNP"
        else:
            tag = next((t for suf, t in _SUFFIX_RULES if low.endswith(suf) and len(low) > len(suf)
                        + 2), "NN")
            if tag == "NNS" and prev in ("PRP", "NN", "NNP") and prev_tok not in ("the", "a"):
                tag = "VBZ"
            elif tag == "NN" and prev in ("PRP", "WP") and prev_tok != "it":
                tag = "VBP"
            elif tag == "VBD" and prev in ("VBZ", "VBP", "VBD") and prev_tok in (
                    "has", "have", "had", "is", "are", "was", "were", "'s", "'ve"):
                tag = "VBN"
        out.append(tag)
    return out


def tag_tokens(tokens: Sequence[str], backend: str | None = None) -> list[str]:
    """Penn tags of Penn tokens (one per token), by ``backend`` (default: the first of
    :func:`available_backends`).

    Raises:
        ValueError: an unknown or unavailable backend.
    """
    backend = backend or available_backends()[0]
    if backend not in available_backends():
        raise ValueError(f"POS backend {backend!r} is not available here "
                         f"({', '.join(available_backends())})")
    toks = [str(t) for t in tokens]
    if not toks:
        return []
    if backend == "brill":
        return [str(t[1]) for t in _brill().find_tags(toks)]
    return _rules_tag(toks)


def tag_words(words: Sequence[str], backend: str | None = None) -> list[tuple[str, ...]]:
    """Penn tags of transcript words: for each word the tags of its tokens (:func:`split_word`),
    the sentence tagged as a whole so the context rules see the neighbours."""
    pieces = [split_word(w) for w in words]
    flat = [p for ps in pieces for p in ps]
    tags = tag_tokens(flat, backend)
    out, k = [], 0
    for ps in pieces:
        out.append(tuple(tags[k:k + len(ps)]))
        k += len(ps)
    return out
