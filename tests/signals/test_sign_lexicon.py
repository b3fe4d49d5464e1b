"""Words -> gestural signs (issue 33): lexicon hits with their times, and the part-of-speech
tagger's accuracy on hand-tagged sentences."""

from __future__ import annotations

import pytest

from gesture_sim.audio import pos
from gesture_sim.audio.phones import Word
from gesture_sim.signals.sign_lexicon import LEXICON, SIGNS, sign_cues

#: Twelve sentences tagged by hand with the Penn Treebank tag set (token/TAG; contractions split
#: as the treebank does). Spoken-style sentences with the lexicon's words in them.
HAND_TAGGED = [
    "I/PRP never/RB said/VBD that/IN all/DT of/IN them/PRP were/VBD wrong/JJ",
    "We/PRP looked/VBD at/IN everything/NN in/IN the/DT house/NN yesterday/NN",
    "You/PRP can/MD put/VB the/DT big/JJ box/NN over/IN there/RB",
    "She/PRP is/VBZ completely/RB sure/JJ about/IN it/PRP",
    "It/PRP costs/VBZ about/RB ten/CD dollars/NNS",
    "My/PRP$ brother/NN and/CC I/PRP are/VBP going/VBG to/TO the/DT city/NN",
    "Well/UH ,/, maybe/RB we/PRP should/MD stop/VB and/CC wait/VB",
    "The/DT process/NN keeps/VBZ running/VBG every/DT day/NN",
    "Yes/UH ,/, this/DT is/VBZ exactly/RB the/DT important/JJ point/NN",
    "Nobody/NN really/RB knows/VBZ how/WRB the/DT old/JJ machines/NNS worked/VBD",
    "They/PRP told/VBD me/PRP to/TO forget/VB it/PRP",
    "I/PRP do/VBP n't/RB know/VB what/WP you/PRP mean/VBP",
]
#: Six more, written after the rule tagger was frozen (its word lists were written beside
#: HAND_TAGGED, so its figure there is optimistic; this is its held-out figure).
HELD_OUT = [
    "Honestly/RB ,/, nobody/NN expected/VBD the/DT results/NNS to/TO be/VB so/RB good/JJ",
    "We/PRP have/VBP been/VBN working/VBG on/IN this/DT problem/NN for/IN years/NNS",
    "Could/MD you/PRP show/VB me/PRP the/DT other/JJ picture/NN again/RB",
    "The/DT kids/NNS were/VBD playing/VBG quietly/RB in/IN the/DT garden/NN",
    "It/PRP is/VBZ kind/NN of/IN a/DT strange/JJ feeling/NN",
    "He/PRP always/RB forgets/VBZ where/WRB he/PRP parked/VBD his/PRP$ car/NN",
]
#: Accuracy each backend must reach on (HAND_TAGGED, HELD_OUT) (measured: docs/SIGNS.md).
MIN_ACCURACY = {"brill": (0.90, 0.90), "rules": (0.85, 0.75)}


def _accuracy(backend: str, sentences: list[str]) -> float:
    right = total = 0
    for sent in sentences:
        toks, gold = zip(*(t.rsplit("/", 1) for t in sent.split()), strict=True)
        got = pos.tag_tokens(list(toks), backend)
        right += sum(g == h for g, h in zip(gold, got, strict=True))
        total += len(gold)
    return right / total


@pytest.mark.parametrize("backend", pos.BACKENDS)
def test_pos_accuracy_on_hand_tagged_sentences(backend: str) -> None:
    if backend not in pos.available_backends():
        pytest.skip(f"{backend} tagger not installed (pip install textblob)")
    for sentences, least in zip((HAND_TAGGED, HELD_OUT), MIN_ACCURACY[backend], strict=True):
        acc = _accuracy(backend, sentences)
        print(f"{backend}: {acc:.3f} on {sum(len(s.split()) for s in sentences)} tokens")
        assert acc >= least


def test_words_are_split_as_the_treebank_does() -> None:
    assert pos.split_word("don't") == ["do", "n't"]
    assert pos.split_word("I'm") == ["I", "'m"]
    assert pos.split_word("there.") == ["there", "."]
    tags = pos.tag_words(["I", "don't", "know"], "rules")
    assert tags == [("PRP",), ("VBP", "RB"), ("VB",)] or len(tags[1]) == 2


def test_lexicon_rows_name_signs_and_sources() -> None:
    assert {e.sign for e in LEXICON} <= set(SIGNS)
    assert {e.source for e in LEXICON} == {"chiu2014", "issue33", "analogy"}
    thesis = {e.phrase: e.sign for e in LEXICON if e.source == "chiu2014"}
    assert all(thesis[w] == "Whole" for w in ("all", "everything", "never", "completely"))
    assert {e.phrase for e in LEXICON if e.source == "issue33"} == {"i", "me", "my"}


def test_cues_carry_the_words_times() -> None:
    words = [Word(0.0, 0.2, "I"), Word(0.2, 0.5, "don't"), Word(0.5, 0.8, "know"),
             Word(1.0, 1.3, "whether"), Word(1.3, 1.9, "everything"), Word(1.9, 2.1, "is"),
             Word(2.1, 2.4, "over"), Word(2.4, 2.8, "there."), Word(3.0, 3.2, "My"),
             Word(3.2, 3.6, "friend")]
    cues = sign_cues(words, tagger="rules")
    got = [(c.sign, c.start_s, c.end_s, c.text) for c in cues]
    assert got == [("Shrug", 0.0, 0.8, "I don't know"),
                   ("Whole", 1.3, 1.9, "everything"),
                   ("Deictic.Other", 2.1, 2.8, "over there."),
                   ("Deictic.Self", 3.0, 3.2, "My")]
    assert cues[0].source == "chiu2014" and cues[-1].source == "issue33"
    # tuples work too, and an empty transcript gives no cues
    assert sign_cues([(0.0, 0.4, "completely")], use_pos=False)[0].sign == "Whole"
    assert sign_cues([]) == []


def test_part_of_speech_decides_that_and_about() -> None:
    said_that = [(0.0, 0.3, "he"), (0.3, 0.6, "said"), (0.6, 0.8, "that"), (0.8, 1.0, "it"),
                 (1.0, 1.2, "costs"), (1.2, 1.5, "about"), (1.5, 1.7, "ten"),
                 (1.7, 2.0, "dollars")]
    cues = sign_cues(said_that, tagger="rules")
    assert [c.text for c in cues] == ["he", "about"]      # "that" here is a complementiser
    assert cues[1].sign == "More-or-less" and cues[1].pos == ("RB",)
    loose = sign_cues(said_that, use_pos=False)
    assert "that" in [c.text for c in loose]
