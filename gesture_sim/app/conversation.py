"""A two-person conversation in, one video of both bodies out (``render --rttm`` / ``--two``).

:func:`render_conversation` reads the audio (a stereo file, one channel per person, or a mono
mix with a diarization), runs :class:`~gesture_sim.conversation.Conversation` in simulated real
time, renders the shared scene from the ``both`` camera with the mix muxed in, and optionally
writes the conversation timeline (a row of roles and backchannels per person) and a JSON file
with each person's roles, segments, backchannels and physics figures.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, Turn
from gesture_sim.conversation import (
    N_PEOPLE,
    Conversation,
    ConversationRun,
    conversation_channels,
    run_conversation,
)
from gesture_sim.errors import GestureSimError
from gesture_sim.feed import RunResult
from gesture_sim.fileio import jsonable
from gesture_sim.metrics.conversation import hand_rest_figures, inside

#: Cameras of the conversation scene (:mod:`gesture_sim.sim.scene`).
CONVERSATION_CAMERAS = ("both", "person_0", "person_1", "face_0", "face_1")


def person_run(run: ConversationRun, p: int) -> RunResult:
    """Person ``p``'s share of a conversation as a single-person :class:`RunResult`."""
    person = run.conversation.people[p]
    costs = {k.split(".", 1)[1]: v for k, v in run.costs.items() if k.startswith(f"p{p}.")}
    return RunResult(pipeline=person, audio=run.channels[:, p], duration=run.duration,
                     wall=run.wall, costs=costs)


def _spans(turns: list[Turn], person: int) -> list[tuple[float, float]]:
    return [(t.t_start, t.t_end) for t in turns if t.person == person]


def conversation_summary(run: ConversationRun) -> dict[str, Any]:
    """Roles, segments, backchannels and (with physics) plausibility per person."""
    from gesture_sim.metrics.physics import physics_metrics
    from gesture_sim.metrics.selection import segment_spans

    conv = run.conversation
    traces = conv.traces() if conv.scene is not None else [None] * N_PEOPLE
    people = []
    for p, person in enumerate(conv.people):
        own, partner = _spans(run.turns, p), _spans(run.turns, 1 - p)
        spans = segment_spans(person_run(run, p))
        bcs = person.listener.backchannels if person.listener is not None else []
        entry: dict[str, Any] = {
            "speaking_s": float(sum(b - a for a, b in own)),
            "segments": [{"t_start": s.t_start, "t_end": s.t_end, "name": s.name}
                         for s in spans],
            "segment_starts_in_own_turns": float(np.mean(inside(
                np.array([s.t_start for s in spans]), [(a - 0.5, b + 0.5) for a, b in own])))
            if spans else None,
            "backchannels": [{"t_cue": b.t_cue, "t_emitted": b.t_emitted, "t_peak": b.t_peak,
                              "kind": b.kind, "invited": b.invited} for b in bcs],
            "backchannels_while_speaking": int(np.sum(inside(
                np.array([b.t_peak for b in bcs]), own))) if bcs else 0,
            "backchannels_per_min_partner_speech": (
                60.0 * len(bcs) / max(sum(b - a for a, b in partner), 1e-9) if partner else None),
        }
        if traces[p] is not None:
            phys = physics_metrics(traces[p]).to_dict()
            entry["physics"] = {k: phys[k] for k in (
                "fell", "foot_skate_mm_s", "ground_penetration_max_mm", "assist_impulse_per_s",
                "joint_limit_max_excess_deg", "saturation_share") if k in phys}
            entry["hands_in_partner_turns"] = hand_rest_figures(traces[p], partner)
        people.append(entry)
    return {"duration_s": run.duration,
            "turns": [{"person": t.person, "t_start": t.t_start, "t_end": t.t_end}
                      for t in run.turns],
            "people": people,
            "pipeline_realtime_factor": run.duration / run.wall if run.wall > 0 else None,
            "timing_s": {"pipeline": run.wall, "stages": run.costs}}


