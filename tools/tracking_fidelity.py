"""How faithfully the physics tracks real motion capture: per-source figures over every frame.

Every real clip of a motion library (default ``motion_library/default``: the BEAT2 take and the
Bandai Namco gestures), plus motion files given on the command line (BVH / SMPL-X ``.npz``,
retargeted with the project's readers at the library's frame rate), is tracked by the
free-standing humanoid as the pipeline tracks it: the clip's joint angles at 30 Hz, the legs held
at the standing pose (balance controller), no assist. Per source (dataset) it reports, pooled
over ALL recorded rows (100 Hz, transitions included):

* hand and elbow error RMS (mm): simulated site vs the kinematic target pose posed with the
  simulated free root;
* G-MPJPE (mm): mean position error over the tracked bodies (trunk, neck, head, clavicles,
  arms, hands), same posing;
* foot skating (mm/s, mean while in contact), self-penetration (max and p99, mm; arm into torso
  or the other arm), the share of rows with a self contact;
* hand speed of the simulated body (p99, p99.9, peak, m/s) next to the same figures of the
  target motion.

Usage (from the repository root)::

    python tools/tracking_fidelity.py [--library DIR] [--json OUT.json] [--markdown]
                                      [--shaper tight|fast] [--max-clips N] [motion files ...]

Run it on one core (``taskset -c 0``) when timing matters; the figures themselves do not depend
on the machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gesture_sim.metrics.physics import physics_metrics  # noqa: E402
from gesture_sim.sim import humanoid as hm  # noqa: E402
from gesture_sim.sim.targets import TargetStream  # noqa: E402
from gesture_sim.sim.trace import SimTrace  # noqa: E402
from gesture_sim.sim.tracking import HumanoidSim  # noqa: E402

#: Bodies whose origins (joint centres) enter G-MPJPE: everything the clip drives above the legs.
TRACKED_BODIES = (
    "abdomen", "chest", "neck", "head",
    "left_clavicle", "left_upper_arm", "left_forearm", "left_hand",
    "right_clavicle", "right_upper_arm", "right_forearm", "right_hand",
)
HAND_SITES = hm.HAND_SITES
ELBOW_SITES = hm.ELBOW_SITES


@dataclass
class ClipFigures:
    """Pooled per-row errors of one tracked clip (arrays over rows)."""

    name: str
    source: str
    seconds: float
    hand_err: np.ndarray          # (T, 2) m
    elbow_err: np.ndarray         # (T, 2) m
    body_err: np.ndarray          # (T, B) m
    hand_speed: np.ndarray        # (T-1, 2) m/s, simulated
    target_hand_speed: np.ndarray  # (T-1, 2) m/s, kinematic target
    skate_sum: float              # sum of foot speeds over contact rows (m/s)
    skate_n: int
    self_pen: np.ndarray          # (T,) m
    self_contact: np.ndarray      # (T,) bool
    fell: bool
    extra: dict = field(default_factory=dict)


def source_of(clip_source: str, name: str) -> str:
    """A short dataset name for grouping ("BEAT2", "Bandai Namco", or the file's stem)."""
    s = clip_source.lower()
    if "beat2" in s or "scott" in name:
        return "BEAT2"
    if "bandai" in s or name.startswith("dataset-"):
        return "Bandai Namco"
    if "cmu" in s or "neutral_" in name:
        return "CMU (Xia 2015 style set)"
    return name


def standing_legs(q: np.ndarray) -> np.ndarray:
    """The clip's joint targets with the legs at the standing pose, as the pipeline does."""
    q = np.array(q, dtype=float)
    q[:, hm.actuated_index(hm.LEG_JOINTS)] = 0.0
    return q


def _poses(model: mujoco.MjModel, qpos_rows: np.ndarray, site_ids: np.ndarray,
           body_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Site and body positions of each qpos row by forward kinematics: (T, S, 3), (T, B, 3)."""
    d = mujoco.MjData(model)
    sites = np.zeros((len(qpos_rows), len(site_ids), 3))
    bodies = np.zeros((len(qpos_rows), len(body_ids), 3))
    for i, row in enumerate(qpos_rows):
        d.qpos[:] = row
        mujoco.mj_kinematics(model, d)
        sites[i] = d.site_xpos[site_ids]
        bodies[i] = d.xpos[body_ids]
    return sites, bodies


def clip_figures(sim: HumanoidSim, name: str, source: str, q: np.ndarray, fps: float
                 ) -> ClipFigures:
    """Track one clip (q: (T, n_act) at ``fps``) from a settled start in its first pose."""
    q = standing_legs(q)
    stream = TargetStream(q, rate=fps)
    sim.reset(q[0])
    trace: SimTrace = sim.run(stream)
    m = sim.model
    site_ids = np.array([m.site(s).id for s in (*HAND_SITES, *ELBOW_SITES)])
    body_ids = np.array([m.body(b).id for b in TRACKED_BODIES])
    sim_s, sim_b = _poses(m, trace.qpos, site_ids, body_ids)
    target_qpos = trace.qpos.copy()
    target_qpos[:, sim.qadr] = trace.q_target
    tgt_s, tgt_b = _poses(m, target_qpos, site_ids, body_ids)
    err_s = np.linalg.norm(sim_s - tgt_s, axis=-1)
    err_b = np.linalg.norm(sim_b - tgt_b, axis=-1)
    dt = trace.dt
    speed = np.linalg.norm(np.diff(sim_s[:, :2], axis=0), axis=-1) / dt
    # the target's hand speed: the stream itself at the row times, without the simulated root
    tq, _ = stream.resample(trace.time - trace.time[0])
    still = np.tile(hm.qpos_from_targets(m, np.zeros(sim.n)), (len(tq), 1))
    still[:, sim.qadr] = tq
    ref_s, _ = _poses(m, still, site_ids[:2], body_ids[:1])
    tspeed = np.linalg.norm(np.diff(ref_s, axis=0), axis=-1) / dt
    both = trace.foot_contact[1:] & trace.foot_contact[:-1]
    fspeed = np.linalg.norm(np.diff(trace.foot_pos[:, :, :2], axis=0), axis=-1) / dt
    pm = physics_metrics(trace)
    return ClipFigures(
        name=name, source=source, seconds=trace.duration, hand_err=err_s[:, :2],
        elbow_err=err_s[:, 2:], body_err=err_b, hand_speed=speed, target_hand_speed=tspeed,
        skate_sum=float(fspeed[both].sum()), skate_n=int(both.sum()),
        self_pen=trace.self_penetration, self_contact=trace.self_contact_count > 0,
        fell=pm.fell, extra={"joint_limit_max_excess_deg": pm.joint_limit_max_excess_deg,
                             "saturation_share_any": pm.saturation_share_any})


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def summarise(figs: list[ClipFigures]) -> dict:
    """Pooled figures of a group of clips (see the module docstring)."""
    cat = np.concatenate
    hand = cat([f.hand_err.ravel() for f in figs])
    elbow = cat([f.elbow_err.ravel() for f in figs])
    body = cat([f.body_err.ravel() for f in figs])
    hs = cat([f.hand_speed.ravel() for f in figs])
    ths = cat([f.target_hand_speed.ravel() for f in figs])
    pen = cat([f.self_pen for f in figs])
    n_skate = sum(f.skate_n for f in figs)
    return {
        "clips": len(figs), "seconds": round(sum(f.seconds for f in figs), 1),
        "fell": sum(f.fell for f in figs),
        "hand_rms_mm": 1000 * _rms(hand), "elbow_rms_mm": 1000 * _rms(elbow),
        "g_mpjpe_mm": 1000 * float(body.mean()),
        "hand_p95_mm": 1000 * float(np.percentile(hand, 95)),
        "skate_mm_s": 1000 * sum(f.skate_sum for f in figs) / max(n_skate, 1),
        "self_pen_max_mm": 1000 * float(pen.max()),
        "self_pen_p99_mm": 1000 * float(np.percentile(pen, 99)),
        "self_contact_share": float(np.mean(cat([f.self_contact for f in figs]))),
        "hand_speed_p99": float(np.percentile(hs, 99)),
        "hand_speed_p999": float(np.percentile(hs, 99.9)),
        "hand_speed_max": float(hs.max()),
        "target_hand_speed_p99": float(np.percentile(ths, 99)),
        "target_hand_speed_p999": float(np.percentile(ths, 99.9)),
        "target_hand_speed_max": float(ths.max()),
        "joint_limit_max_excess_deg": max(f.extra["joint_limit_max_excess_deg"] for f in figs),
        "saturation_share_any_max": max(f.extra["saturation_share_any"] for f in figs),
    }


def load_clips(library: Path | None, files: list[Path], max_clips: int | None
               ) -> list[tuple[str, str, np.ndarray, float]]:
    """(name, source, q (T, n_act), fps) of every clip to track."""
    out = []
    if library is not None:
        from gesture_sim.motion.library import MotionLibrary

        lib = MotionLibrary.load(library)
        col = [list(lib.joint_names).index(j) for j in hm.ACTUATED_JOINTS]
        for clip in lib.clips[:max_clips]:
            out.append((clip.name, source_of(clip.source, clip.name),
                        np.asarray(clip.qpos, dtype=float)[:, col], float(lib.fps)))
    if files:
        from gesture_sim.motion.build import read_motion
        from gesture_sim.motion.retarget import Retargeter
        from gesture_sim.motion.skeleton import resample

        rt = Retargeter()
        col = [list(rt.joint_names).index(j) for j in hm.ACTUATED_JOINTS]
        for path in files:
            motion = resample(read_motion(path, rt.model), 30.0)
            res = rt.retarget(motion)
            out.append((path.stem, source_of("", path.stem) + " (file)",
                        np.asarray(res.qpos, dtype=float)[:, col], 30.0))
    return out


def markdown(groups: dict[str, dict]) -> str:
    """The per-source table (BENCHMARKS.md)."""
    head = ("| source | clips | s | hand RMS mm | elbow RMS mm | G-MPJPE mm | skating mm/s | "
            "self-pen max / p99 mm | hand speed p99 / p99.9 / max m/s (target) |")
    lines = [head, "|" + " --- |" * 9]
    for name, g in groups.items():
        lines.append(
            f"| {name} | {g['clips']} | {g['seconds']:.0f} | {g['hand_rms_mm']:.1f} | "
            f"{g['elbow_rms_mm']:.1f} | {g['g_mpjpe_mm']:.1f} | {g['skate_mm_s']:.2f} | "
            f"{g['self_pen_max_mm']:.1f} / {g['self_pen_p99_mm']:.1f} | "
            f"{g['hand_speed_p99']:.2f} / {g['hand_speed_p999']:.2f} / {g['hand_speed_max']:.2f}"
            f" ({g['target_hand_speed_p99']:.2f} / {g['target_hand_speed_p999']:.2f} / "
            f"{g['target_hand_speed_max']:.2f}) |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="*", type=Path, help="extra motion files (.bvh / .npz)")
    ap.add_argument("--library", type=Path, default=REPO / "motion_library" / "default")
    ap.add_argument("--no-library", action="store_true", help="only the given files")
    ap.add_argument("--max-clips", type=int, default=None, help="first N library clips only")
    ap.add_argument("--json", type=Path, default=None, help="write the figures as JSON")
    ap.add_argument("--markdown", action="store_true", help="print the per-source table")
    ap.add_argument("--shaper", choices=("tight", "fast"), default="tight",
                    help="reference shaping: 'tight' (the default HumanoidSim, every joint "
                         "bounded by the jump limits) or 'fast' (HumanoidSim(fast_shaper=True): "
                         "smooth streams within real-motion bounds)")
    ap.add_argument("--timestep", type=float, default=None,
                    help="physics time step (s; default the model's 0.002)")
    ap.add_argument("--yaw-limit", type=float, default=None, metavar="NM",
                    help="HumanoidSim(yaw_reaction_limit=NM): bound of the upper body's yaw "
                         "reaction (N·m)")
    args = ap.parse_args(argv)
    clips = load_clips(None if args.no_library else args.library, args.files, args.max_clips)
    sim = HumanoidSim(seed=0, fast_shaper=args.shaper == "fast", timestep=args.timestep,
                      yaw_reaction_limit=args.yaw_limit)
    figs: list[ClipFigures] = []
    t0 = time.perf_counter()
    sim_s = 0.0
    for name, source, q, fps in clips:
        f = clip_figures(sim, name, source, q, fps)
        sim_s += f.seconds
        figs.append(f)
    wall = time.perf_counter() - t0
    by_source: dict[str, list[ClipFigures]] = {}
    for f in figs:
        by_source.setdefault(f.source, []).append(f)
    groups = {k: summarise(v) for k, v in by_source.items()}
    groups["all"] = summarise(figs)
    doc = {"groups": groups, "simulated_s": sim_s, "wall_s": wall,
           "clips": {f.name: {"source": f.source, "hand_rms_mm": 1000 * _rms(f.hand_err),
                              "self_pen_max_mm": 1000 * float(f.self_pen.max()),
                              "fell": f.fell} for f in figs}}
    if args.json:
        args.json.write_text(json.dumps(doc, indent=1))
    if args.markdown:
        print(markdown(groups))
    else:
        print(json.dumps(groups, indent=1))
    print(f"({len(figs)} clips, {sim_s:.0f} s simulated in {wall:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
