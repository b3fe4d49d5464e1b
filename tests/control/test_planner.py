"""The planner (issue 51) on tiny libraries with known answers: a planted stressed syllable gets
a segment's own stroke apex; the join, warp and repetition costs decide as they should."""

from __future__ import annotations

import numpy as np

from gesture_sim.control.planner import (
    Plan,
    PlanItem,
    PlanLibrary,
    PlanSettings,
    Speech,
    merge_phrases,
    plan_phrase,
    plan_speech,
)

FPS = 30.0


def _lib(peaks: list[list[float]], lengths: list[int], join: np.ndarray | None = None,
         speed_z: np.ndarray | None = None) -> PlanLibrary:
    n = len(lengths)
    j = np.zeros((n, n)) if join is None else np.asarray(join, dtype=float).copy()
    np.fill_diagonal(j, np.inf)
    return PlanLibrary(pool=np.arange(n), lengths=np.asarray(lengths),
                       peaks=[np.asarray(p, dtype=float) for p in peaks], join=j,
                       speed_z=np.zeros(n) if speed_z is None else speed_z, fps=FPS)


def _strokes(lib: PlanLibrary, items: list[PlanItem]) -> np.ndarray:
    return np.concatenate([it.t_start + lib.peaks[it.segment] / FPS / it.rate for it in items])


def test_a_planted_stressed_syllable_gets_a_stroke_apex() -> None:
    # one stroke 0.5 s into a 1-s segment; a second segment of 0.5 s without strokes to fill
    lib = _lib([[15.0], []], [31, 16])
    cfg = PlanSettings(rates=(1.0,), max_hold_s=0.2, repeat_cost=0.0, energy_weight=0.0,
                       prior_weight=0.0, lead_in_s=0.3)
    for target in (1.37, 2.02, 2.71):
        speech = Speech(5.0, np.array([target]), [(1.0, 3.5)])
        items, cost = plan_phrase(lib, 1.0, 3.5, speech, cfg)
        s = _strokes(lib, items)
        assert np.min(np.abs(s - target)) <= 1.0 / FPS + 1e-9, (target, s)
        assert cost < 0                       # the hit earns more than the plan costs
        # contiguous: each item starts when the one before ends (or after a hold <= 0.2 s)
        for a, b in zip(items[:-1], items[1:], strict=True):
            assert -1e-9 <= b.t_start - a.t_end <= 0.2 + 1.5 / FPS


def test_the_learnt_lead_shifts_the_apex() -> None:
    lib = _lib([[15.0], []], [31, 16])
    cfg = PlanSettings(rates=(1.0,), repeat_cost=0.0, energy_weight=0.0, prior_weight=0.0,
                       lead_s=0.1)
    speech = Speech(5.0, np.array([2.0]), [(1.0, 3.5)])
    items, _ = plan_phrase(lib, 1.0, 3.5, speech, cfg)
    assert np.min(np.abs(_strokes(lib, items) - 2.1)) <= 1.0 / FPS + 1e-9


def test_join_costs_choose_the_sequence() -> None:
    # three stroke-less segments of 1 s; going 0 -> 1 is free, 0 -> 2 dear, 1 -> 2 free ...
    join = np.array([[0, 0, 50], [50, 0, 0], [0, 50, 0]], dtype=float)
    lib = _lib([[], [], []], [31, 31, 31], join)
    cfg = PlanSettings(rates=(1.0,), max_hold_s=0.0, repeat_cost=0.0, energy_weight=0.0,
                       prior_weight=0.0, lead_in_s=0.0)
    speech = Speech(10.0, np.zeros(0), [(0.0, 5.0)])
    items, cost = plan_phrase(lib, 0.0, 5.0, speech, cfg)
    seq = [it.segment for it in items]
    assert all(join[a, b] == 0 for a, b in zip(seq[:-1], seq[1:], strict=True)), seq
    assert cost == 0.0
    # dearer everywhere but one cycle: the plan follows the cycle
    assert len(set(seq)) == 3


