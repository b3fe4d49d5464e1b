"""The listener (gesture_sim.signals.listener): backchannels at the partner's low/falling phrase
ends, never on every syllable nor at its own speech, gain-invariant, causal, smooth; and the
same on a scripted two-voice espeak dialogue (gesture_sim.testing.dialogue) with known pauses."""

from __future__ import annotations

import math
import wave
from dataclasses import replace

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.signals.listener import (
    LISTENER_JOINTS,
    ListenerConfig,
    ListenerSignals,
)
from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.layers import TargetLayers
from gesture_sim.testing import dialogue
from gesture_sim.testing.frames import tracked_frames

J = {n: i for i, n in enumerate(LISTENER_JOINTS)}
DT = 1 / 30
STEP = 0.01
HINGES = [i for n, i in J.items() if "brow" not in n]
BROWS = [J["left_brow_raise"], J["right_brow_raise"]]
CERTAIN = ListenerConfig(p_invited=1.0, p_other=0.0)


# ------------------------------------------------------------------ synthetic partner

def partner(segments: list[tuple[str, float]], gain_db: float = 0.0, latency: float = 0.06
            ) -> tuple[tuple[np.ndarray, ...], list[tuple[str, float]]]:
    """100 Hz frames of a partner speaking ``segments``: ("fall" | "rise" | "flat", s) speech
    (F0 120 Hz +- 1 st, intensity 68 +- 6 dB) whose last 0.3 s falls 6 st / rises 5 st / stays
    level, ("pause", s) silence, ("words", s) speech with 0.1 s gaps every 0.5 s and a fall at
    every word end.

    Returns ((times, intensity_db, silent, t_known, f0_hz), [(ending kind, pause start s)]).
    """
    st_l, i_l, sil_l = [], [], []
    ends: list[tuple[str, float]] = []
    for kind, dur in segments:
        n = int(round(dur / STEP))
        k0 = len(st_l)
        tt = (k0 + np.arange(n)) * STEP
        if kind == "pause":
            st_l += [np.nan] * n
            i_l += [25.0] * n
            sil_l += [True] * n
            continue
        st = 1.0 * np.sin(2 * np.pi * 0.7 * tt)
        inten = 68.0 + 6.0 * np.sin(2 * np.pi * 4.0 * tt)
        silent = np.zeros(n, bool)
        st[(np.arange(n) % 25) >= 23] = np.nan             # a consonant every 0.25 s
        tail = min(30, n)
        if kind == "fall":
            st[-tail:] += np.linspace(0.0, -6.0, tail)
        elif kind == "rise":
            st[-tail:] += np.linspace(0.0, 5.0, tail)
        elif kind == "words":
            pos = np.arange(n) % 50                          # 0.5 s words
            silent = pos >= 40                               # 0.1 s gaps
            fall = (pos >= 25) & ~silent
            st[fall] -= 6.0 * (pos[fall] - 25) / 14.0        # every word ends falling
            st[silent] = np.nan
            inten[silent] = 25.0
        st_l += st.tolist()
        i_l += inten.tolist()
        sil_l += silent.tolist()
        ends.append((kind, (k0 + n) * STEP - 0.5 * STEP))
    times = np.arange(len(st_l)) * STEP
    st_a = np.asarray(st_l)
    f0 = 120.0 * 2.0 ** (st_a / 12.0)
    frames = (times, np.asarray(i_l) + gain_db, np.asarray(sil_l), times + latency, f0)
    return frames, ends


def run(sig: ListenerSignals, frames: tuple[np.ndarray, ...], dur: float,
        own=lambda t: False, stream: bool = False) -> tuple[np.ndarray, np.ndarray, list]:
    """Step ``sig`` at 30 Hz over ``dur`` s (frames pushed up front, or as they become known
    with ``stream``). Returns (times (k,), offsets (k, len(LISTENER_JOINTS)), events)."""
    known = frames[3]
    if not stream:
        sig.push_frames(*frames)
    sent, out, ts, events = 0, [], [], []
    for k in range(int(round(dur / DT))):
        t = k * DT
        if stream:
            n = int(np.searchsorted(known, t + 1e-9, side="right"))
            if n > sent:
                sig.push_frames(*(a[sent:n] for a in frames))
                sent = n
        off, ev = sig.step(t, own(t))
        ts.append(t)
        out.append(off)
        events += ev
    return np.array(ts), np.array(out), events


