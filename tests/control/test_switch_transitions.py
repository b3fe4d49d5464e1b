"""How a segment switch is crossed: the carried start of the switch ramp, a transition path
(the straight line is the ramp itself; a GPDM is Chiu 2014's), and the eased playback rate.
Known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gesture_sim.control.mimic import MimicChooser, build_graph
from gesture_sim.control.ramp import SwitchRamp, carried, smoothstep
from gesture_sim.control.synchrony import SpeechCue, SyncPlayer, SyncSettings


def test_carried_starts_at_the_velocity_and_comes_to_rest_v_tau_beyond() -> None:
    q0, v = np.array([1.0, -2.0]), np.array([0.1, 0.3])
    np.testing.assert_allclose(carried(q0, v, 1, 1e9), q0 + v)        # first step: v itself
    np.testing.assert_allclose(carried(q0, v, 10_000, 4.0), q0 + 4.0 * v)
    np.testing.assert_allclose(carried(q0, v, 2, 4.0), q0 + v * 4.0 * (1 - math.exp(-0.5)))
    assert carried(q0, None, 3, 4.0) is q0 and carried(q0, v, 3, 0.0) is q0


def test_a_carried_ramp_into_the_same_motion_is_invisible() -> None:
    """A switch into a stream that continues the outgoing motion's line: carried on (τ → ∞)
    the ramp returns that line exactly; held still (the old ramp) it lags behind it."""
    q0, v = np.zeros(3), np.array([0.02, -0.01, 0.03])
    line = [q0 + v * k for k in range(1, 10)]
    carry, held = SwitchRamp(6, carry_tau=1e12), SwitchRamp(6)
    carry.start(q0, v)
    held.start(q0, v)
    out_c = np.array([carry(q) for q in line])
    out_h = np.array([held(q) for q in line])
    np.testing.assert_allclose(out_c, line, atol=1e-9)
    assert np.abs(out_h[:6] - np.array(line[:6])).max() > 0.5 * np.abs(v).max()
    np.testing.assert_array_equal(out_h[6:], line[6:])                 # after n steps: q


def test_the_straight_line_path_is_the_ramp_itself() -> None:
    """``P_k = q_from + w_k (q_1 − q_from)`` as the path gives the plain ramp exactly, on a
    moving new stream; the path is asked once, from the last target to the stream's first
    value."""
    rng = np.random.default_rng(0)
    q_from, stream = rng.normal(size=4), rng.normal(size=(9, 4)).cumsum(0)
    asked = []

    def line(a, b, n):
        asked.append((a.copy(), b.copy(), n))
        w = np.array([smoothstep(k / (n + 1)) for k in range(1, n + 1)])[:, None]
        return a + w * (b - a)

    plain, pathed = SwitchRamp(5), SwitchRamp(5, path=line)
    plain.start(q_from)
    pathed.start(q_from)
    np.testing.assert_allclose([pathed(q) for q in stream], [plain(q) for q in stream])
    assert len(asked) == 1 and asked[0][2] == 5
    np.testing.assert_array_equal(asked[0][0], q_from)
    np.testing.assert_array_equal(asked[0][1], stream[0])


@pytest.fixture()
def player_with(small_lib, small_model):
    def make(**kw) -> SyncPlayer:
        chooser = MimicChooser(build_graph(small_lib, alpha=0.5), small_lib, seed=0,
                               model=small_model)
        return SyncPlayer(small_lib, chooser, SyncSettings(**kw))
    return make


def _rates(player: SyncPlayer, n_states: int, seconds: float = 12.0) -> np.ndarray:
    """Speech with an accent every 0.7 s and the energy swinging: the steps' playback rates."""
    fps = player.library.fps
    belief = np.full(n_states, 1.0 / n_states)
    rates = []
    for k in range(int(seconds * fps)):
        t = k / fps
        accents = [t] if k % int(0.7 * fps) == 0 else []
        energy = 0.8 * math.sin(2 * math.pi * 0.9 * t)
        rates.append(player.step(t, belief, SpeechCue(True, 0.0, accents, energy)).rate)
    return np.array(rates)


def test_the_eased_playback_rate_never_jumps_up(player_with, small_model) -> None:
    """With ``rate_tau_s`` the rate rises by at most (1 − e^(−dt/τ)) of the largest rate a
    step (the real-hand speed bound may still lower it at once); without, it jumps."""
    tau, cap = 0.1, 1.5 * 1.5                    # rate_max × the largest energy factor
    eased = _rates(player_with(rate_tau_s=tau), small_model.n_states)
    stepped = _rates(player_with(rate_tau_s=0.0), small_model.n_states)
    dt = 1.0 / 30.0
    bound = (1.0 - math.exp(-dt / tau)) * cap + 1e-9
    assert np.diff(eased).max() <= bound
    assert np.diff(stepped).max() > bound
    assert eased.mean() > 0.5 * stepped.mean()   # it eases the rate, it does not stop it
