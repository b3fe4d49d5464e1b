"""Jaw vs the speech envelope: correlation at zero lag and at the best lag (0-150 ms), for the
simulated jaw and for its (causal) target, on the espeak-ng stimulus of
``tests/signals/test_signals_pipeline.py`` (BENCHMARKS.md, "Face and head signals").

    python tools/jaw_lag.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "pipeline"))

from stimuli import concat, say, silence, write  # noqa: E402

from gesture_sim.feed import run_file  # noqa: E402
from gesture_sim.pipeline import GesturePipeline  # noqa: E402

LOUD = {"pitch": 75, "amplitude": 126}


def _lags(x: np.ndarray, env: np.ndarray) -> list[float]:
    return [float(np.corrcoef(x[k:], env[:len(env) - k])[0, 1]) for k in range(16)]


def main() -> None:
    parts = [silence(0.3), say("this is a plain sentence that we say at first, then we go on"),
             silence(0.6), say("we went to the"), say("market", **LOUD),
             say("in the morning and"), silence(2.0), say("then we walked to the"),
             say("river", **LOUD), say("by the old house"), silence(0.5)]
    x, _ = concat(parts)
    with tempfile.TemporaryDirectory() as tmp:
        wav = write(Path(tmp) / "emph.wav", x)
        pipe = GesturePipeline.create(seed=0)
        run_file(pipe, wav)
    tr, m = pipe.trace(), pipe.sim.model
    t = tr.time - tr.time[0]
    fr = pipe.tracker.frames()
    env = np.where(fr.silent | ~np.isfinite(fr.intensity_db), np.nan, fr.intensity_db)
    floor = np.nanpercentile(env, 5)
    env = np.nan_to_num(env, nan=floor).clip(floor)
    sim = np.interp(fr.times, t, tr.qpos[:, m.jnt_qposadr[m.joint("jaw_open").id]])
    target = np.interp(fr.times, t, tr.q_target[:, list(tr.joint_names).index("jaw_open")])
    for name, series in (("simulated jaw", sim), ("jaw target", target)):
        rs = _lags(series, env)
        print(f"{name}: r {rs[0]:.2f} at 0 ms, {max(rs):.2f} at {10 * int(np.argmax(rs))} ms")


if __name__ == "__main__":
    main()