STATEMENTS = [("pause", 1.0)] + [("fall", 2.0), ("pause", 0.9), ("rise", 2.0), ("pause", 0.9)] * 4
DUR = sum(d for _, d in STATEMENTS)


# ------------------------------------------------------------------ synthetic tests

def test_joints_are_actuated_and_layerable() -> None:
    assert set(LISTENER_JOINTS) <= set(hm.ACTUATED_JOINTS)
    layers = TargetLayers()
    layers.define("listener", LISTENER_JOINTS)
    off = np.zeros(len(LISTENER_JOINTS))
    off[J["head_flex"]] = 0.1
    layers.set("listener", off)
    q = layers.apply(np.zeros(len(hm.ACTUATED_JOINTS)))
    assert q[hm.actuated_index(["head_flex"])[0]] == pytest.approx(0.1)


def test_a_low_falling_end_then_a_pause_gives_one_timed_nod() -> None:
    frames, ends = partner([("pause", 1.0), ("fall", 2.0), ("pause", 2.0)])
    sig = ListenerSignals(CERTAIN, seed=3)
    ts, off, events = run(sig, frames, 5.0)
    assert len(sig.backchannels) == 1
    bc = sig.backchannels[0]
    t_pause = ends[0][1]
    assert bc.invited and bc.kind in ("nod", "nod+brow")
    assert bc.t_cue == pytest.approx(t_pause, abs=0.011)
    assert bc.t_emitted >= bc.t_cue + CERTAIN.pause_wait_s - 1e-9      # causal wait
    assert 0.2 <= bc.t_peak - bc.t_cue <= 1.5
    assert [e for e in events if e[1].startswith("backchannel")] == [
        (round(bc.t_peak, 4), f"backchannel {bc.kind}")]
    nod = off[:, J["neck_flex"]] + off[:, J["head_flex"]]               # > 0: down
    k = int(np.argmax(nod))
    assert abs(ts[k] - bc.t_peak) <= DT + 1e-9
    assert math.radians(6.0) <= nod[k] <= math.radians(10.0)
    assert off[k, J["head_flex"]] > off[k, J["neck_flex"]] > 0           # split over both
    assert np.all(nod[ts < bc.t_emitted] == 0.0)                         # nothing before


def test_rising_ends_do_not_invite() -> None:
    """Over 20 seeds: falling ends get a backchannel nearly always, rising ends almost never
    (the default probabilities 0.9 / 0.05), and every rising end is judged rising."""
    frames, ends = partner(STATEMENTS)
    got = {"fall": 0, "rise": 0}
    for seed in range(20):
        sig = ListenerSignals(seed=seed)
        run(sig, frames, DUR)
        assert len(sig.cues) == len(ends)
        for (kind, t_pause), cue in zip(ends, sig.cues, strict=True):
            assert cue.t_cue == pytest.approx(t_pause, abs=0.011)
            assert cue.invited == (kind == "fall")
            assert cue.rising == (kind == "rise")
            got[kind] += cue.taken
    assert got["fall"] >= 0.75 * 80
    assert got["rise"] <= 0.15 * 80


def test_speech_without_pauses_does_not_nod_on_syllables() -> None:
    """30 s of speech, falling at every word end, 0.1 s gaps: speech is always present (the
    audio-driven listener of Okwechime 2011 would nod throughout), yet no backchannel."""
    frames, _ = partner([("pause", 0.5), ("words", 30.0), ("pause", 0.1)])
    sig = ListenerSignals(CERTAIN)
    run(sig, frames, 30.5)
    assert sig.cues == [] and sig.backchannels == []


def test_the_rate_is_bounded_by_the_refractory_period() -> None:
    frames, _ = partner([("pause", 0.5)] + [("fall", 0.9), ("pause", 0.3)] * 25)
    sig = ListenerSignals(CERTAIN)
    run(sig, frames, 31.0)
    t = np.array([b.t_emitted for b in sig.backchannels])
    assert len(sig.cues) == 25
    assert 8 <= len(t) <= 30.0 / CERTAIN.refractory_s + 1
    assert np.all(np.diff(t) >= CERTAIN.refractory_s - 1e-9)
    assert any(c.blocked == "refractory" for c in sig.cues)


