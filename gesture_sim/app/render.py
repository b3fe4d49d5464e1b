"""Speech in, video out: run a recording through the causal pipeline and render the humanoid.

:func:`render_speech` is what ``gesture-sim render`` and ``gesture-sim demo`` call: the audio is
fed block by block through :class:`~gesture_sim.pipeline.GesturePipeline` in simulated real time
(the same code the live viewer runs), the simulated body's poses are resampled to the video rate
and rendered with the speech muxed in; optionally a timeline figure, a JSON file with the
plausibility metrics and the decision log, the simulated motion as BVH and its arrays as NPZ
(:mod:`gesture_sim.app.motion_export`) are written beside it.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.app.timeline import SegmentSpan, TimelineData, plot_timeline
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import ensure_output_folder
from gesture_sim.pipeline import GesturePipeline, RunResult, run_file


def segment_spans(run: RunResult) -> list[SegmentSpan]:
    """The played segments as spans: a new span where the segment changes or restarts."""
    log = run.pipeline.log
    spans: list[SegmentSpan] = []
    if not log.step_times:
        return spans
    dt = run.pipeline.dt
    kinds = {round(d.t / dt): d.kind for d in log.decisions
             if not d.costs.get("continue", 0.0)}
    start = 0
    n = len(log.step_times)
    for i in range(1, n + 1):
        end_here = (i == n or log.segments[i] != log.segments[i - 1]
                    or log.frames[i] < log.frames[i - 1])
        if not end_here:
            continue
        seg = int(log.segments[start])
        if seg >= 0:        # -1: at rest, no segment plays
            # left early: the decision that followed was an interruption (or a semantic entry);
            # a segment the timing layer left for rest counts as played out
            nxt = kinds.get(round(log.step_times[i] / dt), "end") if i < n else "end"
            spans.append(SegmentSpan(
                t_start=log.step_times[start], t_end=log.step_times[i - 1] + dt,
                segment_id=seg, name=run.pipeline.segment_name(seg),
                interrupted=(i < n and int(log.segments[i]) >= 0
                             and nxt in ("interrupt", "early", "label")),
                kind=kinds.get(round(log.step_times[start] / dt), "end"),
            ))
        start = i
    return spans


def timeline_data(run: RunResult, title: str = "") -> TimelineData:
    """Collect the timeline figure's inputs from a finished run."""
    pipe = run.pipeline
    frames = pipe.tracker.frames()
    log = pipe.log
    hand_times = np.zeros(0)
    hand_speed = np.zeros((0, 2))
    if pipe.sim is not None:
        trace = pipe.trace()
        hands = trace.sim_sites[:, :2]                                       # (T, 2, 3)
        hand_times = trace.time[1:]
        hand_speed = np.linalg.norm(np.diff(hands, axis=0), axis=2) / np.diff(trace.time)[:, None]
    means = getattr(getattr(pipe.model, "hmm", None), "means", None)
    velocity = np.asarray(means)[:, 2] if means is not None else None
    return TimelineData(
        audio=run.audio, frame_times=frames.times, f0_hz=frames.f0_hz,
        intensity_db=frames.intensity_db, syllables=log.syllables,
        step_times=np.asarray(log.step_times), belief=np.asarray(log.beliefs),
        spans=segment_spans(run), hand_times=hand_times, hand_speed=hand_speed,
        state_velocity=velocity, events=list(log.events), title=title,
    )


def decision_log(run: RunResult) -> list[dict[str, Any]]:
    """The controller's decisions as JSON-ready dicts (with the segment's clip name)."""
    out = []
    for d in run.pipeline.log.decisions:
        row = asdict(d)
        row["clip"] = run.pipeline.segment_name(d.segment_id)
        row["costs"] = {k: (None if not np.isfinite(v) else float(v)) for k, v in d.costs.items()}
        out.append(row)
    return out


