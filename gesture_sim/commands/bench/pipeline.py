"""``gesture-sim bench pipeline``: the causal pipeline's cost and latency without rendering.

For each audio file: the whole chain (prosody -> CRF belief -> controller -> PD-tracked physics)
in simulated real time on two cores (``--cores``; with two or more the feed runs the physics
beside the rest, :data:`gesture_sim.feed.PHYSICS_WORKER`; ``--cores 1``: everything on one),
reporting the real-time factor, the seconds per stage, the
cost of one control step (inference + decision), the prosody latency (syllable end -> emission),
the end-to-end latency from a syllable's end to the first target change it can cause (the first
control step at or after its emission), and the peak memory (ru_maxrss) of the run. The baselines
measured in the same run are the same pipeline without physics, which shows what the physics
costs, and the bare ``mj_step`` of the same model (standing, position targets held, the fastest
of 5 runs of 2000 steps): the physics' own limit, and the pipeline's share of it
(``pipeline_to_bare_step``; on a shared machine also ``pipeline_to_bare_step_cpu``, the same
ratio in CPU seconds of the run, a physics process's included, which other processes' time
slices do not move, and ``mj_step_cpu_s``,
the CPU seconds inside ``mj_step`` in the pipeline's own run, with ``mj_step_share_cpu``, its
share of the run's CPU seconds). ``--defer-physics`` sets how much physics the feed may defer
(:data:`gesture_sim.feed.DEFER_PHYSICS_S`; the same physics either way). With
``--conversation`` it measures the two-person scene instead (a stereo file, one
person per channel; default: the scripted two-voice espeak-ng dialogue of the tests) against one
person on the same audio in the same run: what the second body costs.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

from gesture_sim import REPO_DIR
from gesture_sim.commands import print_json
from gesture_sim.errors import GestureSimError
from gesture_sim.methods import METHODS

DEFAULT_FILES = (
    REPO_DIR / "assets" / "audio" / "jfk.wav",
    REPO_DIR / "tests" / "data" / "pipeline" / "beat2_scott_0_2_2.wav",
)


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "pipeline", help="cost and latency of the causal pipeline without rendering",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    parser.add_argument("audio", nargs="*", type=Path,
                        help="speech files (default: the demo speech and a 62 s BEAT2 take)")
    parser.add_argument("--method", default="controller", choices=METHODS,
                        help="the selection method to time (default controller)")
    parser.add_argument("--conversation", nargs="?", const="dialogue", default=None,
                        metavar="STEREO",
                        help="measure the two-person scene on a stereo file (default: the "
                             "scripted espeak-ng dialogue) against one person on its mix")
    parser.add_argument("--defer-physics", type=float, default=None, metavar="S",
                        help="stream seconds of physics the feed may defer and run in one "
                             "stretch (the same physics; default the feed's DEFER_PHYSICS_S, "
                             "0.3; 0: after every control step, as before issue 35 item 3)")
    parser.add_argument("--cores", type=int, default=2, metavar="N",
                        help="CPUs to run on (default 2, fewer where there are fewer): with two "
                             "or more the feed runs the physics beside the audio analysis and "
                             "the control steps, in a process of its own (the same physics; "
                             "GESTURE_SIM_PHYSICS_WORKER=thread|off to choose); 1: all on one "
                             "core. The bare step always runs on one thread")
    parser.add_argument("--body", default="humanoid", metavar="BODY",
                        help="the body driven (humanoid, g1, h1 or a robot map .json; the bare "
                             "step is then that robot's model, standing)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def _pin_cores(n: int) -> int:
    """Pin this process to its ``n`` lowest usable CPUs (fewer where it has fewer); returns
    the number it runs on (0: the OS cannot pin)."""
    import os

    try:
        cpus = sorted(os.sched_getaffinity(0))[:max(int(n), 1)]
        os.sched_setaffinity(0, set(cpus))
        return len(cpus)
    except (AttributeError, OSError):
        return 0


def _cpu_s() -> float:
    """CPU seconds of this process and of its ended children (a feed's physics process)."""
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


def bench_file(path: Path, method: str, body: str = "humanoid") -> dict:
    """Measure one file (see the module docstring)."""
    from gesture_sim.feed import run_file
    from gesture_sim.metrics.selection import latency_summary, selection_summary
    from gesture_sim.pipeline import GesturePipeline

    out: dict = {"audio": str(path)}
    for physics in (False, True):
        pipe = GesturePipeline.create(method=method, physics=physics, body=body)
        run_file(pipe, path)                     # warm-up (imports, caches)
        loop = pipe.sim.loop if pipe.sim is not None else None
        if loop is not None:
            loop.timed, loop.step_cpu_s = True, 0.0
        t0, c0 = time.perf_counter(), _cpu_s()
        run = run_file(pipe, path)
        wall, cpu = time.perf_counter() - t0, _cpu_s() - c0
        key = "with_physics" if physics else "without_physics"
        steps = max(len(pipe.log.step_times), 1)
        out[key] = {
            "realtime_factor": run.duration / wall,
            "cpu_s": cpu, "realtime_factor_cpu": run.duration / cpu,
            "stage_seconds": {k: round(v, 4) for k, v in run.costs.items()},
            "control_step_us": 1e6 * (run.costs["inference"] + run.costs["control"]) / steps,
        }
        if loop is not None:
            out[key]["mj_step_cpu_s"] = loop.step_cpu_s
            out[key]["mj_step_share_cpu"] = loop.step_cpu_s / max(cpu, 1e-9)
            loop.timed = False
        if physics:
            out["duration_s"] = run.duration
            out["latency"] = latency_summary(run)
            out["selection"] = selection_summary(run)
    out["physics_cost_ratio"] = (out["without_physics"]["realtime_factor"]
                                 / out["with_physics"]["realtime_factor"])
    if pipe.body.is_robot:                       # the robot standing, its stand pose held
        import mujoco

        pipe.sim.reset()
        start = mujoco.MjData(pipe.sim.model)
        mujoco.mj_copyData(start, pipe.sim.model, pipe.sim.data)
        out["body"] = pipe.body.name
        out["bare_step"] = bare_step(pipe.sim.model, start=start, ctrl=pipe.sim.stand)
    else:
        out["bare_step"] = bare_step(pipe.sim.model)
    out["pipeline_to_bare_step"] = (out["with_physics"]["realtime_factor"]
                                    / out["bare_step"]["realtime_factor"])
    out["pipeline_to_bare_step_cpu"] = (out["with_physics"]["realtime_factor_cpu"]
                                        / out["bare_step"]["realtime_factor_cpu"])
    out["keyword_spotter"] = bench_spotter(path, pipe.labels)
    return out


def bare_step(model, steps: int = 2000, start=None, repeats: int = 5, ctrl=None) -> dict:
    """``mj_step`` alone on ``model``: the humanoid(s) standing on the floor with the standing
    position targets held (``ctrl`` 0), ``repeats`` runs of ``steps`` steps after 200 to
    settle; steps per second and the real-time factor (simulated s per wall s) of the fastest
    run (wall and CPU each: one run is a few tenths of a second, which another process's time
    slice or a cold cache moves by 10-30 %; the fastest run is the physics' own limit).
    ``start``: an ``MjData`` to start from (a scene of two people, settled at their start
    poses); default the one humanoid's standing pose. ``ctrl``: the controls held (default 0;
    a robot: its standing pose, its motors being position-controlled PD drives)."""
    import mujoco
    import numpy as np

    from gesture_sim.sim import humanoid as hm

    data = mujoco.MjData(model)
    if start is None:
        data.qpos[:] = hm.qpos_from_targets(model, np.zeros(len(hm.ACTUATED_JOINTS)))
    else:
        mujoco.mj_copyData(data, model, start)
        data.qvel[:] = 0.0
    data.ctrl[:] = 0.0 if ctrl is None else ctrl
    for _ in range(200):
        mujoco.mj_step(model, data)
    walls, cpus = [], []
    for _ in range(max(int(repeats), 1)):
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(steps):
            mujoco.mj_step(model, data)
        walls.append(time.perf_counter() - t0)
        cpus.append(max(time.process_time() - c0, 1e-9))
    wall, cpu = min(walls), min(cpus)
    sim_s = steps * float(model.opt.timestep)
    return {"steps": steps, "repeats": len(walls), "steps_per_s": steps / wall,
            "realtime_factor": sim_s / wall, "realtime_factor_cpu": sim_s / cpu,
            "realtime_factor_runs": [round(sim_s / w, 2) for w in walls]}


def bench_spotter(path: Path, labels) -> dict:
    """The keyword spotter (PocketSphinx, the decoder ``render`` and ``live`` run) on the same
    file, fed in 10 ms blocks: wall and CPU seconds, and its share of one core in real time (it
    runs in a worker thread beside the pipeline, live)."""
    from gesture_sim.audio.keywords import KeywordTable, spot_file
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.contracts import SAMPLE_RATE

    samples, _ = load_audio(path)
    table = KeywordTable.load(None)
    t0, c0 = time.perf_counter(), time.process_time()
    hits = spot_file(samples, table, labels)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    duration = len(samples) / SAMPLE_RATE
    return {"wall_s": wall, "cpu_s": cpu, "hits": len(hits),
            "share_of_one_core": cpu / duration}


def bench_conversation(source: str) -> dict:
    """The two-person scene against one person on the same audio (see the module docstring)."""
    import tempfile

    import numpy as np
    from scipy.io import wavfile

    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.conversation import Conversation, conversation_channels, run_conversation
    from gesture_sim.feed import run_file
    from gesture_sim.loading import load_stack
    from gesture_sim.pipeline import GesturePipeline

    if source == "dialogue":
        from gesture_sim.testing.dialogue import make_dialogue

        channels = make_dialogue(seed=0).channels
    else:
        from gesture_sim.audio.turns import load_channels

        channels = load_channels(source)
    voices, turns = conversation_channels(channels=channels)
    stack = load_stack(None, None, policy=True)
    out: dict = {"audio": source, "duration_s": len(voices) / SAMPLE_RATE, "turns": len(turns)}
    with tempfile.TemporaryDirectory() as tmp:
        mix = Path(tmp) / "mix.wav"
        wavfile.write(mix, SAMPLE_RATE, np.clip(voices.sum(axis=1), -1, 1).astype(np.float32))
        pipe = GesturePipeline(stack.library, stack.model, stack.policy,
                               control_library=stack.control_library)
        run_file(pipe, mix)                                  # warm-up
        t0 = time.perf_counter()
        single = run_file(pipe, mix)
        out["one_person"] = {"realtime_factor": single.duration / (time.perf_counter() - t0),
                             "stage_seconds": {k: round(v, 4) for k, v in single.costs.items()}}
    for physics in (False, True):
        conv = Conversation(stack.library, stack.model, stack.policy, physics=physics,
                            control_library=stack.control_library)
        t0, c0 = time.perf_counter(), _cpu_s()
        run = run_conversation(conv, voices, turns)
        wall, cpu = time.perf_counter() - t0, _cpu_s() - c0
        out["two_people" if physics else "two_people_without_physics"] = {
            "realtime_factor": run.duration / wall,
            "cpu_s": cpu, "realtime_factor_cpu": run.duration / cpu,
            "stage_seconds": {k: round(v, 4) for k, v in run.costs.items()}}
        if physics:
            conv.reset()                                     # both settled at their start poses
            out["bare_step"] = bare_step(conv.scene.model, start=conv.scene.data)
    out["second_body_cost_ratio"] = (out["one_person"]["realtime_factor"]
                                     / out["two_people"]["realtime_factor"])
    out["pipeline_to_bare_step"] = (out["two_people"]["realtime_factor"]
                                    / out["bare_step"]["realtime_factor"])
    out["pipeline_to_bare_step_cpu"] = (out["two_people"]["realtime_factor_cpu"]
                                        / out["bare_step"]["realtime_factor_cpu"])
    return out


def run(args: argparse.Namespace) -> int:
    import gesture_sim.feed as feed_module

    if args.cores < 1:
        raise GestureSimError(f"--cores must be at least 1, got {args.cores}")
    cores = _pin_cores(args.cores)
    if args.defer_physics is not None:
        feed_module.DEFER_PHYSICS_S = max(float(args.defer_physics), 0.0)
    worker = feed_module.physics_worker() if feed_module.DEFER_PHYSICS_S > 0 else None
    defer = {"defer_physics_s": feed_module.DEFER_PHYSICS_S, "physics_worker": worker or "off"}
    where = (f"{cores} core{'s' if cores > 1 else ''}" if cores else "unpinned") + \
        (f", physics in its own {worker}" if worker else "")
    if args.conversation is not None:
        doc = {"cores": cores, **defer, **bench_conversation(args.conversation)}
        if args.json:
            print_json(doc)
            return 0
        two, one = doc["two_people"], doc["one_person"]
        print(f"conversation benchmark ({where}): "
              f"{doc['duration_s']:.1f} s, {doc['turns']} turns")
        print(f"  two people with physics {two['realtime_factor']:.1f}x real time "
              f"(without physics {doc['two_people_without_physics']['realtime_factor']:.1f}x); "
              f"one person on the mix {one['realtime_factor']:.1f}x; the second body costs "
              f"{doc['second_body_cost_ratio']:.2f}x")
        print("    stages (s): " + ", ".join(f"{k} {v:.2f}"
                                             for k, v in two["stage_seconds"].items()))
        print(f"    bare mj_step of the two-person scene: "
              f"{doc['bare_step']['realtime_factor']:.1f}x real time; the conversation runs at "
              f"{doc['pipeline_to_bare_step']:.2f} of it ({doc['pipeline_to_bare_step_cpu']:.2f} "
              f"in CPU time)")
        return 0
    files = args.audio or [p for p in DEFAULT_FILES if p.is_file()]
    from gesture_sim.sim.bodies import resolve_body

    resolve_body(args.body)                  # an unknown body fails before any work
    results = [bench_file(Path(p), args.method, args.body) for p in files]
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    doc = {"cores": cores, "method": args.method, **defer, "files": results,
           "peak_rss_mb": round(peak_mb, 1)}
    if args.json:
        print_json(doc)
        return 0
    print(f"pipeline benchmark ({where}, method {args.method})")
    for r in results:
        w, wo = r["with_physics"], r["without_physics"]
        lat = r["latency"]
        print(f"  {Path(r['audio']).name} ({r['duration_s']:.1f} s): "
              f"{w['realtime_factor']:.1f}x real time with physics, "
              f"{wo['realtime_factor']:.1f}x without; control step "
              f"{w['control_step_us']:.0f} us; syllable end -> belief median "
              f"{1000 * lat['syllable_end_to_belief_median_s']:.0f} ms")
        print("    stages (s): " + ", ".join(f"{k} {v:.2f}"
                                             for k, v in w["stage_seconds"].items()))
        print(f"    bare mj_step of the same model: {r['bare_step']['realtime_factor']:.1f}x "
              f"real time; the pipeline runs at {r['pipeline_to_bare_step']:.2f} of it "
              f"({r['pipeline_to_bare_step_cpu']:.2f} in CPU time; mj_step "
              f"{w['mj_step_cpu_s']:.2f} of {w['cpu_s']:.2f} CPU s)")
        ks = r["keyword_spotter"]
        print(f"    keyword spotter: {ks['cpu_s']:.2f} CPU s ({100 * ks['share_of_one_core']:.1f} "
              f"% of one core in real time), {ks['hits']} hits")
    print(f"  peak memory {peak_mb:.0f} MB")
    return 0