def test_no_backchannel_at_its_own_speech() -> None:
    frames, ends = partner(STATEMENTS)
    sig = ListenerSignals(CERTAIN)
    _, off, _ = run(sig, frames, DUR, own=lambda t: True)
    assert sig.backchannels == []
    assert all(c.blocked == "own speech" for c in sig.cues if c.invited)
    assert np.allclose(off, 0.0)                     # no attention, no shift, no nod
    # own speech ending 0.2 s before the first decision still blocks it (own_quiet_s)
    first = ends[0][1]
    sig = ListenerSignals(CERTAIN)
    dec = first + CERTAIN.pause_wait_s + 0.06
    run(sig, frames, DUR, own=lambda t: t < dec - 0.2)
    assert sig.cues[0].blocked == "own speech"
    assert sig.backchannels and sig.backchannels[0].t_cue > first + 1.0


def test_a_quieter_partner_gives_the_same_backchannels() -> None:
    frames, _ = partner(STATEMENTS)
    quiet, _ = partner(STATEMENTS, gain_db=-12.0)
    a, b = ListenerSignals(seed=5), ListenerSignals(seed=5)
    _, off_a, ev_a = run(a, frames, DUR)
    _, off_b, ev_b = run(b, quiet, DUR)
    assert a.backchannels == b.backchannels and len(a.backchannels) >= 3
    assert ev_a == ev_b
    assert np.allclose(off_a, off_b)


def test_causal_streaming_equals_batch_and_the_future_does_not_leak() -> None:
    frames, ends = partner(STATEMENTS)
    a, b = ListenerSignals(seed=2), ListenerSignals(seed=2)
    _, off_a, _ = run(a, frames, DUR)
    _, off_b, _ = run(b, frames, DUR, stream=True)
    assert a.backchannels == b.backchannels
    assert np.array_equal(off_a, off_b)
    # changing the partner after 6 s changes nothing the listener did before those frames
    # were known
    alt = [np.array(x, copy=True) for x in frames]
    late = frames[0] >= 6.0
    alt[4][late] = 300.0
    alt[1][late] = 40.0
    c = ListenerSignals(seed=2)
    ts, off_c, _ = run(c, tuple(alt), DUR)
    early = ts < 6.0 + 0.06
    assert np.array_equal(off_a[early], off_c[early])


def test_offsets_are_bounded_smooth_and_zero_at_rest() -> None:
    segs = [("pause", 1.0)] + [("fall", 2.2), ("pause", 0.7), ("flat", 1.6), ("pause", 0.5)] * 14
    segs.append(("pause", 9.0))
    frames, _ = partner(segs)
    dur = sum(d for _, d in segs)
    heard = sum(d for k, d in segs if k != "pause")
    for seed in range(4):
        sig = ListenerSignals(seed=seed)
        ts, off, events = run(sig, frames, dur)
        assert np.all(off[0] == 0.0) and np.allclose(off[-1], 0.0, atol=1e-12)
        assert np.max(np.abs(off[:, HINGES])) <= math.radians(12.0)
        assert off[:, BROWS].min() >= 0.0 and off[:, BROWS].max() <= 0.008
        step = np.abs(np.diff(off, axis=0))
        assert step[:, HINGES].max() <= math.radians(2.0)   # per 1/30 s step: no jumps
        assert step[:, BROWS].max() <= 0.0015
        shifts = [t for t, e in events if e == "shift"]
        cfg = sig.cfg
        assert 1 <= len(shifts) <= heard / cfg.shift_min_s + 1
        assert np.max(np.abs(off[:, J["lower_spine_bend"]])) > math.radians(0.5)
        listening = (ts > 4.0) & (ts < dur - 9.0)           # attentive tilt and lean
        assert np.all(np.abs(off[listening, J["head_bend"]]) > math.radians(1.0))
        assert np.all(off[listening, J["lower_spine_flex"]] > math.radians(0.1))
        assert {e for _, e in events} <= {"shift", "backchannel nod", "backchannel nod+brow",
                                          "smile S"}
        assert len(sig.backchannels) >= 10
        smiles = sum(1 for _, e in events if e == "smile S")      # some backchannels smile
        assert 0 < smiles < len(sig.backchannels)
        corners = [J[f"{s}_lip_corner_up"] for s in ("left", "right")]
        assert off[:, corners].max() > 0.002 and off[:, corners].min() >= 0.0


def test_reset_reproduces_and_seeds_vary() -> None:
    frames, _ = partner(STATEMENTS)
    sig = ListenerSignals(seed=1)
    _, off1, _ = run(sig, frames, DUR)
    bcs = list(sig.backchannels)
    sig.reset()
    _, off2, _ = run(sig, frames, DUR)
    assert sig.backchannels == bcs and np.array_equal(off1, off2)
    variants = set()
    for seed in range(8):
        other = ListenerSignals(seed=seed)
        run(other, frames, DUR)
        variants.add(tuple(b.kind for b in other.backchannels))
    assert len(variants) > 1                               # seeded variety


