"""Does the lower body live? Sway and weight shifts of the simulated body against the mocap.

Runs the pipeline (``--method``, default controller; physics) on a speech file for each leg mode
(``GesturePipeline(legs=...)``: ``stand``, the legs held in the standing pose; ``clip``, the
clip's lower body over planted feet) and seed, and prints JSON with, per run:

* the plausibility figures of :func:`gesture_sim.metrics.physics.physics_metrics`: fall, foot
  skating (mm/s, mean over rows in contact), assist impulse (N·s per s; always 0: nothing
  holds the body), ground penetration (max, mm), self-penetration (max, mm);
* **CoM sway** (mm): the horizontal COM (``trace.com``) relative to the mid-point of the two
  sole centres, in the pelvis heading frame (x forward, y to the left): its standard deviation
  over time, lateral (``sway_y_mm``) and fore-aft (``sway_x_mm``); and the same SDs taken
  within consecutive 4 s windows and averaged (``sway_*_4s_mm``, which does not grow with the
  length of the run and so compares a 30 s run with the mocap's short standing stretches);
  ``sway_y_norm`` is the lateral 4 s sway divided by the feet's separation (a body standing
  twice as wide sways twice as far for the same weight shift);
* **weight-shift rate** (shifts per minute): the support split σ(t), the COM's projection on the
  line from the right to the left sole centre relative to their mid-point, as a fraction of
  their separation (0 midway, ±0.5 over a sole), smoothed by a 0.5 s moving average; a weight
  shift is a swing of σ by at least 0.1 (hysteresis: a reversal counts only once σ has come
  back 0.1 from its last extreme); ``shifts_per_min`` is their number per minute.

The same two figures are computed on the BEAT2 take's own motion: ``2_scott_0_1_1`` (the only
take of this speaker whose SMPL-X motion is available; the speech file is take 2_scott_0_2_2,
same speaker and session), as retargeted into the default library, played kinematically through
the humanoid model (its COM is the model's COM in the retargeted pose; ``--smplx`` adds the
SMPL-X pelvis as a proxy for comparison, read with :mod:`gesture_sim.motion.smplx`). The speaker
steps every few seconds (the feet lift up to 15 cm), which a planted stance does not do; so the
mocap figures are given over the whole take and over its standing stretches (both feet planted:
sole-centre speed below 0.1 m/s on a 0.5 s average and height below 5 cm, for at least 2 s;
each stretch about its own mean).

Usage (from the repository root)::

    python tools/lower_body.py [--audio WAV] [--start S] [--end S] [--seeds 0 1]
                               [--modes stand clip] [--method M] [--smplx NPZ] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter1d

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gesture_sim.sim import humanoid as hm  # noqa: E402

AUDIO = REPO / "tests/data/pipeline/beat2_scott_0_2_2.wav"
MOCAP_CLIP = "2_scott_0_1_1"
#: Hysteresis of a weight shift (fraction of the feet's separation) and the smoothing (s).
SHIFT_HYSTERESIS = 0.1
SHIFT_SMOOTH_S = 0.5
#: Window of the windowed sway (s).
SWAY_WINDOW_S = 4.0
#: Standing stretches of the mocap: sole speed (m/s, 0.5 s average), height (m), duration (s).
PLANTED_SPEED, PLANTED_HEIGHT, PLANTED_MIN_S = 0.1, 0.05, 2.0


def heading_of(quat: np.ndarray) -> np.ndarray:
    """(T, 2) unit forward direction (horizontal) of root quaternions (T, 4) w-x-y-z."""
    w, x, y, z = quat.T
    fx, fy = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z)
    n = np.maximum(np.hypot(fx, fy), 1e-9)
    return np.stack([fx / n, fy / n], axis=1)


def count_shifts(x: np.ndarray, h: float = SHIFT_HYSTERESIS) -> int:
    """Swings of ``x`` of at least ``h`` (hysteresis turning points), see the module docstring."""
    if not len(x):
        return 0
    n, d = 0, 0
    hi = lo = ext = float(x[0])
    for v in x.tolist():
        if d == 0:
            hi, lo = max(hi, v), min(lo, v)
            if hi - lo >= h:
                d, ext, n = (1 if v == hi else -1), v, n + 1
        elif d == 1:
            if v > ext:
                ext = v
            elif ext - v >= h:
                d, ext, n = -1, v, n + 1
        else:
            if v < ext:
                ext = v
            elif v - ext >= h:
                d, ext, n = 1, v, n + 1
    return n


def windowed_sd(x: np.ndarray, rate: float, window_s: float = SWAY_WINDOW_S) -> float:
    """Mean of the SDs of ``x`` (T,) over consecutive whole windows (NaN if none fits)."""
    w = int(round(window_s * rate))
    k = len(x) // w
    if k == 0:
        return float("nan")
    return float(np.mean([x[i * w:(i + 1) * w].std() for i in range(k)]))


def sway_figures(com: np.ndarray, feet: np.ndarray, heading: np.ndarray, rate: float,
                 spans: list[tuple[int, int]] | None = None) -> dict:
    """Sway and weight-shift figures of COM (T, 2+) over feet (T, 2, 2+) with the pelvis
    heading (T, 2), at ``rate`` Hz; over ``spans`` (row ranges, each about its own mean) or the
    whole series."""
    mid = 0.5 * (feet[:, 0, :2] + feet[:, 1, :2])
    rel = com[:, :2] - mid
    x = rel[:, 0] * heading[:, 0] + rel[:, 1] * heading[:, 1]
    y = -rel[:, 0] * heading[:, 1] + rel[:, 1] * heading[:, 0]
    a = feet[:, 0, :2] - feet[:, 1, :2]
    sep = np.linalg.norm(a, axis=1)
    split = np.einsum("tc,tc->t", rel, a) / np.maximum(sep, 0.05) ** 2
    split = uniform_filter1d(split, max(int(round(SHIFT_SMOOTH_S * rate)), 1), mode="nearest")
    spans = spans if spans is not None else [(0, len(com))]
    xs = np.concatenate([x[i:j] - x[i:j].mean() for i, j in spans])
    ys = np.concatenate([y[i:j] - y[i:j].mean() for i, j in spans])
    x4 = np.nanmean([windowed_sd(x[i:j], rate) for i, j in spans])
    y4 = np.nanmean([windowed_sd(y[i:j], rate) for i, j in spans])
    seconds = sum(j - i for i, j in spans) / rate
    shifts = sum(count_shifts(split[i:j]) for i, j in spans)
    width = float(np.mean(np.concatenate([sep[i:j] for i, j in spans])))
    return {
        "seconds": round(seconds, 2),
        "sway_x_mm": round(1000 * float(xs.std()), 1),
        "sway_y_mm": round(1000 * float(ys.std()), 1),
        "sway_x_4s_mm": round(1000 * float(x4), 1),
        "sway_y_4s_mm": round(1000 * float(y4), 1),
        "feet_separation_mm": round(1000 * width, 0),
        "sway_y_norm": round(float(y4) / width, 3),
        "split_sd": round(float(np.concatenate([split[i:j] - split[i:j].mean()
                                                for i, j in spans]).std()), 3),
        "shifts": int(shifts),
        "shifts_per_min": round(60.0 * shifts / seconds, 1) if seconds else None,
    }


def planted_spans(feet: np.ndarray, rate: float) -> list[tuple[int, int]]:
    """Row ranges where both feet stand still on the floor (module docstring)."""
    v = np.linalg.norm(np.gradient(feet[:, :, :2], axis=0), axis=-1) * rate
    v = uniform_filter1d(v, max(int(round(0.5 * rate)), 1), axis=0, mode="nearest")
    ok = np.all((v < PLANTED_SPEED) & (feet[:, :, 2] < PLANTED_HEIGHT), axis=1)
    spans, i, n = [], 0, len(ok)
    while i < n:
        if ok[i]:
            j = i
            while j < n and ok[j]:
                j += 1
            if j - i >= PLANTED_MIN_S * rate:
                spans.append((i, j))
            i = j
        else:
            i += 1
    return spans


def mocap_figures(library_dir: str | None = None, clip_name: str = MOCAP_CLIP) -> dict:
    """The BEAT2 take as retargeted into the library, played kinematically (module docstring)."""
    import mujoco

    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(library_dir or DEFAULT_LIBRARY_DIR)
    clip = next(c for c in lib.clips if c.name == clip_name)
    m = hm.load_model(scene=False)
    d = mujoco.MjData(m)
    qadr = hm.qpos_addresses(m, list(lib.joint_names))
    sites = [m.site(s).id for s in hm.FOOT_SITES]
    pelvis = m.body("pelvis").id
    n = clip.n_frames
    com, feet = np.zeros((n, 3)), np.zeros((n, 2, 3))
    for t in range(n):
        d.qpos[:3], d.qpos[3:7] = clip.root_pos[t], clip.root_quat[t]
        d.qpos[qadr] = clip.qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        com[t], feet[t] = d.subtree_com[pelvis], d.site_xpos[sites]
    heading = heading_of(np.asarray(clip.root_quat, dtype=float))
    spans = planted_spans(feet, clip.fps)
    pelvis_xy = np.asarray(clip.root_pos, dtype=float)
    return {
        "clip": clip_name, "frames": n, "fps": clip.fps,
        "com_source": "humanoid COM of the retargeted pose (kinematic playback)",
        "whole": sway_figures(com, feet, heading, clip.fps),
        "standing": sway_figures(com, feet, heading, clip.fps, spans),
        "standing_spans_s": [(round(i / clip.fps, 1), round(j / clip.fps, 1)) for i, j in spans],
        "pelvis_proxy_standing": sway_figures(pelvis_xy, feet, heading, clip.fps, spans),
    }


def smplx_pelvis_figures(path: Path) -> dict:
    """The SMPL-X take itself, the pelvis as the COM proxy (feet: the SMPL-X ankle joints)."""
    from gesture_sim.motion.smplx import read_smplx

    mo = read_smplx(path)
    names = list(mo.names)
    p = mo.positions                                   # (T, J, 3), Y up, faces +Z, left +X
    zup = np.stack([p[..., 2], p[..., 0], p[..., 1]], axis=-1)   # x fwd, y left, z up
    pel = zup[:, names.index("pelvis")]
    feet = np.stack([zup[:, names.index("left_ankle")], zup[:, names.index("right_ankle")]], 1)
    feet = feet.copy()
    feet[..., 2] -= feet[..., 2].min()
    hip = zup[:, names.index("left_hip")] - zup[:, names.index("right_hip")]
    heading = np.stack([hip[:, 1], -hip[:, 0]], axis=1)
    heading /= np.maximum(np.linalg.norm(heading, axis=1, keepdims=True), 1e-9)
    spans = planted_spans(feet, mo.fps)
    return {"file": str(path), "com_source": "SMPL-X pelvis joint (proxy), ankles as the feet",
            "whole": sway_figures(pel, feet, heading, mo.fps),
            "standing": sway_figures(pel, feet, heading, mo.fps, spans)}


def run_figures(mode: str, seed: int, samples: np.ndarray, method: str = "controller") -> dict:
    """One pipeline run (``method``, physics) in leg mode ``mode``."""
    from gesture_sim.feed import run_file
    from gesture_sim.metrics.physics import physics_metrics
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(seed=seed, legs=mode, method=method)
    t0 = time.perf_counter()
    res = run_file(pipe, y=samples, sr=16000)
    wall = time.perf_counter() - t0
    tr = pipe.trace()
    pm = physics_metrics(tr)
    rate = 1.0 / tr.dt
    heading = heading_of(tr.qpos[:, 3:7])
    out = {
        "mode": mode, "method": method, "seed": seed, "seconds": round(res.duration, 2),
        "real_time_factor": round(res.duration / wall, 2),
        "fell": pm.fell, "foot_skate_mm_s": round(pm.foot_skate_mm_s, 3),
        "assist_impulse_per_s": pm.assist_impulse_per_s,
        "ground_penetration_max_mm": round(pm.ground_penetration_max_mm, 2),
        "self_penetration_max_mm": round(pm.self_penetration_max_mm, 2),
        "com_margin_min_mm": round(1000 * pm.com_margin_min_m, 1),
        "knee_flex_mean_deg": round(float(np.rad2deg(tr.q[:, [
            hm.ACTUATED_JOINTS.index(f"{s}_knee_flex") for s in ("left", "right")]]).mean()), 1),
    }
    out.update(sway_figures(tr.com, tr.foot_pos, heading, rate))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--audio", default=str(AUDIO))
    ap.add_argument("--start", type=float, default=0.0, help="excerpt start (s)")
    ap.add_argument("--end", type=float, default=None, help="excerpt end (s)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--modes", nargs="+", default=["stand", "clip"])
    ap.add_argument("--method", default="controller",
                    help="the selection method (levine09: its own lower-body stream)")
    ap.add_argument("--smplx", default=None, help="also the SMPL-X take's pelvis (proxy)")
    ap.add_argument("--no-mocap", action="store_true")
    ap.add_argument("--json", default=None, help="also write the JSON here")
    args = ap.parse_args(argv)

    from gesture_sim.audio.sources import load_audio

    y, _ = load_audio(args.audio)
    a = int(args.start * 16000)
    b = len(y) if args.end is None else int(args.end * 16000)
    out: dict = {"audio": str(args.audio), "excerpt_s": [args.start, round(b / 16000, 2)],
                 "runs": []}
    for mode in args.modes:
        for seed in args.seeds:
            out["runs"].append(run_figures(mode, seed, y[a:b], args.method))
    if not args.no_mocap:
        out["mocap"] = mocap_figures()
        if args.smplx:
            out["mocap_smplx_pelvis"] = smplx_pelvis_figures(Path(args.smplx))
    text = json.dumps(out, indent=1)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
