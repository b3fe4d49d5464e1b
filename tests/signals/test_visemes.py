"""Visemes with Cohen–Massaro coarticulation: known answers on phone lists and a real take."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.phones import ARPABET, SIL, Phone, phones_from_textgrid
from gesture_sim.errors import GestureSimError
from gesture_sim.signals.visemes import (
    PHONE_TARGETS,
    VISEME_CHANNELS,
    VISEME_CLASSES,
    Coarticulator,
    LiveCoarticulator,
    VisemeConfig,
    classify_track,
    labels_at,
    viseme_class,
)

TAKE = Path(__file__).resolve().parents[1] / "data" / "textgrids" / "2_scott_0_1_1.TextGrid"
JAW, CLOSE, ROUND, SPREAD, TUCK, TONGUE = range(6)


def seq(labels: str, d: float = 0.1, t0: float = 0.0) -> list[Phone]:
    return [Phone(t0 + i * d, t0 + (i + 1) * d, lab) for i, lab in enumerate(labels.split())]


def test_the_contract() -> None:
    assert VISEME_CHANNELS == ("jaw_open", "lip_close", "lip_round", "lip_spread", "lip_tuck",
                               "tongue_tip")
    phones = [p for c in VISEME_CLASSES for p in c.phones]
    assert sorted(phones) == sorted(ARPABET) and len(set(phones)) == len(phones)
    assert set(PHONE_TARGETS) == set(ARPABET)
    assert viseme_class("M") == "closed" and viseme_class(SIL) == "rest"
    with pytest.raises(GestureSimError):
        viseme_class("QQ")


def test_bilabials_close_the_lips_between_open_vowels() -> None:
    ph = seq("SIL M AA P AA SIL")
    co = Coarticulator(ph)
    m, a1, p, a2 = (co.at(x.centre_s) for x in ph[1:5])
    assert m[CLOSE] >= 0.9 and p[CLOSE] >= 0.9
    assert a1[CLOSE] <= 0.2 and a2[CLOSE] <= 0.2
    assert a1[JAW] > 0.2 and m[JAW] < a1[JAW]
    # short real-speech durations (40 ms bilabial, 50 ms vowels) still close
    ph = seq("SIL AH M AH B IY SIL", d=0.045)
    co = Coarticulator(ph)
    assert co.at(ph[2].centre_s)[CLOSE] >= 0.9 and co.at(ph[4].centre_s)[CLOSE] >= 0.9


def test_vowel_shapes() -> None:
    def centre(lab: str) -> np.ndarray:
        ph = seq(f"SIL T {lab} T SIL")
        return Coarticulator(ph).at(ph[2].centre_s)

    aa, iy, uw = centre("AA"), centre("IY"), centre("UW")
    assert aa[JAW] > iy[JAW] + 0.1
    assert 0.2 < aa[JAW] <= 0.35
    assert uw[ROUND] > 0.7 and uw[ROUND] > aa[ROUND] + 0.5 and uw[ROUND] > iy[ROUND] + 0.5
    assert iy[SPREAD] > 0.5 and iy[SPREAD] > uw[SPREAD] + 0.4
    # rounding peaks inside UW
    ph = seq("SIL S UW S SIL")
    co = Coarticulator(ph)
    t = np.arange(0.0, 0.5, 0.005)
    tr = co.track(t)
    assert ph[2].start_s <= t[tr[:, ROUND].argmax()] < ph[2].end_s
    # anticipatory rounding: the /s/ before UW is rounder than an /s/ before IY
    s_uw = co.at(ph[1].centre_s)[ROUND]
    ph2 = seq("SIL S IY S SIL")
    assert s_uw > Coarticulator(ph2).at(ph2[1].centre_s)[ROUND] + 0.2


def test_consonant_articulators() -> None:
    for lab, ch in (("F", TUCK), ("V", TUCK), ("TH", TONGUE), ("DH", TONGUE)):
        ph = seq(f"SIL AH {lab} AH SIL")
        co = Coarticulator(ph)
        y = co.at(ph[2].centre_s)
        assert y[ch] >= 0.8, lab
        assert co.at(ph[1].centre_s)[ch] < 0.35, lab
        assert y[CLOSE] < 0.1
    ph = seq("SIL AH L AH SIL")
    assert 0.1 < Coarticulator(ph).at(ph[2].centre_s)[TONGUE] < 0.5
    ph = seq("SIL AH SH AH SIL")
    assert Coarticulator(ph).at(ph[2].centre_s)[ROUND] > 0.3


def test_rest_far_from_speech_and_vectorised_track() -> None:
    ph = seq("SIL HH AH L OW SIL") + [Phone(0.6, 3.0, SIL)]
    co = Coarticulator(ph)
    assert np.allclose(co.at(2.5), 0.0, atol=1e-3)
    assert np.allclose(co.at(-5.0), 0.0, atol=1e-3)
    t = np.linspace(-0.2, 3.2, 341)
    tr = co.track(t)
    assert tr.shape == (341, 6)
    assert np.allclose(tr[::37], np.array([co.at(x) for x in t[::37]]))
    assert Coarticulator([]).track(t).shape == (341, 6)
    with pytest.raises(GestureSimError):
        Coarticulator([Phone(0.0, 0.1, "XX")])


def test_continuity_and_bilabials_on_a_real_take() -> None:
    ph = phones_from_textgrid(TAKE)
    co = Coarticulator(ph)
    t = np.arange(0.0, ph[-1].end_s, 0.01)
    tr = co.track(t)
    assert np.all(np.isfinite(tr)) and tr[:, JAW].max() <= 0.35 and tr[:, 1:].max() <= 1.0
    jump = np.abs(np.diff(tr, axis=0)).max(axis=0)
    assert jump[JAW] < 0.06  # rad per 10 ms
    assert np.all(jump[1:] < 0.3)  # per 10 ms (a fast lip closure takes 40-50 ms)
    bil = [p for p in ph if p.label in ("P", "B", "M")]
    closed = []
    for p in bil:
        inside = (t >= p.start_s) & (t < p.end_s)
        closed.append(max(tr[inside, CLOSE].max(initial=0.0), co.at(p.centre_s)[CLOSE]) >= 0.9)
    assert len(bil) > 40 and np.mean(closed) >= 0.9
    # the TextGrid's track classified frame by frame agrees with its own phones' classes
    lab = [viseme_class(x) for x in labels_at(ph, t)]
    agree = np.mean([a == b for a, b in zip(classify_track(tr), lab, strict=True)])
    assert agree > 0.4


def test_live_coarticulator_looks_back_only() -> None:
    ph = seq("SIL S UW S SIL")
    live = LiveCoarticulator()
    for p in ph:
        live.push(p, emitted_s=p.end_s + 0.1)  # each known 100 ms after it ends
    # at the /s/ before UW, UW is not known yet: no anticipatory rounding
    s_centre = ph[1].centre_s
    assert live.at(s_centre)[ROUND] < 0.05
    assert Coarticulator(ph).at(s_centre)[ROUND] > 0.2
    # with lag = the latency, each phone is shown whole once known
    lagged = LiveCoarticulator(lag_s=0.15)
    for p in ph:
        lagged.push(p, emitted_s=p.end_s + 0.1)
    assert lagged.at(ph[2].centre_s + 0.15)[ROUND] > 0.6
    t = np.arange(0.0, 0.8, 0.01)
    assert np.allclose(lagged.track(t)[::9], np.array([lagged.at(x) for x in t[::9]]))
    # phones pushed without a time count from then on
    now = LiveCoarticulator()
    for p in ph:
        now.push(p)
    assert np.allclose(now.at(ph[2].centre_s), Coarticulator(ph).at(ph[2].centre_s))


def test_config_knobs() -> None:
    ph = seq("SIL S UW S SIL")
    wide = Coarticulator(ph).at(ph[1].centre_s)[ROUND]
    narrow = Coarticulator(ph, VisemeConfig(theta_scale=3.0)).at(ph[1].centre_s)[ROUND]
    assert narrow < wide
    ph = seq("SIL AY SIL", d=0.3)
    co = Coarticulator(ph)
    start, end = co.at(0.38), co.at(0.55)  # diphthong: open onset, spread offset
    assert start[JAW] > end[JAW] and end[SPREAD] > start[SPREAD]