# ------------------------------------------------------------------ the espeak dialogue

def _dialogue_or_skip(seed: int):
    try:
        return dialogue.make_dialogue(seed)
    except GestureSimError as exc:
        pytest.skip(str(exc))


def _converse(frames: list[tuple[np.ndarray, ...]], dur: float, seeds: tuple[int, int]
              ) -> list[ListenerSignals]:
    """Both persons listen to each other at 30 Hz; a person speaks while any of its own
    frames known by t within the last 0.3 s is not silent."""
    lis = [ListenerSignals(seed=s) for s in seeds]
    sent = [0, 0]
    for k in range(int(dur / DT)):
        t = k * DT
        for p in (0, 1):
            fr = frames[p]
            n = int(np.searchsorted(fr[3], t + 1e-9, side="right"))
            if n > sent[p]:
                lis[1 - p].push_frames(*(a[sent[p]:n] for a in fr))
                sent[p] = n
        for p in (0, 1):
            fr = frames[p]
            n = sent[p]
            recent = (fr[0][:n] >= t - 0.3) & ~fr[2][:n]
            lis[p].step(t, bool(recent.any()))
    return lis


@pytest.fixture(scope="module")
def conversations() -> list[tuple[object, list[ListenerSignals]]]:
    out = []
    for seed in range(3):
        d = _dialogue_or_skip(seed)
        frames = [tracked_frames(d.channels[:, p]) for p in (0, 1)]
        out.append((d, _converse(frames, d.duration, (10 * seed, 10 * seed + 1))))
    return out


def test_the_dialogue_is_composed_as_scripted(tmp_path) -> None:
    d = _dialogue_or_skip(0)
    assert 20.0 <= d.duration <= 27.0
    assert d.channels.shape == (len(d.mono), 2) and d.channels.dtype == np.float32
    assert np.array_equal(d.mono, d.channels.sum(axis=1))
    assert not np.any((np.abs(d.channels[:, 0]) > 0) & (np.abs(d.channels[:, 1]) > 0))
    assert d.turns[0].t_start == pytest.approx(1.0, abs=1e-3)
    assert [t.person for t in d.turns] == [0, 0, 0, 1, 1, 1, 0, 0, 0, 1]
    sr = 16_000
    for turn in d.turns:                                   # exact: speech inside, zero outside
        a, b = round(turn.t_start * sr), round(turn.t_end * sr)
        ch = d.channels[:, turn.person]
        assert ch[a] != 0.0 and ch[b - 1] != 0.0
        assert ch[a - 1] == 0.0 and ch[b] == 0.0
    assert len(d.inviting_pauses) == 4 and len(d.other_pauses) == 2 and len(d.turn_gaps) == 3
    for _, a, b in d.inviting_pauses + d.other_pauses:
        assert 0.79 <= b - a <= 1.01
    for _, a, b in d.turn_gaps:
        assert 1.09 <= b - a <= 1.31
    assert d.texts[4].endswith("?") and d.texts[7].endswith("?")
    assert dialogue.make_dialogue(0).turns == d.turns                 # seeded
    assert dialogue.make_dialogue(1).turns != d.turns
    paths = d.write(tmp_path)
    with wave.open(str(paths["stereo"])) as w:
        assert (w.getnchannels(), w.getsampwidth(), w.getframerate()) == (2, 2, sr)
        assert w.getnframes() == len(d.mono)
    with wave.open(str(paths["mono"])) as w:
        assert w.getnchannels() == 1 and w.getnframes() == len(d.mono)
    lines = paths["rttm"].read_text().split("\n")
    rows = [ln.split() for ln in lines if ln.strip()]
    assert len(rows) == len(d.turns)
    for row, turn in zip(rows, d.turns, strict=True):
        assert row[0] == "SPEAKER" and row[1] == "dialogue" and row[7] == "AB"[turn.person]
        assert float(row[3]) == pytest.approx(turn.t_start, abs=1e-3)
        assert float(row[4]) == pytest.approx(turn.duration, abs=1e-3)


def _near(t: float, pauses: list[tuple[int, float, float]], speaker: int) -> bool:
    return any(s == speaker and a - 0.2 <= t <= a + 0.1 for s, a, _ in pauses)


