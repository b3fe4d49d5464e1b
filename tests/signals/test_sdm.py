"""The Social Dynamics Model (gesture_sim.signals.sdm): annotation files, Apriori with the
temporal bag (planted rules recovered with their confidences), rules as JSON, and the interest
dial."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.signals import sdm
from gesture_sim.signals.sdm import (
    RULE_BASE_RATES,
    ListenerTendencies,
    SignalTable,
    load_rules,
    mine,
    read_annotations,
    read_csv,
    read_elan,
    save_rules,
    transactions,
)

FPS = 25.0


def planted(seed: int = 0, n_slots: int = 1500, p_nod: float = 0.8, p_smile: float = 0.6
            ) -> SignalTable:
    """Synthetic annotations of speaker A and listener B, slots of 40 frames (1.6 s).

    Each slot holds (drawn at random) a speaker nod (4 frames, at the slot start) answered with
    probability ``p_nod`` by a listener nod starting 4..8 frames after its onset; or a speaker
    laugh (6 frames) answered with probability ``p_smile`` by a listener smile 6..10 frames
    after; or nothing but a background listener nod at 20..30 frames into the slot (noise,
    outside every bag). Speaker and listener activity are independent noise (20 % of frames).
    Three speaker head shakes, each answered by a listener shake: confidence 1 but support
    12 / 60000 frames, under the 0.5 % minimum. A talks throughout.
    """
    rng = np.random.default_rng(seed)
    n = 40 * n_slots
    rows: list[tuple[str, str, float, float | None]] = [("A", "talking", 0.0, n / FPS)]

    def add(person: str, sig: str, k0: int, length: int) -> None:
        rows.append((person, sig, k0 / FPS, (k0 + length) / FPS))

    shakes = {100, 700, 1300}
    for slot in range(n_slots):
        k = 40 * slot
        if slot in shakes:
            add("A", "shake", k, 4)
            add("B", "shake", k + 5, 3)
            continue
        u = rng.random()
        if u < 1 / 3:
            add("A", "nod", k, 4)
            if rng.random() < p_nod:
                add("B", "nod", k + 4 + int(rng.integers(0, 5)), 3)
        elif u < 2 / 3:
            add("A", "laugh", k, 6)
            if rng.random() < p_smile:
                add("B", "smile", k + 6 + int(rng.integers(0, 5)), 4)
        elif rng.random() < 0.5:
            add("B", "nod", k + 20 + int(rng.integers(0, 8)), 3)
    for person in ("A", "B"):
        act = rng.random(n) < 0.2
        for k in np.flatnonzero(act):
            add(person, "activity", int(k), 1)
    return SignalTable.from_intervals(rows, FPS, n_frames=n)


def _rule(rules, ante, cons):
    hits = [r for r in rules if r.antecedent == ante and r.consequent == cons]
    return hits[0] if hits else None


def test_planted_rules_are_recovered_with_their_confidences() -> None:
    table = planted()
    rules = mine(table, min_support=0.005, min_confidence=0.3, pairs=[("A", "B")])
    nod = _rule(rules, ("nod",), "nod")
    smile = _rule(rules, ("laugh",), "smile")
    assert nod is not None and smile is not None
    assert nod.confidence == pytest.approx(0.8, abs=0.06)
    assert smile.confidence == pytest.approx(0.6, abs=0.06)
    # Eq. 5.1-5.2 exactly: support = count / instances, confidence = count / antecedent count
    spk, lst = transactions(table, "A", "B")
    j_nod = sdm.SIGNALS.index("nod")
    a = spk[:, j_nod]
    assert nod.antecedent_count == int(a.sum())
    assert nod.count == int((a & lst[:, j_nod]).sum())
    assert nod.support == pytest.approx(nod.count / len(spk))
    assert nod.confidence == pytest.approx(nod.count / nod.antecedent_count)
    # the shake rule (confidence 1) is under the minimum support: not returned
    assert _rule(mine(table, 0.005, 0.0, pairs=[("A", "B")]), ("shake",), "shake") is None
    assert _rule(mine(table, 0.0001, 0.0, pairs=[("A", "B")]), ("shake",), "shake"
                 ).confidence == pytest.approx(1.0)
    # no crossed rule: a speaker laugh does not predict a listener nod beyond chance
    cross = _rule(mine(table, 0.0001, 0.0, pairs=[("A", "B")]), ("laugh",), "nod")
    assert cross is None or cross.confidence < 0.05
    # every returned rule passes both thresholds; antecedents are speaker signals only
    for r in rules:
        assert r.support >= 0.005 - 1e-12 and r.confidence >= 0.3 - 1e-12
        assert "talking" not in r.antecedent and "voiced" not in r.antecedent


def test_the_temporal_bag_is_a_real_parameter() -> None:
    """A bag of 3 frames misses the listener nods that start 4..8 frames after the onset."""
    table = planted(n_slots=600)
    short = _rule(mine(table, 0.001, 0.0, bag=3, pairs=[("A", "B")]), ("nod",), "nod")
    assert short is None or short.confidence < 0.3
    with pytest.raises(GestureSimError, match="temporal bag"):
        mine(table, bag=0)


def test_apriori_finds_longer_antecedents() -> None:
    """Speaker nod + laugh together predict a listener nod; each alone does not."""
    rng = np.random.default_rng(3)
    rows = [("A", "talking", 0.0, 2000.0)]
    for slot in range(1200):
        k = 40 * slot
        u = rng.random()
        sigs = ["nod", "laugh"] if u < 0.3 else ["nod"] if u < 0.6 else ["laugh"] if u < 0.9 else []
        for s in sigs:
            rows.append(("A", s, k / FPS, (k + 4) / FPS))
        if len(sigs) == 2:
            rows.append(("B", "nod", (k + 5) / FPS, (k + 8) / FPS))
    table = SignalTable.from_intervals(rows, FPS, n_frames=48000)
    rules = mine(table, 0.002, 0.6, pairs=[("A", "B")])
    both = _rule(rules, ("laugh", "nod"), "nod")
    assert both is not None and both.confidence == pytest.approx(1.0)
    assert _rule(rules, ("nod",), "nod") is None               # half of the nods: conf 0.5
    assert _rule(rules, ("laugh",), "nod") is None


def test_csv_and_elan_give_the_same_table(tmp_path) -> None:
    csv_path = tmp_path / "a.csv"
    csv_path.write_text("person,signal,start,end,time\n"
                        "A,talking,0,4,\n"
                        "A,N,1.0,1.2,\n"
                        "B,nod,1.4,1.6,\n"
                        "B,smile,,,2.01\n"
                        "B,G-S,0.5,3.0,\n")
    elan = tmp_path / "a.txt"
    elan.write_text("# ELAN export\n"
                    "A:talking\t\t0.0\t4.0\t4.0\t\n"
                    "A_nod\t\t00:00:01.000\t00:00:01.200\t0.2\t\n"
                    "B\t\t1.4\t1.6\t0.2\tnod\n"
                    "B\t\t2.01\t2.03\t0.02\tsmile\n"
                    "B:gaze\t\t0.5\t3.0\t2.5\t\n")
    a, b = read_csv(csv_path), read_elan(elan)
    assert a.persons == b.persons == ("A", "B")
    assert np.array_equal(a.data, b.data)
    assert read_annotations(csv_path).n_frames == a.n_frames
    nod = a.signal("A", "nod")
    assert np.flatnonzero(nod).tolist() == [25, 26, 27, 28, 29]       # [1.0, 1.2) s at 25 Hz
    assert np.flatnonzero(a.signal("B", "smile")).tolist() == [50]      # the frame of 2.01 s


@pytest.mark.parametrize("text, where", [
    ("person,signal,start,end\nA,wink,0,1\n", "line 2"),
    ("person,signal,start,end\nA,nod,2,1\n", "line 2"),
    ("person,signal,start,end\nA,nod,0,1\nB,nod,x,1\n", "line 3"),
    ("person,start,end\nA,0,1\n", "line 1"),
])
def test_bad_csv_is_a_one_line_error_naming_file_and_line(tmp_path, text, where) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(GestureSimError) as exc:
        read_csv(p)
    msg = str(exc.value)
    assert "\n" not in msg and "bad.csv" in msg and where in msg


def test_bad_elan_is_a_one_line_error(tmp_path) -> None:
    p = tmp_path / "bad.txt"
    p.write_text("A:nod\t\t1.0\t1.2\t\nA:wink\t\t1.0\t1.2\t\n")
    with pytest.raises(GestureSimError, match=r"bad\.txt: line 2"):
        read_elan(p)
    p.write_text("A:nod\t1.0\n")
    with pytest.raises(GestureSimError, match="line 1"):
        read_elan(p)
    with pytest.raises(GestureSimError, match="cannot read"):
        read_elan(tmp_path / "missing.txt")


def test_rules_round_trip_as_json(tmp_path) -> None:
    rules = mine(planted(n_slots=300), 0.005, 0.3, pairs=[("A", "B")])
    path = tmp_path / "rules.json"
    save_rules(path, rules, fps=FPS, bag=10)
    assert load_rules(path) == rules
    path.write_text("{}")
    with pytest.raises(GestureSimError, match="cannot read rules"):
        load_rules(path)


def test_the_thesis_dial_keeps_the_rule_at_one_half_and_table_5_4_ratios() -> None:
    tend = ListenerTendencies.from_thesis()
    mid = tend.at(0.5)
    for r, v in mid.items():
        base = RULE_BASE_RATES[r]
        assert v == pytest.approx(base if r == "activity" else min(base, 1.0))
    assert all(v == 1.0 for v in tend.scale(0.5).values())
    s0, s1 = tend.scale(0.0), tend.scale(1.0)
    assert s1["nod"] / s0["nod"] == pytest.approx(1.7)
    assert s1["voiced"] / s0["voiced"] == pytest.approx(1.5)
    assert s1["gaze_partner"] == s0["gaze_partner"] == 1.0          # G-S does not discriminate
    assert tend.at(1.0)["nod"] == 1.0                                # a probability: clipped
    assert tend.at(0.0)["nod"] == pytest.approx(0.9 / math.sqrt(1.7))
    assert tend.at(0.25)["voiced"] < tend.at(0.75)["voiced"]         # monotone
    assert tend.at(-3.0) == tend.at(0.0) and tend.at(7.0) == tend.at(1.0)


def test_the_dial_from_mined_rules_takes_their_confidences() -> None:
    hi = mine(planted(1, n_slots=900, p_nod=0.8), 0.005, 0.0, pairs=[("A", "B")])
    lo = mine(planted(2, n_slots=900, p_nod=0.4), 0.005, 0.0, pairs=[("A", "B")])
    tend = ListenerTendencies.from_rules(hi, lo)
    assert tend.source == "mined rules"
    assert tend.ratios()["nod"] > 1.3
    assert tend.ratios()["smile"] == pytest.approx(1.0, abs=0.25)    # same p_smile in both
    assert tend.scale(1.0)["nod"] > 1.0 > tend.scale(0.0)["nod"]