def test_warp_is_paid_only_when_the_stroke_needs_it() -> None:
    lib = _lib([[15.0]], [31])
    speech = Speech(3.0, np.array([1.45]), [(1.0, 1.6)])
    base = dict(max_hold_s=0.0, repeat_cost=0.0, energy_weight=0.0, prior_weight=0.0,
                lead_in_s=0.0)
    # from t = 1.0 at rate 1 the apex lands at 1.5; at 1.13 at 1.44: worth it when cheap ...
    cheap = plan_phrase(lib, 1.0, 1.6, speech, PlanSettings(rates=(1.0, 1.13), rate_weight=1.0,
                                                             **base))[0]
    assert cheap[0].rate == 1.13
    # ... not when a rate change costs more than the hit earns
    dear = plan_phrase(lib, 1.0, 1.6, speech, PlanSettings(rates=(1.0, 1.13),
                                                            rate_weight=1e4, **base))[0]
    assert dear[0].rate == 1.0


def test_repetition_costs_spread_the_choice() -> None:
    # segment 0 is the cheapest to join to anything; with a repetition cost the plan uses all
    join = np.full((4, 4), 5.0)
    join[:, 0] = 0.0
    join[0, :] = 0.0
    lib = _lib([[]] * 4, [31] * 4, join)
    speech = Speech(20.0, np.zeros(0), [(0.0, 12.0)])
    base = dict(rates=(1.0,), max_hold_s=0.0, energy_weight=0.0, prior_weight=0.0,
                lead_in_s=0.0)
    free = plan_phrase(lib, 0.0, 12.0, speech, PlanSettings(repeat_cost=0.0, **base))[0]
    spread = plan_phrase(lib, 0.0, 12.0, speech, PlanSettings(repeat_cost=100.0,
                                                              repeat_window=3, **base))[0]
    seq_free = [it.segment for it in free]
    seq = [it.segment for it in spread]
    assert seq_free.count(0) >= len(seq_free) // 2 - 1     # 0, x, 0, y, ...
    for i in range(len(seq) - 2):                          # no repeat within 3 items
        assert len(set(seq[i:i + 3])) == 3, seq


def test_the_belief_prior_steers_the_choice() -> None:
    lib = _lib([[], []], [31, 31])
    lib.eta = np.array([[0.0, 5.0], [5.0, 0.0]])            # segment i fits state i
    belief = np.zeros((200, 2))
    belief[:, 1] = 1.0                                       # the belief is on state 1
    cfg = PlanSettings(rates=(1.0,), max_hold_s=0.0, repeat_cost=0.0, energy_weight=0.0,
                       prior_weight=1.0, lead_in_s=0.0)
    speech = Speech(6.0, np.zeros(0), [(0.0, 0.9)], belief=belief)
    assert [it.segment for it in plan_phrase(lib, 0.0, 0.9, speech, cfg)[0]] == [1]
    belief[:, ::-1] = belief.copy()
    speech = Speech(6.0, np.zeros(0), [(0.0, 0.9)], belief=belief)
    assert [it.segment for it in plan_phrase(lib, 0.0, 0.9, speech, cfg)[0]] == [0]


def test_the_whole_plan_rests_in_pauses_and_looks_up_its_frames() -> None:
    assert merge_phrases([(0, 1), (1.3, 2), (3, 4)], 0.6) == [(0, 2), (3, 4)]
    lib = _lib([[15.0], [10.0]], [31, 25])
    speech = Speech(8.0, np.array([1.0, 2.2, 5.5]), [(0.5, 2.5), (5.0, 6.5)])
    plan = plan_speech(lib, speech, PlanSettings(energy_weight=0.0, prior_weight=0.0))
    assert isinstance(plan, Plan) and len(plan.phrases) == 2
    assert plan.phrases[0][1] <= 2.5 + 0.4 + 1e-9 and plan.phrases[1][0] >= 5.0 - 0.3 - 1e-9
    assert plan.at(3.5) == (-1, 0.0)                          # the pause between: rest
    i, p = plan.at(plan.items[0].t_start + 0.2)
    assert i == 0 and abs(p - 0.2 * plan.items[0].rate * FPS) < 1e-6
    for target in speech.targets:
        assert np.min(np.abs(plan.strokes - target)) <= 0.1