def test_listeners_nod_after_the_inviting_pauses_only(conversations) -> None:
    answered = total = after_questions = 0
    for d, lis in conversations:
        for s, a, _ in d.inviting_pauses:
            hits = [b for b in lis[1 - s].backchannels if a - 0.2 <= b.t_cue <= a + 0.1]
            total += 1
            if hits:
                answered += 1
                assert 0.2 <= hits[0].t_peak - a <= 1.5
                assert hits[0].invited
        for p in (0, 1):
            partner_ends = [(t.person, t.t_end, t.t_end) for t in d.turns]
            for b in lis[p].backchannels:
                # every nod answers the end of a partner's utterance, none comes mid-speech
                assert _near(b.t_cue, partner_ends, 1 - p), b
                assert 0.2 <= b.t_peak - b.t_cue <= 1.5
                for turn in d.turns:                        # never at its own speech
                    if turn.person == p:
                        assert not turn.t_start <= b.t_emitted <= turn.t_end + 0.3, b
                        assert not turn.t_start <= b.t_peak <= turn.t_end, b
                if _near(b.t_cue, d.other_pauses, 1 - p):
                    after_questions += 1
            for c in lis[p].cues:                           # the questions' ends rise
                if _near(c.t_cue, d.other_pauses, 1 - p):
                    assert c.rising and not c.invited, c
        assert answered >= total / 2
    assert total == 12 and answered >= 9
    assert after_questions <= 1


def test_a_quieter_dialogue_gives_the_same_backchannels(conversations) -> None:
    d, lis = conversations[0]
    frames = [tracked_frames(d.channels[:, p] * np.float32(10 ** (-12 / 20))) for p in (0, 1)]
    quiet = _converse(frames, d.duration, (0, 1))
    for p in (0, 1):
        a, b = lis[p].backchannels, quiet[p].backchannels
        assert [x.kind for x in a] == [x.kind for x in b]
        assert np.allclose([x.t_cue for x in a], [x.t_cue for x in b], atol=0.021)


def test_changing_a_config_value_changes_the_decisions() -> None:
    """The wait is a real parameter: a wait longer than the pauses gives no opportunity."""
    frames, _ = partner(STATEMENTS)
    sig = ListenerSignals(replace(CERTAIN, pause_wait_s=1.0))
    run(sig, frames, DUR)
    assert sig.cues == [] and sig.backchannels == []


def test_missing_tools_are_a_one_line_error(monkeypatch) -> None:
    monkeypatch.setattr(dialogue.shutil, "which", lambda name: None)
    with pytest.raises(GestureSimError, match="espeak-ng and sox"):
        dialogue.make_dialogue(0)


# ------------------------------------------------------------------ the interest dial (sdm)

def test_interest_one_half_without_voiced_is_the_rule_exactly() -> None:
    frames, _ = partner(STATEMENTS)
    cfg = replace(ListenerConfig(), p_voiced=0.0)
    a = ListenerSignals(cfg, seed=4)
    b = ListenerSignals(cfg, seed=4, interest=0.5)
    _, off_a, ev_a = run(a, frames, DUR)
    _, off_b, ev_b = run(b, frames, DUR)
    assert a.backchannels == b.backchannels and ev_a == ev_b
    assert np.array_equal(off_a, off_b)


def test_the_interested_listener_nods_and_backchannels_more() -> None:
    """Table 5.4 around the rule: nods x1.7 and voiced x1.5 from interest 0 to 1 (the invited
    nod probability saturates at 1, so the measured nod ratio is smaller)."""
    frames, _ = partner(STATEMENTS)
    nods = {0.0: 0, 1.0: 0}
    voiced = {0.0: 0, 1.0: 0}
    for interest in (0.0, 1.0):
        for seed in range(12):
            sig = ListenerSignals(seed=seed, interest=interest)
            run(sig, frames, DUR)
            nods[interest] += sum(b.kind.startswith("nod") for b in sig.backchannels)
            voiced[interest] += sum(b.kind.endswith("mm") for b in sig.backchannels)
            assert {b.kind for b in sig.backchannels} <= {
                "nod", "nod+brow", "nod+mm", "nod+brow+mm", "mm"}
    assert nods[1.0] > 1.2 * nods[0.0]
    assert voiced[1.0] > 1.2 * voiced[0.0] > 0
    sig = ListenerSignals(seed=0)
    assert sig.interest is None
    sig.set_interest(2.0)
    assert sig.interest == 1.0
    sig.set_interest(None)
    assert sig.interest is None