def load_conversation(audio: str | os.PathLike[str], rttm: str | os.PathLike[str] | None
                      ) -> tuple[np.ndarray, np.ndarray, list[Turn]]:
    """(voices (n, 2), mix (n,), turns) of a stereo file, or of a mono file with an RTTM."""
    from gesture_sim.audio import turns as tu

    channels = tu.load_channels(audio)
    given = None
    if rttm is not None:
        given, _names = tu.read_rttm(rttm, n_persons=N_PEOPLE)
        recording = tu.rttm_file_id(rttm)
        tu.check_turns(given, len(channels) / SAMPLE_RATE, str(rttm),
                       recording=None if recording in (None, Path(audio).stem) else recording)
    if channels.shape[1] == N_PEOPLE:
        voices, found = conversation_channels(channels=channels, turns=given)
        mix = channels.mean(axis=1)
    elif channels.shape[1] == 1:
        if given is None:
            raise GestureSimError(f"{audio}: one channel; a conversation needs a stereo file "
                                  "(one channel per person) or --rttm FILE (who speaks when)")
        mix = channels[:, 0]
        voices, found = conversation_channels(mono=mix, turns=given)
    else:
        raise GestureSimError(f"{audio}: {channels.shape[1]} channels; a conversation needs "
                              f"{N_PEOPLE} (one per person) or one with --rttm")
    if not found:
        raise GestureSimError(f"{audio}: nobody speaks (no turns found)")
    return voices, mix.astype(np.float32), found


def render_conversation(
    audio: str | os.PathLike[str], output: str | os.PathLike[str], *,
    rttm: str | os.PathLike[str] | None = None,
    library: str | os.PathLike[str] | None = None, model: str | os.PathLike[str] | None = None,
    method: str = "controller", seed: int = 0, style: float = 0.5, width: int = 1280,
    height: int = 720, fps: float = 30.0, camera: str = "both", workers: int | None = None,
    quality: str = "standard", timeline: str | os.PathLike[str] | None = None,
    metrics: str | os.PathLike[str] | None = None, show_progress: bool = True,
    face: bool = True, look: str = "human", listener_model: str = "rule",
    interests: tuple[float | None, float | None] = (None, None), listener_tendencies=None,
    listener_motion: str | None = None,
) -> dict[str, Any]:
    """Render a two-person conversation to an mp4 at ``output``; returns a JSON-ready summary.

    Person 0 (blue, on the left of the ``both`` camera) has the first channel or the RTTM's
    first speaker; person 1 (red) the other. Seeds ``seed`` and ``seed + 1``. ``look``: the
    bodies drawn (:data:`gesture_sim.sim.looks.LOOKS`; the physics is the same).
    ``listener_model``, ``interests``, ``listener_tendencies`` (the interest tables,
    :class:`~gesture_sim.signals.sdm.ListenerTendencies`) and ``listener_motion`` (the
    audio-driven listener's motion, :class:`~gesture_sim.pipeline.GesturePipeline`): the listeners
    (:class:`~gesture_sim.conversation.Conversation`).
    """
    from gesture_sim import validation as v
    from gesture_sim.app.render import check_video_settings
    from gesture_sim.app.video import frames_for_duration, render_video, resample_qpos
    from gesture_sim.fileio import atomic_outputs
    from gesture_sim.sim.looks import check_look
    from gesture_sim.sim.scene import conversation_model, scene_qpos

    check_video_settings(width, height, fps, style, seed, workers, quality)
    check_look(look)
    if camera not in CONVERSATION_CAMERAS:
        raise GestureSimError(f"--camera of a conversation must be one of "
                              f"{', '.join(CONVERSATION_CAMERAS)}; got {camera!r}")
    v.input_file("audio", audio, "audio file")
    inputs = [audio] + ([rttm] if rttm is not None else [])
    if rttm is not None:
        v.input_file("rttm", rttm, "RTTM file")
    out_path, timeline_path, metrics_path = v.check_outputs(
        [v.Output("output", output, v.VIDEO_EXTENSIONS),
         v.Output("timeline", timeline, v.PNG_EXTENSIONS) if timeline is not None else None,
         v.Output("metrics", metrics, v.JSON_EXTENSIONS) if metrics is not None else None],
        inputs=inputs)
    voices, mix, turns = load_conversation(audio, rttm)
    # the output folders are created with the outputs (see app/render.py)
    t0 = time.perf_counter()
    conv = Conversation.create(library, model, method=method, seeds=(seed, seed + 1),
                               style=style, show_progress=show_progress, signals=face,
                               listener_model=listener_model, interests=interests,
                               listener_tendencies=listener_tendencies,
                               listener_motion=listener_motion)
    run = run_conversation(conv, voices, turns, mix=mix, show_progress=show_progress)
    summary = {"output": str(output), "audio": str(audio), "rttm": str(rttm) if rttm else None,
               "method": method, "seeds": [seed, seed + 1], "fps": fps, "size": [width, height],
               **conversation_summary(run)}
    model_mj = conv.scene.model
    traces = conv.traces()
    qpos = scene_qpos(model_mj, traces)
    times = traces[0].time[: len(qpos)]
    n_frames = frames_for_duration(run.duration, fps)
    qpos = resample_qpos(model_mj, times, qpos, fps, n_frames=n_frames)
    with atomic_outputs(out_path, timeline_path, metrics_path) as (tmp_video, tmp_timeline,
                                                                   tmp_metrics):
        drawn = conversation_model(conv.distance, look=look)   # the same qpos layout
        video = render_video(drawn, qpos, tmp_video, fps=fps, audio=run.mix, width=width,
                             height=height, camera=camera, workers=workers, quality=quality,
                             show_progress=show_progress)
        summary["frames"] = video.n_frames
        summary["render_realtime_factor"] = video.realtime_factor
        summary["total_realtime_factor"] = run.duration / (time.perf_counter() - t0)
        if timeline is not None:
            plot_conversation(run, tmp_timeline, title=f"{Path(audio).name} — {method}")
            summary["timeline"] = str(timeline)
        if metrics is not None:
            doc = {k: val for k, val in summary.items()
                   if k not in ("timing_s", "pipeline_realtime_factor",
                                "render_realtime_factor", "total_realtime_factor")}
            tmp_metrics.write_text(json.dumps(jsonable(doc), indent=1), encoding="utf-8")
            summary["metrics"] = str(metrics)
    return summary


