"""`bench pipeline`'s baseline: the bare mj_step of the same model, measured in the same run."""

from __future__ import annotations

import math

from gesture_sim.commands.bench.pipeline import bare_step
from gesture_sim.sim import humanoid as hm


def test_the_bare_step_baseline_is_the_models_own_rate() -> None:
    model = hm.load_model()
    out = bare_step(model, steps=100)
    assert out["steps"] == 100 and out["steps_per_s"] > 0
    # simulated seconds per wall second = steps per second x the model's time step
    assert math.isclose(out["realtime_factor"], out["steps_per_s"] * model.opt.timestep,
                        rel_tol=1e-9)
