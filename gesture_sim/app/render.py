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
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.app.timeline import TimelineData, plot_timeline
from gesture_sim.audio.plot import drawable
from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.errors import GestureSimError
from gesture_sim.feed import RunResult, run_file
from gesture_sim.methods import REGISTRY
from gesture_sim.metrics.selection import (  # noqa: F401 (re-exported)
    decision_log,
    following_summary,
    latency_summary,
    segment_spans,
    selection_summary,
)
from gesture_sim.pipeline import GesturePipeline
from gesture_sim.sim.humanoid import load_model
from gesture_sim.sim.looks import DEFAULT_LOOK, check_look


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
    state_names = None
    if REGISTRY[pipe.method].signs:               # its belief is over the gestural signs
        from gesture_sim.inference.sign_model import SIGNS

        state_names, velocity = tuple(SIGNS), None
    return TimelineData(
        audio=run.audio, frame_times=frames.times, f0_hz=frames.f0_hz,
        intensity_db=frames.intensity_db, syllables=log.syllables,
        step_times=np.asarray(log.step_times), belief=np.asarray(log.beliefs),
        spans=segment_spans(run), hand_times=hand_times, hand_speed=hand_speed,
        state_velocity=velocity, events=list(log.events), title=drawable(title),
        accents=[a.t for a in log.accents], strokes=list(log.strokes),
        rest_spans=_rest_spans(log), energy_times=np.asarray(log.step_times),
        energy=np.asarray(log.energy) if log.energy else None,
        signals=list(getattr(log, "signals", ())),
        words=[(w.t_start, w.t_end, w.word) for w in getattr(log, "words", ())],
        state_names=state_names,
    )


def _rest_spans(log: Any) -> list[tuple[float, float]]:
    """Spans (s) where the timing layer was at rest or retracting to it."""
    spans: list[tuple[float, float]] = []
    start = None
    for t, mode in zip(log.step_times, log.modes, strict=False):
        resting = mode in ("rest", "to_rest")
        if resting and start is None:
            start = t
        elif not resting and start is not None:
            spans.append((start, t))
            start = None
    if start is not None and log.step_times:
        spans.append((start, log.step_times[-1]))
    return spans


def check_video_settings(width: int, height: int, fps: float, style: float, seed: int,
                         workers: int | None, quality: str) -> None:
    """The numbers of a render (frame size, rate, style, seed, workers, quality), checked
    before any work (one-line :class:`GestureSimError`)."""
    from gesture_sim import validation as v
    from gesture_sim.app.video import QUALITIES

    v.frame_size(width, height)
    v.fps("fps", fps)
    v.style("style", style)
    v.seed("seed", seed)
    v.workers("workers", workers)
    if quality not in QUALITIES:
        raise GestureSimError(f"quality must be one of {', '.join(QUALITIES)}; got {quality!r}")


def check_label_times(labels: Sequence[tuple[float, str]], duration_s: float
                      ) -> tuple[tuple[float, str], ...]:
    """``--label`` requests checked against the audio's duration (s): the end itself, as the
    message prints it (to the next 1/100 s), is accepted; such a time is moved onto the end."""
    from gesture_sim import validation as v

    shown = math.ceil(round(duration_s * 100.0, 6)) / 100.0
    checked = v.labels("--label", labels, duration_s=shown)
    return tuple((min(t, duration_s), label) for t, label in checked)


def check_input_times(duration_s: float, *, signals_file: str | os.PathLike[str] | None = None,
                      transcript: str | os.PathLike[str] | None = None) -> None:
    """GestureSimError (one line naming the file) if a ``--signals`` label or a ``--transcript``
    word lies outside the audio (``duration_s``): the file belongs to another recording (the
    one rule of every side file, :func:`gesture_sim.validation.side_file_times`)."""
    from gesture_sim.validation import side_file_times

    if signals_file is not None:
        from gesture_sim.signals.ruth import load_markup

        side_file_times("", signals_file, [(i.t0, i.t0, f"label {i.label!r}")
                                           for i in load_markup(signals_file).items],
                        duration_s)
    if transcript is not None:
        from gesture_sim.audio.keywords import read_word_list

        side_file_times("", transcript, [(a, b, f"word {w[:30]!r}")
                                         for a, b, w in read_word_list(transcript)],
                        duration_s)