def selection_summary(run: RunResult) -> dict[str, float]:
    """Shares of how segments were left: played to completion vs interrupted; repeats."""
    spans = segment_spans(run)
    if not spans:
        return {"segments_played": 0}
    finished = spans[:-1]   # the last one is cut by the end of the audio
    interrupted = sum(s.interrupted for s in finished)
    repeats = sum(a.segment_id == b.segment_id for a, b in zip(spans[:-1], spans[1:],
                                                               strict=True))
    return {
        "segments_played": len(spans),
        "distinct_segments": len({s.segment_id for s in spans}),
        "interrupted_share": interrupted / max(len(finished), 1),
        "completed_share": 1.0 - interrupted / max(len(finished), 1),
        "back_to_back_repeats": repeats,
        "mean_segment_s": float(np.mean([s.t_end - s.t_start for s in spans])),
    }


def latency_summary(run: RunResult) -> dict[str, float]:
    """Prosody latency (syllable end → emission) and decision latency (emission → next step)."""
    syl = run.pipeline.log.syllables
    if not syl:
        return {}
    prosody = np.array([s.t_emitted - s.t_end for s in syl])
    dt = run.pipeline.dt
    # the first control step at or after emission sees the syllable
    to_step = np.array([np.ceil(s.t_emitted / dt - 1e-9) * dt - s.t_emitted for s in syl])
    return {
        "prosody_latency_median_s": float(np.median(prosody)),
        "prosody_latency_p95_s": float(np.percentile(prosody, 95)),
        "emission_to_belief_max_s": float(to_step.max()),
        "syllable_end_to_belief_median_s": float(np.median(prosody + to_step)),
    }


def render_speech(
    audio: str | os.PathLike[str], output: str | os.PathLike[str], *,
    library: str | os.PathLike[str] | None = None, model: str | os.PathLike[str] | None = None,
    method: str = "controller", seed: int = 0, style: float = 0.5, width: int = 1280,
    height: int = 720, fps: float = 30.0, camera: str = "front", workers: int | None = None,
    quality: str = "standard", timeline: str | os.PathLike[str] | None = None,
    metrics: str | os.PathLike[str] | None = None, show_progress: bool = True,
    labels: tuple[tuple[float, str], ...] = (), bvh: str | os.PathLike[str] | None = None,
    npz: str | os.PathLike[str] | None = None,
) -> dict[str, Any]:
    """Render ``audio`` to an mp4 at ``output``; returns a JSON-ready summary.

    The physics is simulated for the whole file first (fast, single core), then the frames are
    rendered by ``workers`` processes and encoded, with the speech muxed in as AAC. ``bvh``:
    also write the simulated body's motion at 30 fps as BVH; ``npz``: its qpos, targets and
    decision log as arrays (see :mod:`gesture_sim.app.motion_export`).
    """
    from gesture_sim import validation as v
    from gesture_sim.app import motion_export as me
    from gesture_sim.app.video import (
        QUALITIES,
        check_camera,
        frames_for_duration,
        render_video,
        resample_qpos,
    )
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.fileio import atomic_outputs
    from gesture_sim.metrics.physics import physics_metrics

    # every check before any work: numbers, the audio, every output (not an input, not another
    # output, not a folder or special file, a supported extension)
    v.frame_size(width, height)
    v.fps("fps", fps)
    v.style("style", style)
    v.seed("seed", seed)
    v.workers("workers", workers)
    if quality not in QUALITIES:
        raise GestureSimError(f"quality must be one of {', '.join(QUALITIES)}; got {quality!r}")
    check_camera(camera)
    v.input_file("audio", audio, "audio file")
    out_path, timeline_path, metrics_path, bvh_path, npz_path = v.check_outputs(
        [v.Output("output", output, v.VIDEO_EXTENSIONS),
         v.Output("timeline", timeline, v.PNG_EXTENSIONS) if timeline is not None else None,
         v.Output("metrics", metrics, v.JSON_EXTENSIONS) if metrics is not None else None,
         v.Output("bvh", bvh, (".bvh",)) if bvh is not None else None,
         v.Output("npz", npz, (".npz",)) if npz is not None else None],
        inputs=[audio])
    samples, _ = load_audio(audio)   # a broken file fails here, in well under a second
    labels = v.labels("--label", labels, duration_s=len(samples) / 16000.0)
    del samples
    for path in (out_path, timeline_path, metrics_path, bvh_path, npz_path):
        if path is not None:
            ensure_output_folder(path)
    t0 = time.perf_counter()
    pipe = GesturePipeline.create(library, model, method=method, seed=seed, style=style,
                                  show_progress=show_progress)
    t_load = time.perf_counter() - t0
    run = run_file(pipe, audio, show_progress=show_progress, labels=labels)
    if not pipe.log.syllables:
        raise GestureSimError(f"{audio}: no speech found (no syllables); nothing to gesture to")
    trace = pipe.trace()
    n_frames = frames_for_duration(run.duration, fps)
    qpos = resample_qpos(pipe.sim.model, trace.time, trace.qpos, fps, n_frames=n_frames)
    # all outputs go to temporaries and are renamed together once every one of them is written
    with atomic_outputs(out_path, timeline_path, metrics_path, bvh_path, npz_path) as (
            tmp_video, tmp_timeline, tmp_metrics, tmp_bvh, tmp_npz):
        video = render_video(pipe.sim.model, qpos, tmp_video, fps=fps, audio=run.audio,
                             width=width, height=height, camera=camera, workers=workers,
                             quality=quality, show_progress=show_progress)
        summary = _summary(run, pipe, video, trace, output, audio, fps, width, height, method,
                           seed, style, t0, t_load)
        phys = physics_metrics(trace).to_dict()
        summary["physics"] = {k: phys[k] for k in _PHYSICS_KEYS if k in phys}
        if timeline is not None:
            plot_timeline(timeline_data(run, title=f"{Path(audio).name} — {method}"),
                          tmp_timeline)
            summary["timeline"] = str(timeline)
        if metrics is not None:
            summary["metrics"] = str(metrics)
            doc = dict(summary, physics=phys, decision_log=decision_log(run))
            for key in _WALL_CLOCK_KEYS:  # the file is byte-identical for the same input
                doc.pop(key, None)
            tmp_metrics.write_text(json.dumps(doc, indent=1, default=_json_default),
                                   encoding="utf-8")
        if bvh is not None:
            me.write_bvh_from_trace(tmp_bvh, pipe.sim.model, trace, run.duration)
            summary["bvh"] = str(bvh)
        if npz is not None:
            me.write_npz(tmp_npz, me.motion_arrays(pipe.sim.model, trace, decision_log(run)))
            summary["npz"] = str(npz)
    return summary


