"""Shared fixtures of the control-layer tests: small synthetic libraries and state models."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.control.inputs import ControlLibrary, StateModel
from gesture_sim.testing.synthetic import synthetic_library, synthetic_model


@pytest.fixture(scope="session")
def small_lib() -> ControlLibrary:
    return synthetic_library(20.0, seed=3)


@pytest.fixture(scope="session")
def small_model(small_lib: ControlLibrary) -> StateModel:
    return synthetic_model(small_lib, n_states=5, seed=4)


def _random_beliefs(rng: np.random.Generator, steps: int, n_states: int,
                    switch_p: float = 0.03) -> np.ndarray:
    """(steps, S) beliefs concentrated on a state that changes now and then."""
    s = [int(rng.integers(n_states))]
    for _ in range(steps - 1):
        s.append(s[-1] if rng.random() > switch_p else int(rng.integers(n_states)))
    b = np.full((steps, n_states), 0.1 / n_states) + rng.dirichlet(np.ones(n_states), steps) * 0.2
    b[np.arange(steps), s] += 0.7
    return b / b.sum(axis=1, keepdims=True)


@pytest.fixture(scope="session")
def random_beliefs():
    """The belief-sequence generator (a fixture so test modules need not import conftest)."""
    return _random_beliefs