def render_speech(
    audio: str | os.PathLike[str], output: str | os.PathLike[str], *,
    library: str | os.PathLike[str] | None = None, model: str | os.PathLike[str] | None = None,
    method: str = "controller", seed: int = 0, style: float = 0.5, width: int = 1280,
    height: int = 720, fps: float = 30.0, camera: str = "front", workers: int | None = None,
    quality: str = "standard", timeline: str | os.PathLike[str] | None = None,
    metrics: str | os.PathLike[str] | None = None, show_progress: bool = True,
    labels: tuple[tuple[float, str], ...] = (), bvh: str | os.PathLike[str] | None = None,
    npz: str | os.PathLike[str] | None = None,
    signals_file: str | os.PathLike[str] | None = None, face: bool = True,
    keywords: str | os.PathLike[str] | None = None,
    transcript: str | os.PathLike[str] | None = None,
    smplx: str | os.PathLike[str] | None = None, mixamo: str | os.PathLike[str] | None = None,
    look: str = DEFAULT_LOOK,
    to_skeleton: tuple[str | os.PathLike[str], str | os.PathLike[str]] | None = None,
    phones: str = "auto", text: str | os.PathLike[str] | None = None,
    sign_model: str | os.PathLike[str] | None = None, transition: str = "ramp",
    body: str | None = None, robot_export: str | os.PathLike[str] | None = None,
) -> dict[str, Any]:
    """Render ``audio`` to an mp4 at ``output``; returns a JSON-ready summary.

    The physics is simulated for the whole file first (fast, single core), then the frames are
    rendered by ``workers`` processes and encoded, with the speech muxed in as AAC. ``bvh``:
    also write the simulated body's motion at 30 fps as BVH; ``npz``: its qpos, targets and
    decision log as arrays (see :mod:`gesture_sim.app.motion_export`); ``smplx``: SMPL-X
    parameters in BEAT2's npz layout, ``mixamo``: a BVH on the Mixamo rig
    (:mod:`gesture_sim.export`), ``to_skeleton``: ``(SKELETON.bvh, OUT.bvh)``, the motion on
    the hierarchy of the user's BVH (:mod:`gesture_sim.export.skeleton`). ``look``: the body
    drawn (:data:`gesture_sim.sim.looks.LOOKS`; the physics is the same in every look).
    ``keywords``: a keyword table file (or ``"default"``, the shipped one) whose spotted words
    request semantic gestures; ``transcript``: aligned words to use instead of the spotter.
    ``phones`` (:data:`PHONE_MODES`) and ``text``: where the mouth's phones come from
    (:func:`speech_phones`). ``sign_model``: ``chiu14``'s sign model folder (None: the
    shipped one). ``transition``: how the timing layer crosses a segment switch
    (:data:`~gesture_sim.methods.TRANSITIONS`). ``body``: the body driven
    (:func:`gesture_sim.sim.bodies.resolve_body`: humanoid, g1, h1 or a robot map file; a robot
    is drawn as its own model, from its own front camera, and takes none of the humanoid's
    motion exports); ``robot_export``: ``STEM.npz``, the robot's joint trajectory for a real
    robot, written with ``STEM.csv`` and ``STEM.pkl`` (:mod:`gesture_sim.app.robot_export`).
    """
    from gesture_sim import validation as v
    from gesture_sim.app import motion_export as me
    from gesture_sim.app.video import (
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
    check_video_settings(width, height, fps, style, seed, workers, quality)
    from gesture_sim.sim.bodies import resolve_body

    spec = resolve_body(body)
    if spec.is_robot:
        human_only = [n for n, x in (("bvh", bvh), ("smplx", smplx), ("mixamo", mixamo),
                                     ("to_skeleton", to_skeleton)) if x is not None]
        if human_only:
            raise GestureSimError(f"--{human_only[0].replace('_', '-')} exports the humanoid; "
                                  f"not with --body {spec.name}")
    else:
        check_camera(camera)
        if robot_export is not None:
            raise GestureSimError("--robot-export needs a robot --body (g1, h1 or a map file)")
    check_look(look)
    from gesture_sim.app.robot_export import export_paths

    robot_files = export_paths(robot_export) if robot_export is not None else (None,) * 3
    v.input_file("audio", audio, "audio file")
    user_skeleton = None
    if to_skeleton is not None:
        from gesture_sim.export.skeleton import read_skeleton

        if len(to_skeleton) != 2:
            raise GestureSimError("to_skeleton: expected (SKELETON.bvh, OUT.bvh)")
        v.input_file("to_skeleton", to_skeleton[0], "BVH skeleton")
        user_skeleton = read_skeleton(to_skeleton[0])   # a skeleton it cannot take: here
    paths = v.check_outputs(
        [v.Output("output", output, v.VIDEO_EXTENSIONS),
         v.Output("timeline", timeline, v.PNG_EXTENSIONS) if timeline is not None else None,
         v.Output("metrics", metrics, v.JSON_EXTENSIONS) if metrics is not None else None,
         v.Output("bvh", bvh, (".bvh",)) if bvh is not None else None,
         v.Output("npz", npz, (".npz",)) if npz is not None else None,
         v.Output("smplx", smplx, (".npz",)) if smplx is not None else None,
         v.Output("mixamo", mixamo, (".bvh",)) if mixamo is not None else None,
         v.Output("to_skeleton", to_skeleton[1], (".bvh",)) if to_skeleton is not None
         else None,
         *(v.Output("robot_export", f, (f.suffix,)) if f is not None else None
           for f in robot_files)],
        inputs=[audio] + ([to_skeleton[0]] if to_skeleton is not None else []))
    if phones not in PHONE_MODES:
        raise GestureSimError(f"phones: {phones!r}; choose one of {', '.join(PHONE_MODES)}")
    if text is not None:
        v.input_file("text", text, "transcript text")
    samples, _ = load_audio(audio)   # a broken file fails here, in well under a second
    duration = len(samples) / SAMPLE_RATE
    labels = check_label_times(labels, duration)
    check_input_times(duration, signals_file=signals_file, transcript=transcript)
    speech, mouth, text_words = (speech_phones(samples, phones, transcript, text) if face
                                 else (None, "none (--no-face)", None))
    del samples
    # the output folders are created with the outputs (check_outputs has tried that they can
    # be), so a run that fails before writing leaves none behind
    t0 = time.perf_counter()
    pipe = GesturePipeline.create(library, model, method=method, seed=seed, style=style,
                                  show_progress=show_progress, signals=face,
                                  signals_file=signals_file, phones=speech,
                                  sign_model=sign_model, transition=transition,
                                  body=spec)
    robot_library = _robot_library(pipe) if spec.is_robot else None
    t_load = time.perf_counter() - t0
    table = None
    if keywords is not None:
        from gesture_sim.audio.keywords import KeywordTable, check_keyword_labels
        from gesture_sim.methods import no_labels_note

        explicit = str(keywords) != "default"
        table = KeywordTable.load(keywords if explicit else None)
        check_keyword_labels(table, pipe.labels, explicit=explicit,
                             none=no_labels_note(pipe.method, pipe.library))
    run = run_file(pipe, audio, show_progress=show_progress, labels=labels, keywords=table,
                   transcript=transcript, words=text_words)
    if not pipe.log.syllables:
        raise GestureSimError(f"{audio}: no speech found (no syllables); nothing to gesture to")
    trace = pipe.trace()
    n_frames = frames_for_duration(run.duration, fps)
    qpos = resample_qpos(pipe.sim.model, trace.time, trace.qpos, fps, n_frames=n_frames)
    # all outputs go to temporaries and are renamed together once every one of them is written
    with atomic_outputs(*paths) as (tmp_video, tmp_timeline, tmp_metrics, tmp_bvh, tmp_npz,
                                    tmp_smplx, tmp_mixamo, tmp_skeleton, *tmp_robot):
        # the look is drawn only: its model has the physics model's qpos layout; a robot is
        # drawn as its own model
        drawn = spec.robot.load_model() if spec.is_robot else load_model(look=look)
        video = render_video(drawn, qpos, tmp_video, fps=fps, audio=run.audio,
                             width=width, height=height, camera=camera, workers=workers,
                             quality=quality, show_progress=show_progress)
        summary = _summary(run, pipe, video, trace, output, audio, fps, width, height, method,
                           seed, style, t0, t_load)
        summary["mouth"] = {"source": mouth, "phones": None if speech is None else len(speech)}
        phys = physics_metrics(trace).to_dict()
        summary["physics"] = {k: phys[k] for k in _PHYSICS_KEYS if k in phys}
        if timeline is not None:
            plot_timeline(timeline_data(run, title=f"{Path(audio).name} — {method}"),
                          tmp_timeline)
            summary["timeline"] = str(timeline)
        if metrics is not None:
            summary["metrics"] = str(metrics)
            doc = dict(summary, physics=phys, decision_log=decision_log(run))
            if pipe.signals is not None and not spec.is_robot:  # head and face (issue 14)
                from gesture_sim.metrics.face import trace_figures

                doc["face_head"] = trace_figures(trace, pipe.sim.model, pipe.log.signals,
                                                 [a.t for a in pipe.log.accents], run.duration)
                doc["face_head"]["events"] = pipe.log.signals
            for key in _WALL_CLOCK_KEYS:  # the file is byte-identical for the same input
                doc.pop(key, None)
            tmp_metrics.write_text(json.dumps(doc, indent=1, default=_json_default),
                                   encoding="utf-8")
        if robot_export is not None:
            from gesture_sim.app.robot_export import robot_arrays, write_robot_export

            write_robot_export(*tmp_robot, robot_arrays(spec.robot, trace))
            summary["robot_export"] = [str(f) for f in robot_files]
        if spec.is_robot:
            summary["body"] = spec.name
            summary["robot_library"] = robot_library
        if bvh is not None:
            me.write_bvh_from_trace(tmp_bvh, pipe.sim.model, trace, run.duration)
            summary["bvh"] = str(bvh)
        if npz is not None:
            me.write_npz(tmp_npz, me.motion_arrays(pipe.sim.model, trace, decision_log(run)))
            summary["npz"] = str(npz)
        if smplx is not None:
            me.write_smplx_from_trace(tmp_smplx, pipe.sim.model, trace, run.duration)
            summary["smplx"] = str(smplx)
        if mixamo is not None:
            me.write_mixamo_from_trace(tmp_mixamo, pipe.sim.model, trace, run.duration)
            summary["mixamo"] = str(mixamo)
        if to_skeleton is not None:
            me.write_skeleton_from_trace(tmp_skeleton, user_skeleton, pipe.sim.model, trace,
                                         run.duration)
            summary["to_skeleton"] = str(to_skeleton[1])
    return summary


#: Where the mouth's phones come from (``render --phones``): ``auto`` the transcript's (a
#: TextGrid's phone tier, or its words or ``text`` force-aligned to the audio) when one is
#: given, else the phones PocketSphinx recognises in the file; ``recognise`` always those;
#: ``off`` none: the jaw opens with the loudness (the degraded mode).
PHONE_MODES = ("auto", "recognise", "off")


def speech_phones(samples: np.ndarray, mode: str = "auto",
                  transcript: str | os.PathLike[str] | None = None,
                  text: str | os.PathLike[str] | None = None,
                  ) -> tuple[list | None, str, list | None]:
    """The phones the mouth forms (:class:`~gesture_sim.audio.phones.Phone`, None for the
    loudness jaw) of 16 kHz ``samples`` (n,), a line saying where they came from, and the
    ``text``'s words with their aligned times (:class:`~gesture_sim.audio.phones.Word`, for a
    method that reads words, ``chiu14``) when ``text`` was aligned, else None."""
    from gesture_sim.audio import phones as ph

    if mode == "off":
        return None, "loudness (no phones: --phones off)", None
    if mode == "auto" and transcript is not None:
        from gesture_sim.audio.keywords import read_word_list
        from gesture_sim.audio.textgrid import read_textgrid

        try:
            grid = read_textgrid(transcript)
        except GestureSimError:
            grid = None
        if grid is not None and "phones" in grid:
            return ph.phones_from_textgrid(transcript), f"{transcript} (phone tier)", None
        words = " ".join(w for _, _, w in read_word_list(transcript))
        aligned, source, _ = _aligned(samples, words,
                                      f"{transcript} (words aligned to the audio)")
        return aligned, source, None      # the transcript's own word times are the words
    if mode == "auto" and text is not None:
        try:
            words = Path(text).read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError) as exc:
            raise GestureSimError(f"{text}: cannot read the transcript text ({exc})") from None
        return _aligned(samples, words, f"{text} (aligned to the audio)")
    return _recognised(samples), "recognised from the audio (PocketSphinx phone loop)", None