def plot_conversation(run: ConversationRun, path: str | os.PathLike[str], title: str = "") -> None:
    """The conversation timeline: per person its voice, its roles (speaking from the turns),
    the segments it played, its backchannels, and its bodies' wrist speed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gesture_sim.metrics.selection import segment_spans

    conv = run.conversation
    traces = conv.traces() if conv.scene is not None else [None] * N_PEOPLE
    colours = ("#3f6ba8", "#a84c3d")
    fig, axes = plt.subplots(2 * N_PEOPLE, 1, figsize=(14, 2.2 * 2 * N_PEOPLE), sharex=True,
                             gridspec_kw={"height_ratios": [1.0, 1.3] * N_PEOPLE})
    t_audio = np.arange(len(run.channels)) / SAMPLE_RATE
    step = max(1, len(t_audio) // 20000)
    for p, person in enumerate(conv.people):
        ax, ax2 = axes[2 * p], axes[2 * p + 1]
        c = colours[p]
        ax.plot(t_audio[::step], run.channels[::step, p], color=c, lw=0.5)
        for a, b in _spans(run.turns, p):
            ax.axvspan(a, b, color=c, alpha=0.12, lw=0)
        ax.set_ylabel(f"person {p}\nvoice")
        ax.set_yticks([])
        # roles row: speaking spans, segments played, backchannels
        for a, b in _spans(run.turns, p):
            ax2.broken_barh([(a, b - a)], (2.6, 0.8), color=c, alpha=0.8)
        for s in segment_spans(person_run(run, p)):
            ax2.broken_barh([(s.t_start, s.t_end - s.t_start)], (1.6, 0.7), color=c, alpha=0.45,
                            edgecolor="white", lw=0.5)
        bcs = person.listener.backchannels if person.listener is not None else []
        for b in bcs:
            ax2.plot([b.t_peak], [1.1], marker="v", color="black" if b.invited else "grey",
                     ms=7)
            ax2.plot([b.t_cue, b.t_peak], [1.1, 1.1], color="black", lw=0.8)
        if traces[p] is not None:
            tr = traces[p]
            hands = tr.sim_sites[:, :2]
            speed = np.max(np.linalg.norm(np.diff(hands, axis=0), axis=2), axis=1) / np.diff(
                tr.time)
            ax2.plot(tr.time[1:], 0.9 * np.clip(speed / 2.0, 0, 1), color="#444", lw=0.6)
        ax2.set_ylim(0, 3.6)
        ax2.set_yticks([0.45, 1.1, 1.95, 3.0])
        ax2.set_yticklabels(["wrist speed\n(0-2 m/s)", "backchannels", "segments", "speaking"],
                            fontsize=7)
    axes[-1].set_xlabel("time (s)")
    axes[-1].set_xlim(0, run.duration)
    if title:
        from gesture_sim.audio.plot import drawable

        axes[0].set_title(drawable(title))
    fig.tight_layout()
    fig.savefig(path, dpi=90, format="png")
    plt.close(fig)

