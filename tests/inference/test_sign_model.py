"""The sign predictor (Chiu 2014's DCNF over gestural signs): training recovers a planted word ->
sign mapping, Viterbi is exact, the causal filter meets the exact marginal, save/load, and the
live filter sees a word only once it has been said."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from gesture_sim.contracts import Syllable
from gesture_sim.inference import sign_model as sm

WORDS_ONLY = sm.SignModelSettings(prosody=False, pos=False, lexicon=False, context=0,
                                  min_count=1, lexicon_weight=0.0, l2=0.01,
                                  prior_weight=0.05, bias_weight=0.1)


def _planted(n_frames: int, seed: int) -> tuple[list, list, np.ndarray]:
    """Words one per 1-s frame: "alpha" in Whole frames, "beta" in Frame frames, filler in Beats
    frames; runs of 2-4 frames."""
    rng = np.random.default_rng(seed)
    labels, words = [], []
    k = 0
    while k < n_frames:
        sign = rng.choice(["Whole", "Frame", "Beats", "Beats"])
        for _ in range(int(rng.integers(2, 5))):
            if k >= n_frames:
                break
            word = {"Whole": "alpha", "Frame": "beta"}.get(sign) or str(rng.choice(
                ["the", "and", "then", "we", "it"]))
            words.append((k + 0.2, k + 0.6, word))
            labels.append(sm.SIGN_INDEX[sign])
            k += 1
    spans = [(i, i + 1.0, sm.SIGNS[y]) for i, y in enumerate(labels)]
    return words, spans, np.array(labels)


def test_training_recovers_a_planted_word_to_sign_mapping() -> None:
    words, spans, _ = _planted(60, 0)
    take = sm.LabelledTake("planted", 60.0, [], words, spans)
    model = sm.train_on_takes([take], WORDS_ONLY, tagger="rules")
    test_words, _, truth = _planted(40, 1)
    x = sm.frame_inputs(model.layout, 40.0, (), test_words, tagger="rules")
    pred = model.decode(x)
    assert np.mean(pred == truth) >= 0.9
    for sign in ("Whole", "Frame"):                      # the planted words' own signs
        i = sm.SIGN_INDEX[sign]
        assert np.mean(pred[truth == i] == i) >= 0.7
    assert "alpha" in model.layout.vocabulary and "beta" in model.layout.vocabulary
    assert model.info["frames"] == 60


def _brute(unary, trans, trans2=None):
    n, s = unary.shape
    best, arg = -np.inf, None
    for path in itertools.product(range(s), repeat=n):
        v = sum(unary[t, q] for t, q in enumerate(path))
        v += sum(trans[a, b] for a, b in zip(path[:-1], path[1:], strict=True))
        if trans2 is not None:
            v += sum(trans2[a, b, c] for a, b, c in zip(path, path[1:], path[2:], strict=False))
        if v > best:
            best, arg = v, path
    return np.array(arg)


@pytest.mark.parametrize("order", [1, 2])
def test_viterbi_is_exact(order: int) -> None:
    rng = np.random.default_rng(order)
    for _ in range(5):
        u, tr = rng.normal(size=(5, 3)), rng.normal(size=(3, 3))
        t2 = rng.normal(size=(3, 3, 3)) if order == 2 else None
        np.testing.assert_array_equal(sm.viterbi(u, tr, t2), _brute(u, tr, t2))


def test_viterbi_decodes_a_planted_sequence_through_noise() -> None:
    rng = np.random.default_rng(3)
    truth = np.repeat([13, 4, 13, 0, 5], 6)
    u = rng.normal(0, 1.0, size=(len(truth), sm.N_SIGNS))
    u[np.arange(len(truth)), truth] += 2.0
    sticky = np.log(np.full((sm.N_SIGNS, sm.N_SIGNS), 0.1 / 13) + np.eye(sm.N_SIGNS) * 0.9)
    path = sm.viterbi(u, sticky)
    assert np.mean(path == truth) > 0.9
    assert np.mean(u.argmax(axis=1) == truth) < np.mean(path == truth)   # the chain helped
    # and the causal filter, with no future, agrees on the clear frames
    f = sm.ChainForward(sticky)
    causal = np.array([f.step(x) for x in u]).argmax(axis=1)
    assert np.mean(causal == truth) >= np.mean(u.argmax(axis=1) == truth)


def _trained(order: int = 1):
    words, spans, _ = _planted(30, 2)
    syl = [Syllable(k + 0.1, k + 0.4, k + 0.5, 120.0 + 10 * (k % 3), 60.0 + k % 5, True)
           for k in range(30)]
    cfg = replace(sm.SignModelSettings(min_count=1, iterations=60), order=order)
    return sm.train_on_takes([sm.LabelledTake("t", 30.0, syl, words, spans)], cfg,
                             tagger="rules"), syl, words


@pytest.mark.parametrize("order", [1, 2])
def test_the_causal_filter_meets_the_exact_marginal_on_the_last_frame(order: int) -> None:
    model, syl, words = _trained(order)
    x = sm.frame_inputs(model.layout, 30.0, syl, words, tagger="rules")
    exact = model.marginals(x)
    causal = model.causal_marginals(x)
    np.testing.assert_allclose(causal[-1], exact[-1], atol=1e-9)
    np.testing.assert_allclose(causal[0], np.exp(model.unary(x[:1])[0])
                               / np.exp(model.unary(x[:1])[0]).sum(), atol=1e-9)
    assert np.allclose(causal.sum(axis=1), 1.0)


def test_save_and_load_round_trip(tmp_path) -> None:
    model, syl, words = _trained(2)
    model.segment_signs = {"fingerprint": "abc", "signs": ["Beats", "Rest"]}
    model.save(tmp_path)
    back = sm.SignModel.load(tmp_path)
    x = sm.frame_inputs(model.layout, 30.0, syl, words, tagger="rules")
    np.testing.assert_allclose(back.marginals(x), model.marginals(x))
    np.testing.assert_array_equal(back.decode(x), model.decode(x))
    assert back.layout == model.layout and back.settings == model.settings
    assert back.segment_signs["signs"] == ["Beats", "Rest"]


def test_the_table_a1_prior_holds_transitions_the_data_never_show() -> None:
    model, _, _ = _trained(1)
    prior = sm.table_a1_log_transitions()
    rest, nod = sm.SIGN_INDEX["Rest"], sm.SIGN_INDEX["Head-nod"]   # absent from the data
    assert abs(model.dcnf.trans[rest, nod] - prior[rest, nod]) < 0.5
    assert np.allclose(np.exp(prior).sum(axis=1), 1.0)


def test_the_live_filter_sees_a_word_only_once_said() -> None:
    model, _, _ = _trained(1)
    word = model.layout.vocabulary[0]
    f = model.new_filter([(2.0, 2.5, word)])
    lex = model.layout.blocks()["words"]
    alpha = 0
    for t in np.arange(0.0, 2.5 + model.settings.word_latency_s - 0.05, 1 / 30):
        f.step(float(t))
        assert not any(alpha in v for v in f.builder.words.values())
    f.step(2.5 + model.settings.word_latency_s + 0.01)
    assert f.builder.row(2)[lex][alpha] == 1.0
    b = f.belief
    assert b.shape == (sm.N_SIGNS,) and abs(b.sum() - 1.0) < 1e-9
