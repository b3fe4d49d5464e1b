"""Adapters from the motion library and the inference model to the control layer's arrays."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gesture_sim.control.inputs import ControlLibrary, StateModel
from gesture_sim.errors import GestureSimError

DEFAULT_LIBRARY = Path(__file__).resolve().parents[2] / "motion_library" / "default"


def test_state_model_from_inference_accepts_row_and_column_stochastic() -> None:
    rng = np.random.default_rng(0)
    p = rng.dirichlet(np.ones(3), 3)                            # row-stochastic
    hmm = SimpleNamespace(means=rng.normal(size=(3, 6)), covars=np.repeat(np.eye(6)[None], 3, 0))
    model = SimpleNamespace(hmm=hmm, transition_matrix=p, fingerprint="abc")
    sm = StateModel.from_inference(model)
    np.testing.assert_allclose(sm.transition, p)
    assert sm.n_states == 3
    # the fingerprint covers the parameters, not only the training data's hash
    other = SimpleNamespace(hmm=SimpleNamespace(means=hmm.means + 1.0, covars=hmm.covars),
                            transition_matrix=p, fingerprint="abc")
    assert StateModel.from_inference(other).fingerprint != sm.fingerprint
    assert StateModel.from_inference(model).fingerprint == sm.fingerprint
    crf_model = SimpleNamespace(hmm=hmm, crf=SimpleNamespace(T=p.T))      # the paper's T
    np.testing.assert_allclose(StateModel.from_inference(crf_model).transition, p)
    with pytest.raises(GestureSimError, match="rows"):
        StateModel(means=hmm.means, covs=hmm.covars, transition=p * 2)


def test_library_validation_refuses_bad_interruption_frames(small_lib) -> None:
    bad = small_lib.interrupt_frames.copy()
    bad[0] = bad[0][::-1]
    with pytest.raises(GestureSimError, match="interruption"):
        ControlLibrary(**{**small_lib.__dict__, "interrupt_frames": bad})


@pytest.mark.skipif(not DEFAULT_LIBRARY.is_dir(), reason="no shipped default library")
def test_adapter_on_shipped_library_reproduces_its_interruption_costs() -> None:
    from gesture_sim.motion.library import MotionLibrary

    ml = MotionLibrary.load(DEFAULT_LIBRARY)
    lib = ControlLibrary.from_motion_library(ml)
    assert lib.n_segments == len(ml.segments) and lib.fingerprint == ml.fingerprint
    # the frame features + fitted scale reproduce D_in, so mid-clip semantic entries are
    # priced on the same scale as ordinary interruptions
    rng = np.random.default_rng(1)
    for _ in range(50):
        a, b = rng.integers(lib.n_segments, size=2)
        k = int(rng.integers(lib.n_interrupts))
        f = lib.features(a)[lib.interrupt_frames[a, k]]
        d = lib.pose_scale * np.linalg.norm(f - lib.features(b)[0]) + lib.interrupt_penalty
        assert d == pytest.approx(lib.d_in[a, k, b], rel=1e-6, abs=1e-6)
