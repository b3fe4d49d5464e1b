"""`gesture-sim listener mine`: Okwechime's rules from a user's annotations (a known answer),
and the rules driving a conversation's interested and bored listeners."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gesture_sim import cli
from gesture_sim.signals.sdm import ListenerTendencies, load_rules


def _csv(path: Path, p_answer: float, seed: int) -> Path:
    """A talks for 200 s and nods every 2 s; B nods back 0.2 s later with p_answer."""
    rng = np.random.default_rng(seed)
    rows = ["start,end,signal,person", "0,200,talking,A"]
    for k in range(100):
        t = 2.0 * k
        rows.append(f"{t:.2f},{t + 0.2:.2f},nod,A")
        if rng.random() < p_answer:
            rows.append(f"{t + 0.2:.2f},{t + 0.32:.2f},nod,B")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_mine_recovers_the_planted_rule_and_feeds_the_interest_tables(tmp_path, capsys) -> None:
    keen = _csv(tmp_path / "keen.csv", 0.9, 0)
    bored = _csv(tmp_path / "bored.csv", 0.3, 1)
    for src, out in ((keen, "keen.json"), (bored, "bored.json")):
        assert cli.main(["listener", "mine", str(src), "-o", str(tmp_path / out),
                         "--json"]) == 0
        summary = json.loads(capsys.readouterr().out)
        assert summary["rules"] >= 1 and summary["persons"] == ["A", "B"]
    def nod_rule(name):
        return next(r for r in load_rules(tmp_path / name)
                    if r.antecedent == ("nod",) and r.consequent == "nod")

    keen_rule, bored_rule = nod_rule("keen.json"), nod_rule("bored.json")
    # a speaker nod's frames are answered within the bag about as often as its nods (0.9 vs
    # 0.3; the pooled B => A pair dilutes both alike)
    assert 1.8 < keen_rule.confidence / bored_rule.confidence < 4.0
    assert keen_rule.confidence > 0.4
    tend = ListenerTendencies.from_rules(load_rules(tmp_path / "keen.json"),
                                         load_rules(tmp_path / "bored.json"))
    assert 1.8 < tend.ratios()["nod"] < 4.0 and tend.source == "mined rules"


def test_mine_checks_its_input_and_output_first(tmp_path, capsys) -> None:
    assert cli.main(["listener", "mine", str(tmp_path / "none.csv"), "-o",
                     str(tmp_path / "r.json")]) == 2
    assert "none.csv" in capsys.readouterr().err
    src = _csv(tmp_path / "a.csv", 0.5, 0)
    assert cli.main(["listener", "mine", str(src), "-o", str(src)]) == 2   # not over its input
    assert "a.csv" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("start,end,signal,person\n1,x,nod,A\n", encoding="utf-8")
    assert cli.main(["listener", "mine", str(bad), "-o", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r.json").exists()
