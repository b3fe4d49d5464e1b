#!/usr/bin/env python3
"""GPDM (Chiu 2014, §5.3) vs switch-ramp transitions, both measured against real motion.

Usage (from the repository root):

    .venv/bin/python tools/gpdm_transitions.py [LIBRARY] [--pairs 50] [--frames 6 15]
        [--seed 0] [--json OUT] [--save-model MODEL.npz]

Fits a :class:`gesture_sim.motion.gpdm.GPDM` on the library's co-speech clips (clips without
tags), then, for ``--pairs`` seeded random pairs (A, B) of co-speech segments (B not A's
successor) and each transition length n of ``--frames``, fills the n frames between A's last
frame A[-1] and B[n] (the same timeline for every method):

* ``ramp``: what :class:`gesture_sim.control.ramp.SwitchRamp` makes of the switch A → B: frame k
  (k = 1..n) is ``A[-1] + smoothstep(k/(n+1)) (B[k-1] − A[-1])``, then B[n], B[n+1], ...;
* ``gpdm``: :meth:`GPDM.transition` from A[-1] to B[n] (latent path optimised under the
  dynamics GP and the manifold term);
* ``gpdm_chiu``: the same with Chiu's own path energy (``--chiu-manifold-weight`` × manifold
  variance + ``--spread-weight`` × squared latent steps, no dynamics term);
* ``gpdm_line``: the same with the straight latent line (no path optimisation), an ablation;
* ``real``: the library's own frames across every real boundary between consecutive segments
  of a clip (A = the segment before, B = its successor, the n frames after the boundary).

Figures per method and n, over windows A[-3:] + transition + B[n:n+3]:

* joint-space jerk: the norm over the joints of the third difference × fps³ (rad/s³), mean
  and 95th percentile over the n + 3 jerk samples that touch the transition;
* hand speed: the left and right hand sites (MuJoCo kinematics of ``humanoid.xml``, root
  fixed at its standing pose) over the n + 1 steps A[-1] → ... → B[n] (m/s); its histogram
  (0–3 m/s, 30 bins + overflow) and the Hellinger distance to the real boundaries' one;
* end-point continuity: the pose step |T_1 − A[-1]| and |B[n] − T_n| (rad, joint-vector norm)
  and the velocity jump |v_in − v_A| and |v_out − v_B| (rad/s), v_A, v_B the last velocity of
  A and the first of B[n:].
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only contend

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.motion.gpdm import GPDM, THETA_NAMES  # noqa: E402
from gesture_sim.motion.library import MotionLibrary  # noqa: E402

CONTEXT = 3
SPEED_BINS = np.append(np.linspace(0.0, 3.0, 31), np.inf)


def ramp_frames(a_last: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """SwitchRamp(n) from a_last over B's first n frames (n, D)."""
    k = np.arange(1, n + 1) / (n + 1)
    w = (k * k * (3 - 2 * k))[:, None]
    return a_last + w * (b[:n] - a_last)


class HandFK:
    """Hand-site positions (M, 2, 3) of actuated joint vectors (M, n_act), root fixed."""

    def __init__(self, joint_names: tuple[str, ...]) -> None:
        import mujoco

        from gesture_sim.sim import humanoid as hm

        self.mj = mujoco
        self.model = hm.load_model(scene=False)
        self.data = mujoco.MjData(self.model)
        self.hm = hm
        names = list(joint_names)
        self.cols = np.array([names.index(j) for j in hm.ACTUATED_JOINTS])
        self.sites = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, s)
                      for s in ("left_hand_site", "right_hand_site")]

    def __call__(self, Q: np.ndarray) -> np.ndarray:
        out = np.zeros((len(Q), 2, 3))
        for t, q in enumerate(Q):
            self.data.qpos[:] = self.hm.qpos_from_targets(self.model, q[self.cols])
            self.mj.mj_kinematics(self.model, self.data)
            out[t] = self.data.site_xpos[self.sites]
        return out


