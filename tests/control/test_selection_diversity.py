"""The controller's selection-diversity options (issue 31): the novelty term ``repeat_cost``
(recently played segments are chosen less) and ``sample_state`` (which segment to enter is
decided on a hidden state drawn from the belief, not on the belief's average)."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.control.controller import GestureController, run_online
from gesture_sim.control.costs import ControlSettings
from gesture_sim.control.policy import train_policy
from gesture_sim.control.style import default_tones
from gesture_sim.errors import GestureSimError


@pytest.fixture(scope="module")
def trained(small_lib, small_model):
    return train_policy(small_lib, small_model, ControlSettings(), tones=default_tones(),
                        labels=("wave",))


def _recent_replays(run, fps: float, window_s: float) -> float:
    """Share of the switches (and starts) into a segment played within ``window_s`` before."""
    last: dict[int, int] = {}
    hits = total = 0
    prev = -1
    for t, a in enumerate(run.segments.tolist()):
        if a != prev:
            total += 1
            hits += int(a in last and (t - last[a]) / fps <= window_s)
        if prev >= 0:
            last[prev] = t
        prev = a
    return hits / max(total, 1)


def test_repeat_cost_off_is_the_controller_as_before(trained, small_lib, random_beliefs) -> None:
    policy = trained
    beliefs = random_beliefs(np.random.default_rng(11), 1200, policy.n_states)
    for temperature in (0.0, 2.0):
        base = run_online(GestureController(policy, small_lib, temperature=temperature,
                                            seed=3), beliefs)
        off = run_online(GestureController(policy, small_lib, temperature=temperature, seed=3,
                                           repeat_cost=0.0, repeat_tau_s=3.0,
                                           sample_state=False), beliefs)
        np.testing.assert_array_equal(base.segments, off.segments)
        np.testing.assert_array_equal(base.frames, off.frames)
        assert [d.costs for d in base.decisions] == [d.costs for d in off.decisions]
        assert not any("repeat" in d.costs for d in off.decisions)


def test_repeat_cost_chooses_a_segment_just_played_less_often(trained, small_lib,
                                                              random_beliefs) -> None:
    policy = trained
    fps = small_lib.fps
    rng = np.random.default_rng(2)
    shares_off, shares_on, distinct_off, distinct_on = [], [], [], []
    for _ in range(4):
        beliefs = random_beliefs(rng, 1500, policy.n_states)
        off = run_online(GestureController(policy, small_lib), beliefs)
        on = run_online(GestureController(policy, small_lib, repeat_cost=20.0,
                                          repeat_tau_s=5.0), beliefs)
        shares_off.append(_recent_replays(off, fps, 5.0))
        shares_on.append(_recent_replays(on, fps, 5.0))
        distinct_off.append(len(set(off.segments.tolist())))
        distinct_on.append(len(set(on.segments.tolist())))
        # the term is what the docstring says: repeat_cost * exp(-age / tau) of the entry
        seen: dict[int, float] = {}
        prev = -1
        for d in on.decisions:
            if "repeat" in d.costs and not d.costs["continue"]:
                age = d.t - seen.get(d.segment_id, -np.inf)
                assert d.costs["repeat"] == pytest.approx(20.0 * np.exp(-age / 5.0), abs=1e-9)
            if prev >= 0:
                seen[prev] = d.t          # the segment left at this decision was playing
            seen[d.segment_id] = d.t
            prev = d.segment_id
    assert np.mean(shares_on) < 0.5 * np.mean(shares_off), (shares_off, shares_on)
    assert np.mean(distinct_on) > np.mean(distinct_off)


def test_repeat_cost_never_delays_a_requested_label(trained, small_lib, random_beliefs) -> None:
    policy = trained
    delay = policy.meta["max_label_delay_frames"]
    wave = set(small_lib.segments_with_tag("wave").tolist())
    rng = np.random.default_rng(8)
    for _ in range(6):
        beliefs = random_beliefs(rng, 200, policy.n_states)
        at = int(rng.integers(20, 120))
        run = run_online(GestureController(policy, small_lib, repeat_cost=50.0), beliefs,
                         labels={at: "wave"})
        later = np.nonzero([s in wave for s in run.segments[at:]])[0]
        assert len(later) and later[0] <= delay + 1


def test_repeat_cost_settings_are_checked(trained, small_lib) -> None:
    with pytest.raises(GestureSimError):
        GestureController(trained, small_lib, repeat_cost=-1.0)
    with pytest.raises(GestureSimError):
        GestureController(trained, small_lib, repeat_cost=1.0, repeat_tau_s=0.0)


def test_sample_state_off_and_one_hot_beliefs_change_nothing(trained, small_lib,
                                                             random_beliefs) -> None:
    policy = trained
    beliefs = random_beliefs(np.random.default_rng(4), 1000, policy.n_states)
    base = run_online(GestureController(policy, small_lib, seed=2), beliefs)
    off = run_online(GestureController(policy, small_lib, seed=2, sample_state=False), beliefs)
    np.testing.assert_array_equal(base.segments, off.segments)
    assert [d.costs for d in base.decisions] == [d.costs for d in off.decisions]
    # a certain belief: the draw is that state, so the argmin decides as before
    one_hot = np.eye(policy.n_states)[beliefs.argmax(axis=1)]
    sure = run_online(GestureController(policy, small_lib), one_hot)
    drawn = run_online(GestureController(policy, small_lib, sample_state=True), one_hot)
    np.testing.assert_array_equal(sure.segments, drawn.segments)


def test_sample_state_plays_each_likely_state_instead_of_their_average(
        trained, small_lib, small_model) -> None:
    """Under a belief split between two states, the expected-value argmin plays segments
    between their kinematics; drawing the state plays segments near one or the other, and
    the played kinematics spread wider."""
    policy = trained
    n = policy.n_states
    params, means = small_lib.params, small_model.means
    ratios = []
    for i, j in [(0, 1), (1, 2), (2, 3), (0, 4)]:
        belief = np.zeros((1500, n))
        belief[:, [i, j]] = 0.5
        near, spread = [], []
        for sample in (False, True):
            segs = run_online(GestureController(policy, small_lib, seed=1, sample_state=sample),
                              belief).segments
            d = np.minimum(np.linalg.norm(params[segs] - means[i], axis=1),
                           np.linalg.norm(params[segs] - means[j], axis=1))
            near.append(d.mean())
            spread.append(params[segs].std(axis=0).mean())
        assert near[1] < near[0], (i, j, near)
        assert spread[1] > spread[0], (i, j, spread)
        ratios.append(near[1] / near[0])
    assert np.mean(ratios) < 0.8, ratios