#: Summary entries measured on the wall clock: printed, but not in the metrics file.
_WALL_CLOCK_KEYS = ("timing_s", "pipeline_realtime_factor", "render_realtime_factor",
                    "total_realtime_factor")
#: The physics figures the summary shows (the metrics file has all of them).
_PHYSICS_KEYS = ("fell", "foot_skate_mm_s", "ground_penetration_max_mm",
                 "joint_limit_max_excess_deg", "saturation_share", "hand_error_settled_rms_mm",
                 "assist_impulse_per_s")


def _summary(run: RunResult, pipe: GesturePipeline, video: Any, trace: Any,
             output: str | os.PathLike[str], audio: str | os.PathLike[str], fps: float,
             width: int, height: int, method: str, seed: int, style: float, t0: float,
             t_load: float) -> dict[str, Any]:
    """The JSON-ready summary of a finished render (``physics`` filled in by the caller)."""
    return {
        "output": str(output), "audio": str(audio), "duration_s": run.duration,
        "frames": video.n_frames, "fps": fps, "size": [width, height], "method": method,
        "seed": seed, "style": style, "syllables": len(pipe.log.syllables),
        "decisions": len(pipe.log.decisions), "selection": selection_summary(run),
        "latency": latency_summary(run),
        "timing_s": {"load": t_load, "pipeline": run.wall, "render": video.wall_s,
                     "stages": run.costs},
        "pipeline_realtime_factor": run.duration / run.wall if run.wall > 0 else None,
        "render_realtime_factor": video.realtime_factor,
        "total_realtime_factor": run.duration / (time.perf_counter() - t0),
    }


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")
