"""The RUTH signal scheduler without physics: envelopes, channel limits, jog codes, blinks,
calm, markup, and the additive target layers."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.contracts import Accent, Boundary
from gesture_sim.errors import GestureSimError
from gesture_sim.signals.ruth import (
    SIGNAL_JOINTS,
    Action,
    Channel,
    RuthSignals,
    jog_goal,
    load_markup,
    parse_markup,
)
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.layers import TargetLayers

J = {n: i for i, n in enumerate(SIGNAL_JOINTS)}
DT = 1 / 30


def _run(sig: RuthSignals, dur: float, accents=(), boundaries=(), speaking=None):
    """Step ``sig`` at 30 Hz; returns (times, offsets (k, 11))."""
    acc, bnd = sorted(accents, key=lambda a: a.t_emitted), list(boundaries)
    times, out, last = [], [], -1e9
    for k in range(int(dur / DT)):
        t = k * DT
        new_a = [a for a in acc if a.t_emitted <= t]
        acc = acc[len(new_a):]
        new_b = [b for b in bnd if b.t_emitted <= t]
        bnd = bnd[len(new_b):]
        sp = speaking(t) if speaking else False
        last = t if sp else last
        off, _ = sig.step(t, new_a, new_b, sp, 0.0 if sp else min(t - last, 1e3))
        times.append(t)
        out.append(off)
    return np.array(times), np.array(out)


def test_jog_codes_are_sums_and_forward_is_counter_flexion() -> None:
    for code, parts in (("DR", "DR"), ("UR", "UR"), ("DL", "DL"), ("UL", "UL")):
        assert np.allclose(jog_goal(code), jog_goal(parts[0]) + jog_goal(parts[1]))
    d, f = jog_goal("D"), jog_goal("F")
    assert d[J["neck_flex"]] > 0 and d[J["head_flex"]] > 0          # nod down = flexion
    assert f[J["neck_flex"]] > 0 > f[J["head_flex"]]                # forward: counter-flexion
    assert np.allclose(jog_goal("B"), -f)
    assert jog_goal("R")[J["head_twist"]] < 0 < jog_goal("L")[J["head_twist"]]
    assert jog_goal("J")[J["head_bend"]] > 0 > jog_goal("C")[J["head_bend"]]
    tl = jog_goal("TL")
    assert tl[J["head_bend"]] > 0 and tl[J["head_flex"]] > 0       # tilt plus a down-nod
    with pytest.raises(GestureSimError):
        jog_goal("X*")


def test_envelope_attack_peak_decay_and_one_baton_per_channel() -> None:
    g = jog_goal("D")
    a = Action("baton", "D*", g, 1.0, start=1.0, peak=1.1, release=1.1, decay=0.25)
    assert a.level(0.99) == 0 and a.level(1.1) == pytest.approx(1.0)
    assert 0 < a.level(1.05) < 1 and 0 < a.level(1.2) < 1 and a.level(1.36) == 0
    ch = Channel("jog")
    assert ch.add_baton(a, 1.0)
    rising = Action("baton", "D*", g, 1.0, 1.05, 1.15, 1.15, 0.25)
    assert not ch.add_baton(rising, 1.05)          # the first is still rising: refused
    later = Action("baton", "D*", g, 0.5, 1.2, 1.3, 1.3, 0.25)
    before = ch.value(1.2)
    assert ch.add_baton(later, 1.2)                 # decaying: replaced, continuously
    assert np.allclose(ch.value(1.2), before)
    assert ch.baton is later


def test_accent_gives_nod_peaking_soon_after_emission_and_phrase_underliner() -> None:
    sig = RuthSignals(seed=1)
    acc = [Accent(t=1.0, t_emitted=1.03, strength=3.0)]
    bnd = [Boundary(t=1.6, t_emitted=1.8, kind="pause")]
    t, off = _run(sig, 3.0, acc, bnd, speaking=lambda t: 0.5 < t < 1.7)
    pitch = off[:, J["neck_flex"]] + off[:, J["head_flex"]]
    k = int(np.argmax(pitch))
    assert 1.05 <= t[k] <= 1.25
    assert pitch[t < 1.03].max() == 0.0                  # causal: nothing before emission
    texts = [e for _, e in sig.events]
    assert "nod D*" in texts and "jog TL" in texts and "jog end" in texts
    assert abs(off[-1]).max() < 1e-9                      # released after the boundary


def test_silence_keeps_blinking_at_a_human_rate_and_stays_calm() -> None:
    sig = RuthSignals(seed=3)
    _, off = _run(sig, 120.0)
    kinds = [e for _, e in sig.events]
    blinks = [e for e in kinds if e.startswith("blink")]
    assert 4 <= len(blinks) <= 30, len(blinks)          # 9/min expected: 18 in 2 min
    assert not [e for e in kinds if e.startswith(("nod", "brow", "jog"))]
    lid = off[:, J["left_eyelid_close"]]
    assert lid.max() == pytest.approx(0.014) and np.median(lid) == 0
    assert np.allclose(off[:, :J["jaw_open"] + 1], 0) and np.allclose(off[:, 7:9], 0)


def test_jaw_follows_the_frame_intensity_and_closes_in_silence() -> None:
    sig = RuthSignals(seed=0)
    n = 300
    times = np.arange(n) * 0.01
    rng = np.random.default_rng(0)
    level = 60 + 10 * np.sin(2 * np.pi * 4 * times) + rng.normal(0, 0.5, n)
    silent = times >= 2.0
    sig.push_frames(times, np.where(silent, np.nan, level), silent, times + 0.03,
                    np.full(n, 120.0))
    jaw = []
    for k in range(int(3.0 / 0.01)):
        off, _ = sig.step(k * 0.01)
        jaw.append(off[J["jaw_open"]])
    jaw = np.array(jaw)
    speech = (times > 0.5) & (times < 1.95)
    r = np.corrcoef(jaw[3:][speech[:-3]], level[:-3][speech[:-3]])[0, 1]
    assert r > 0.9
    assert jaw[times > 2.1].max() == 0.0
    assert jaw.max() <= np.radians(12.0) + 1e-9


def test_markup_drives_signals_ahead_of_time(tmp_path) -> None:
    f = tmp_path / "s.txt"
    f.write_text("# labels\nauto off\n1.00 nod\n2.0 brow\n2.5-3.5 jog TR\n3.0 blink\n"
                 "1.5 jog UR*\n0.5 accent 4\n", encoding="utf-8")
    m = load_markup(f)
    assert not m.auto and len(m.items) == 6
    sig = RuthSignals(markup=m)
    t, off = _run(sig, 4.5)
    ev = dict((text, tt) for tt, text in sig.events)
    pitch = off[:, J["neck_flex"]] + off[:, J["head_flex"]]
    assert abs(t[np.argmax(pitch[t < 1.3])] - 1.0) <= 0.05     # the nod peaks on its label
    assert abs(ev["brow 1+2*"] - 2.0) < 0.05 and "jog TR" in ev and "jog UR*" in ev
    assert not any(e.startswith("blink spont") for e in ev)       # auto off: no spontaneous
    assert any(e.startswith("blink label") for e in ev)
    assert "jog D*" in ev and "nod D*" not in ev        # auto off: the accent label is unused


@pytest.mark.parametrize("text", ["1.0 wave", "abc nod", "1.0 jog XY*", "1.0 jog TL",
                                  "1.0-2.0 nod*", "1.0-2.0 jog D*", "1.0 brow 4",
                                  "1.0 accent loud", "2.0-1.0 jog TL", "1.0 blink 3"])
def test_bad_markup_is_one_line_error(text: str) -> None:
    with pytest.raises(GestureSimError) as exc:
        parse_markup(f"0.5 nod\n{text}\n", source="f.txt")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("f.txt:2:")


def test_missing_markup_file_is_one_line_error(tmp_path) -> None:
    with pytest.raises(GestureSimError, match="cannot read signals file"):
        load_markup(tmp_path / "nope.txt")


def test_layers_add_offsets_and_clamp_only_the_touched_joints() -> None:
    layers = TargetLayers()
    layers.define("face", ["jaw_open", "head_flex"])
    layers.define("more", ["head_flex"])
    q = np.zeros(len(hm.ACTUATED_JOINTS))
    q[hm.actuated_index(["left_shoulder_flex"])] = 9.0   # out of range, not touched: kept
    layers.set("face", np.array([1.0, 0.1]))
    layers.set("more", np.array([0.05]))
    out = layers.apply(q)
    jaw, head, sh = hm.actuated_index(["jaw_open", "head_flex", "left_shoulder_flex"])
    lo, hi = layers.ranges[jaw]
    assert lo <= out[jaw] < hi and out[jaw] > 0.95 * hi          # clamped inside the range
    assert out[head] == pytest.approx(0.15) and out[sh] == 9.0
    with pytest.raises(GestureSimError):
        layers.set("face", np.zeros(3))