def _aligned(samples: np.ndarray, words: str, source: str) -> tuple[list, str, list | None]:
    """The transcript's phones force-aligned to the audio and its words with their times;
    where PocketSphinx finds no alignment, the recognised phones and no words, with a warning
    (the render goes on)."""
    import warnings

    from gesture_sim.audio import phones as ph

    where = source.split(" (", 1)[0]         # the transcript file, for the warnings
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            aligned = ph.align_transcript(samples, SAMPLE_RATE, words)
        for w in caught:                       # the aligner's notes, naming the file
            warnings.warn(f"{where}: {str(w.message).removeprefix('align_transcript: ')}",
                          stacklevel=1)
        return list(aligned.phones), source, list(aligned.words)
    except GestureSimError as exc:
        reason = str(exc).removeprefix("align_transcript: ")
        warnings.warn(f"{where}: {reason}; the lips use the phones recognised in the audio "
                      "instead", stacklevel=1)
    return (_recognised(samples),
            "recognised from the audio (the transcript could not be aligned)", None)


def _recognised(samples: np.ndarray) -> list:
    """The phones PocketSphinx's phone loop finds in a whole recording (used as known in
    advance: an offline render shows them on time, as a transcript's)."""
    from gesture_sim.audio.phones import recognise_phones

    return [e.phone for e in recognise_phones(samples, SAMPLE_RATE, chunk_s=0.5)]


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
        "latency": latency_summary(run), "following": following_summary(run),
        "timing_s": {"load": t_load, "pipeline": run.wall, "render": video.wall_s,
                     "stages": run.costs},
        "pipeline_realtime_factor": run.duration / run.wall if run.wall > 0 else None,
        "render_realtime_factor": video.realtime_factor,
        "total_realtime_factor": run.duration / (time.perf_counter() - t0),
    }


def _robot_library(pipe: GesturePipeline) -> dict | None:
    """Build the library's frames on the pipeline's robot once, into the cache, when neither
    the shipped nor the cached build is there (:func:`gesture_sim.sim.robot_ik.
    retarget_library`); returns its info (``built``, ``seconds``, ``path``), None without a
    library of clips."""
    from gesture_sim.sim.robot_ik import cache_dir, cache_file, retarget_library, shipped_dir

    lib, targets = pipe.library, pipe.to_body
    if not getattr(lib, "clips", None) or targets is None:
        return None
    name = cache_file(pipe.body.robot, lib.fingerprint)
    folder = next((f for f in (shipped_dir(), cache_dir()) if (f / name).is_file()), cache_dir())
    frames, info = retarget_library(pipe.body.robot, [c.qpos for c in lib.clips], lib.fps,
                                    fingerprint=lib.fingerprint, cache=folder)
    targets.clips_h = [np.asarray(c.qpos, dtype=np.float32) for c in lib.clips]
    targets.clips_r = frames
    return info


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")
