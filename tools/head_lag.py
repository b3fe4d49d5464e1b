"""Measure the head's PD tracking delay for a RUTH baton (issue 14).

Drives neck_flex/head_flex (40/60) with a raised-cosine nod (attack, decay) sampled at 30 Hz
(as the pipeline sends targets) from the standing pose and prints the delay (s) of the simulated
displacement peak and of the speed peak after the reference's. Usage:
    .venv/bin/python tools/head_lag.py [--amp-deg 5] [--attack 0.1] [--decay 0.25]
"""

from __future__ import annotations

import argparse

import numpy as np

from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import TargetStream
from gesture_sim.sim.tracking import HumanoidSim


def bump(t: np.ndarray, t0: float, attack: float, decay: float) -> np.ndarray:
    """Raised-cosine bump: 0 at t0, 1 at t0 + attack, 0 at t0 + attack + decay."""
    y = np.zeros_like(t)
    a = (t >= t0) & (t < t0 + attack)
    y[a] = 0.5 - 0.5 * np.cos(np.pi * (t[a] - t0) / attack)
    d = (t >= t0 + attack) & (t < t0 + attack + decay)
    y[d] = 0.5 + 0.5 * np.cos(np.pi * (t[d] - t0 - attack) / decay)
    return y


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--amp-deg", type=float, default=5.0)
    p.add_argument("--attack", type=float, default=0.1)
    p.add_argument("--decay", type=float, default=0.25)
    a = p.parse_args()
    sim = HumanoidSim(seed=0)
    sim.reset()
    rate, dur, t0 = 30.0, 2.0, 0.5
    t = np.arange(int(dur * rate) + 1) / rate
    env = bump(t, t0, a.attack, a.decay)
    q = np.tile(sim.standing_pose(), (len(t), 1))
    amp = np.deg2rad(a.amp_deg)
    neck, head = hm.actuated_index(["neck_flex", "head_flex"])
    q[:, neck] += 0.4 * amp * env
    q[:, head] += 0.6 * amp * env
    trace = sim.run(TargetStream(q, rate=rate))
    qa = hm.qpos_addresses(sim.model, ["neck_flex", "head_flex"])
    ang = trace.qpos[:, qa].sum(axis=1)
    ang -= ang[0]
    ref = trace.q_target[:, [neck, head]].sum(axis=1) - q[0, [neck, head]].sum()
    tt = trace.time - trace.time[0]
    spd, rspd = np.gradient(ang, tt), np.gradient(ref, tt)
    print(f"peak delay {tt[np.argmax(ang)] - tt[np.argmax(ref)]:.3f} s, "
          f"speed-peak delay {tt[np.argmax(spd)] - tt[np.argmax(rspd)]:.3f} s, "
          f"realised {np.rad2deg(ang.max()):.2f} of {a.amp_deg:.2f} deg")


if __name__ == "__main__":
    main()