def window_figures(W: np.ndarray, n: int, fps: float, fk: HandFK) -> dict:
    """Figures of one window W = A[-3:] + n transition frames + B[n:n+3] (n + 6, D)."""
    jerk = np.linalg.norm(np.diff(W, 3, axis=0), axis=1) * fps ** 3
    hands = fk(W[CONTEXT - 1:CONTEXT + n + 1])
    speed = np.linalg.norm(np.diff(hands, axis=0), axis=2).ravel() * fps
    a1, a0, t1 = W[CONTEXT - 2], W[CONTEXT - 1], W[CONTEXT]
    tn, b0, b1 = W[CONTEXT + n - 1], W[CONTEXT + n], W[CONTEXT + n + 1]
    return {
        "jerk": jerk, "speed": speed,
        "step_in": float(np.linalg.norm(t1 - a0)), "step_out": float(np.linalg.norm(b0 - tn)),
        "vjump_in": float(np.linalg.norm((t1 - a0) - (a0 - a1)) * fps),
        "vjump_out": float(np.linalg.norm((b0 - tn) - (b1 - b0)) * fps),
    }


def summarise(rows: list[dict], ref_hist: np.ndarray | None) -> dict:
    jerk = np.concatenate([r["jerk"] for r in rows])
    speed = np.concatenate([r["speed"] for r in rows])
    hist = np.histogram(speed, SPEED_BINS)[0].astype(float)
    hist /= max(hist.sum(), 1.0)
    out = {
        "n_windows": len(rows),
        "jerk_mean": float(jerk.mean()), "jerk_p95": float(np.percentile(jerk, 95)),
        "hand_speed_mean": float(speed.mean()), "hand_speed_p95": float(np.percentile(speed, 95)),
        "hand_speed_hist": hist.tolist(),
    }
    for k in ("step_in", "step_out", "vjump_in", "vjump_out"):
        out[k] = float(np.mean([r[k] for r in rows]))
    if ref_hist is not None:
        out["hellinger_vs_real"] = float(np.sqrt(max(0.0, 1.0 - np.sqrt(hist * ref_hist).sum())))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("library", nargs="?", default=str(ROOT / "motion_library" / "default"),
                    help="motion library folder (default: the shipped one)")
    ap.add_argument("--pairs", type=int, default=50, help="random segment pairs (default 50)")
    ap.add_argument("--frames", type=int, nargs="+", default=[6, 15],
                    help="transition lengths n (frames; default 6 15)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the fit runs and the pairs")
    ap.add_argument("--latent-dim", type=int, default=3)
    ap.add_argument("--components", type=int, default=16, help="PCA components")
    ap.add_argument("--runs", type=int, default=10, help="training runs")
    ap.add_argument("--run-length", type=int, default=32, help="frames per training run")
    ap.add_argument("--max-iter", type=int, default=200, help="L-BFGS iterations of the fit")
    ap.add_argument("--manifold-weight", type=float, default=1.0,
                    help="weight w of the mapping-variance term of the path energy")
    ap.add_argument("--chiu-manifold-weight", type=float, default=100.0,
                    help="w of the mapping-variance term in the gpdm_chiu energy (default 100)")
    ap.add_argument("--spread-weight", type=float, default=1.0,
                    help="λ of the squared latent steps in the gpdm_chiu energy (default 1)")
    ap.add_argument("--save-model", help="write the fitted GPDM (.npz)")
    ap.add_argument("--json", help="write the figures as JSON")
    args = ap.parse_args(argv)

    lib = MotionLibrary.load(args.library)
    fps = float(lib.fps)
    co = [k for k, c in enumerate(lib.clips) if not c.tags]
    if not co:
        ap.error("the library has no co-speech clip (clip without tags)")
    seqs = [lib.clips[k].qpos.astype(float) for k in co]
    model = GPDM.fit(seqs, d=args.latent_dim, n_components=args.components, n_runs=args.runs,
                     run_length=args.run_length, seed=args.seed, max_iter=args.max_iter)
    if args.save_model:
        model.save(args.save_model)
    print(f"GPDM: N={model.info['N']} frames, q={model.info['n_components']} "
          f"(explained {model.info['explained_variance']:.3f}), d={model.d}, "
          f"{model.info['iterations']} L-BFGS iterations, {model.info['seconds']:.1f} s")

    fk = HandFK(lib.joint_names)
    n_max = max(args.frames)
    segs = [s for s in lib.segments if s.clip in co]
    a_ok = [s for s in segs if s.length >= CONTEXT]
    b_ok = [s for s in segs if s.length >= n_max + CONTEXT + 1]
    rng = np.random.default_rng(args.seed)
    pairs: list[tuple[int, int]] = []
    while len(pairs) < args.pairs:
        a, b = a_ok[rng.integers(len(a_ok))], b_ok[rng.integers(len(b_ok))]
        if a.index != b.index and a.successor != b.index:
            pairs.append((a.index, b.index))
    bounds = []
    for s in segs:
        if s.successor >= 0:
            nxt = lib.segments[s.successor]
            n_fr = lib.clips[s.clip].n_frames
            if nxt.clip == s.clip and nxt.start == s.end and s.end - CONTEXT >= 0 \
                    and s.end + n_max + CONTEXT <= n_fr:
                bounds.append((s.clip, s.end))

    t0 = time.perf_counter()
    results: dict[str, dict] = {}
    for n in args.frames:
        real = []
        for c, b in bounds:
            q = lib.clips[c].qpos.astype(float)
            real.append(window_figures(q[b - CONTEXT:b + n + CONTEXT], n, fps, fk))
        per: dict[str, list] = {"ramp": [], "gpdm": [], "gpdm_chiu": [], "gpdm_line": []}
        for ia, ib in pairs:
            A, B = lib.segment_qpos(ia).astype(float), lib.segment_qpos(ib).astype(float)
            fills = {
                "ramp": ramp_frames(A[-1], B, n),
                "gpdm": model.transition(A[-1], B[n], n, args.manifold_weight),
                "gpdm_chiu": model.transition(A[-1], B[n], n, args.chiu_manifold_weight,
                                              dynamics_weight=0.0,
                                              spread_weight=args.spread_weight),
                "gpdm_line": model.transition(A[-1], B[n], n, optimise=False),
            }
            for name, T in fills.items():
                W = np.vstack([A[-CONTEXT:], T, B[n:n + CONTEXT]])
                per[name].append(window_figures(W, n, fps, fk))
        ref = summarise(real, None)
        ref_hist = np.asarray(ref["hand_speed_hist"])
        ref["hellinger_vs_real"] = 0.0
        results[f"real_{n}"] = ref
        for name, rows in per.items():
            results[f"{name}_{n}"] = summarise(rows, ref_hist)
    seconds = time.perf_counter() - t0

    cols = ("jerk_mean", "jerk_p95", "hellinger_vs_real", "hand_speed_mean", "step_in",
            "step_out", "vjump_in", "vjump_out")
    print(f"{len(pairs)} pairs, {len(bounds)} real boundaries, transitions {seconds:.1f} s")
    print(f"{'method':<14}" + "".join(f"{c:>18}" for c in cols))
    for key, r in results.items():
        print(f"{key:<14}" + "".join(f"{r[c]:>18.3f}" for c in cols))
    if args.json:
        info = {k: v for k, v in model.info.items() if k != "runs"}
        out = {"library": str(args.library), "fps": fps, "seed": args.seed,
               "pairs": pairs, "real_boundaries": bounds, "frames": args.frames,
               "speed_bins": SPEED_BINS[:-1].tolist() + ["inf"],
               "model": {**info, "theta": dict(zip(
                   THETA_NAMES, np.exp(model.theta).tolist(), strict=True))},
               "manifold_weight": args.manifold_weight,
               "chiu_manifold_weight": args.chiu_manifold_weight,
               "spread_weight": args.spread_weight, "transition_seconds": seconds,
               "results": results}
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
