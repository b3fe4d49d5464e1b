"""Building a motion library from motion files: read, resample, retarget, segment, parametrise."""

from __future__ import annotations

import json
import os
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.kinematics import (
    PARAM_NAMES,
    fit_normalisation,
    interruption_frames,
    normalise,
    raw_parameters,
)
from gesture_sim.motion.library import Clip, MotionLibrary, Segment
from gesture_sim.motion.retarget import Retargeter, RetargetResult, heading_frame, match_any
from gesture_sim.motion.segmentation import SegmentationSettings, segment_clip
from gesture_sim.motion.skeleton import SkeletonMotion, resample

#: Default semantic tags by clip-name pattern (fnmatch): the Bandai Namco gesture contents.
DEFAULT_TAG_RULES: dict[str, list[str]] = {
    "*wave-*": ["wave"],
    "*_bow_*": ["bow"],
    "*_bye_*": ["bye"],
    "*_byebye_*": ["bye", "wave"],
    "*_guide_*": ["guide", "point"],
    "*_call_*": ["call", "beckon"],
    "*_respond_*": ["respond"],
    "*raise-up-*": ["raise_hand"],
}
#: A segment of a tagged clip is a stroke (and gets the tags) when its mean hand speed is at
#: least this fraction of the clip's fastest segment.
STROKE_FRACTION = 0.5

_KNOWN_LICENCES = (
    (re.compile(r"^dataset-[12]_"), "CC BY-NC 4.0",
     "Bandai Namco Research Motion Dataset (Kobayashi et al. 2023)"),
    (re.compile(r"^\d+_[a-z]+_\d+_\d+_\d+(\D|$)"), "CC BY-NC 4.0",
     "BEAT2 (Liu et al. 2022; EMAGE, Liu et al. 2024)"),
)


@dataclass
class ClipReport:
    """One row of the build summary."""

    name: str
    family: str
    frames: int
    seconds: float
    segments: int
    retarget_error: float
    retarget_error_p95: float

    def to_dict(self) -> dict:
        return {"name": self.name, "family": self.family, "frames": self.frames,
                "seconds": round(self.seconds, 3), "segments": self.segments,
                "retarget_error": round(self.retarget_error, 5),
                "retarget_error_p95": round(self.retarget_error_p95, 5)}


def read_motion(path: str | os.PathLike[str], model=None) -> SkeletonMotion:
    """Read a ``.bvh`` or an SMPL-X ``.npz`` file (the latter with the humanoid's proportions)."""
    from gesture_sim.motion.bvh import read_bvh
    from gesture_sim.motion.smplx import humanoid_rest_offsets, read_smplx

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return read_bvh(path)
    if suffix == ".npz":
        return read_smplx(path, humanoid_rest_offsets(model) if model is not None else None)
    raise GestureSimError(f"{path}: unsupported motion file type {suffix!r} (use .bvh or .npz)")


def motion_duration(path: str | os.PathLike[str]) -> float | None:
    """Seconds of a ``.bvh`` (its ``Frames:`` x ``Frame Time:``) or SMPL-X ``.npz`` (frames of
    ``poses`` / its frame rate) motion file, read from the header alone; None when the file
    does not say (the full reader, :func:`read_motion`, then reports what is wrong)."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".bvh":
            frames = frame_time = None
            with path.open(encoding="utf-8", errors="replace") as fh:
                in_motion = False
                for line in fh:
                    text = line.strip()
                    if text == "MOTION":
                        in_motion = True
                    elif in_motion and text.startswith("Frames:"):
                        frames = float(text[len("Frames:"):])
                    elif in_motion and text.startswith("Frame Time:"):
                        frame_time = float(text[len("Frame Time:"):])
                        break
            if frames is None or frame_time is None or not frame_time > 0:
                return None
            return frames * frame_time
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as d:
                key = next((k for k in ("mocap_frame_rate", "mocap_framerate") if k in d.files),
                           None)
                if key is None or "poses" not in d.files:
                    return None
                rate = np.asarray(d[key])
                if rate.size != 1 or rate.dtype.kind not in "iuf" or not float(rate.item()) > 0:
                    return None
                return len(d["poses"]) / float(rate.item())
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    return None


def guess_licence(name: str) -> tuple[str, str]:
    """(licence, dataset) for file stems of the known datasets, else ('unknown', '')."""
    for pattern, licence, dataset in _KNOWN_LICENCES:
        if pattern.search(name):
            return licence, dataset
    return "unknown (see the source's terms)", ""


def load_tag_rules(path: str | os.PathLike[str] | None) -> dict[str, list[str]]:
    """Tag rules from a JSON file ``{"<fnmatch pattern>": ["tag", ...]}``; defaults if None."""
    if path is None:
        return dict(DEFAULT_TAG_RULES)
    try:
        rules = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise GestureSimError(f"cannot read tags file {path}: {exc}") from exc
    if not isinstance(rules, dict) or not all(
            isinstance(v, list) and all(isinstance(t, str) for t in v) for v in rules.values()):
        raise GestureSimError(
            f"tags file {path} must map name patterns to lists of tags, "
            '(e.g. {"*wave*": ["wave"]})')
    return rules


def build_library(
    inputs: list[str | os.PathLike[str]], tag_rules: dict[str, list[str]] | None = None,
    fps: float = 30.0, settings: SegmentationSettings | None = None,
    licence: str | None = None, retargeter: Retargeter | None = None,
    on_clip: Callable[[ClipReport], None] | None = None,
    normalisation: dict | None = None,
    finger_tracks: dict[str, np.ndarray] | None = None,
) -> tuple[MotionLibrary, list[ClipReport]]:
    """Build a library from motion files.

    The segments' kinematic parameters are normalised with a B_X / W_X fitted to these clips
    (:func:`~gesture_sim.motion.kinematics.fit_normalisation`), or with ``normalisation`` when
    given: pass an inference model's ``param_normalisation`` to build a library that model can
    drive without retraining (Gesture Controllers' modularity: a new library needs a new control
    layer, not a new inference model).

    The work is :func:`analyse_clip` per file (read, resample, retarget, segment, raw
    parameters) and :func:`assemble_library` over all of them (normalisation, segments).

    Args:
        inputs: ``.bvh`` / SMPL-X ``.npz`` files.
        tag_rules: clip-name pattern -> tags (:data:`DEFAULT_TAG_RULES` when ``None``).
        fps: the library's frame rate (Hz); sources at other rates are resampled.
        settings: segmentation thresholds.
        licence: licence of every input; guessed from known dataset names when ``None``.
        retargeter: reuse a retargeter (the humanoid is loaded when ``None``).
        on_clip: called after each clip (e.g. to advance a progress bar).
        normalisation: ``{"names", "B", "W"}`` to keep (six positive finite B and W, names
            T D V A C H); ``None`` fits one to these clips.
        finger_tracks: a dict to fill with clip name -> (T, 40) finger targets of the inputs
            that carry hand motion (save them beside the library with
            :func:`~gesture_sim.motion.finger_tracks.save_finger_tracks`).

    Returns:
        The library and one :class:`ClipReport` per input.
    """
    if not inputs:
        raise GestureSimError("no input motion files given")
    if normalisation is not None:
        normalisation = check_normalisation(normalisation)
    settings = settings or SegmentationSettings()
    rt = retargeter or Retargeter()
    analyses: list[ClipAnalysis] = []
    for path in inputs:
        analysis = analyse_clip(path, tag_rules, fps=fps, settings=settings, licence=licence,
                                retargeter=rt)
        analyses.append(analysis)
        if finger_tracks is not None and analysis.fingers is not None:
            finger_tracks[analysis.clip.name] = analysis.fingers
        if on_clip:
            on_clip(analysis.report)
    return assemble_library(analyses, settings, normalisation)


@dataclass
class ClipAnalysis:
    """One motion file read, resampled, retargeted, segmented and parametrised: everything a
    library clip and an inference training take need, before any normalisation (which is
    fitted over all clips by :func:`assemble_library`).

    Attributes:
        clip: the library clip (qpos (T, n_joints) rad / m, root (T, 3) m and (T, 4), key
            points (T, K, 3) m in the heading frame, name, source, licence, tags).
        segments: (n, 2) int frame ranges ``[start, end)`` at ``clip.fps``.
        raw: (n, 6) raw kinematic parameters T D V A C H (s, m, m/s, m/s², 1/m, m).
        report: the build summary row.
        joint_names: the humanoid's joint names (columns of ``clip.qpos``).
        fingers: (T, 40) finger joint targets (rad) of a source with hand motion (an SMPL-X
            take's hand pose, :func:`~gesture_sim.motion.finger_tracks.smplx_finger_track`;
            a BVH's finger joints, :func:`~gesture_sim.motion.finger_tracks.bvh_finger_track`),
            one row per clip frame; ``None`` without.
    """

    clip: Clip
    segments: np.ndarray
    raw: np.ndarray
    report: ClipReport
    joint_names: tuple[str, ...]
    fingers: np.ndarray | None = None


def analyse_clip(
    path: str | os.PathLike[str], tag_rules: dict[str, list[str]] | None = None,
    fps: float = 30.0, settings: SegmentationSettings | None = None,
    licence: str | None = None, retargeter: Retargeter | None = None,
) -> ClipAnalysis:
    """Read, resample to ``fps`` (Hz), retarget, segment and parametrise one motion file, as
    :func:`build_library` does for each of its inputs (the arguments are its own).

    Raises:
        GestureSimError: an unreadable or unsupported file, or one shorter than 8 frames.
    """
    settings = settings or SegmentationSettings()
    tag_rules = DEFAULT_TAG_RULES if tag_rules is None else tag_rules
    rt = retargeter or Retargeter()
    path = Path(path)
    motion = resample(read_motion(path, rt.model), fps)
    if motion.n_frames < 8:
        raise GestureSimError(f"{path}: too short to use ({motion.n_frames} frames)")
    result = rt.retarget(motion)
    kp = heading_frame(result.root_pos, result.root_quat, result.keypoints)
    name = path.stem
    lic, dataset = guess_licence(name)
    clip_tags = tuple(dict.fromkeys(
        t for pattern, tags in tag_rules.items() if match_any(name, [pattern]) for t in tags))
    clip = Clip(
        name=name, fps=fps, qpos=result.qpos, root_pos=result.root_pos.astype(np.float32),
        root_quat=result.root_quat.astype(np.float32),
        source=f"{dataset}: {path.name}" if dataset else path.name,
        licence=licence or lic, tags=clip_tags, keypoints=kp.astype(np.float32),
        retarget_error=result.error)
    segs = segment_clip(kp[:, :2], fps, settings)
    raw = raw_parameters(kp[:, :2], kp[:, :2, 2], fps, segs)
    report = ClipReport(name, result.family, motion.n_frames, motion.n_frames / fps,
                        len(segs), result.error, result.error_p95)
    fingers = None
    if path.suffix.lower() == ".npz":
        from gesture_sim.motion.finger_tracks import smplx_finger_track

        fingers = smplx_finger_track(path, rt.model, fps, motion.n_frames)
    elif path.suffix.lower() == ".bvh":
        from gesture_sim.motion.finger_tracks import bvh_finger_track

        fingers = bvh_finger_track(motion, rt.model, fps, motion.n_frames)
    return ClipAnalysis(clip, np.array(segs, dtype=int).reshape(-1, 2), raw, report,
                        tuple(rt.joint_names), fingers)


def assemble_library(
    analyses: list[ClipAnalysis], settings: SegmentationSettings | None = None,
    normalisation: dict | None = None,
) -> tuple[MotionLibrary, list[ClipReport]]:
    """The library of analysed clips (:func:`analyse_clip`, all at one frame rate and on one
    humanoid), in the given order: their segments, linked within each clip, with parameters
    normalised by ``normalisation`` (checked) or by one fitted to all clips' raw parameters.

    ``settings`` is recorded in the library's info (the segmentation the clips were cut with).

    Raises:
        GestureSimError: no clips, clips at different frame rates or of different humanoids.
    """
    if not analyses:
        raise GestureSimError("no input motion files given")
    if normalisation is not None:
        normalisation = check_normalisation(normalisation)
    settings = settings or SegmentationSettings()
    fps = analyses[0].clip.fps
    joint_names = analyses[0].joint_names
    for a in analyses:
        if a.clip.fps != fps or tuple(a.joint_names) != tuple(joint_names):
            raise GestureSimError(f"clip {a.clip.name} is not at {fps:g} fps on the same "
                                  "humanoid as the others")
    clips = [a.clip for a in analyses]
    raws = [a.raw for a in analyses]
    ranges = [[(int(s), int(e)) for s, e in a.segments] for a in analyses]
    reports = [a.report for a in analyses]
    all_raw = np.concatenate(raws)
    norm = fit_normalisation(all_raw) if normalisation is None else normalisation
    params = normalise(all_raw, norm)
    segments: list[Segment] = []
    for ci, (clip, segs, raw) in enumerate(zip(clips, ranges, raws, strict=True)):
        first = len(segments)
        vmax = raw[:, 2].max()
        for k, (a, b) in enumerate(segs):
            i = first + k
            stroke = bool(clip.tags) and raw[k, 2] >= STROKE_FRACTION * vmax
            segments.append(Segment(
                index=i, clip=ci, start=a, end=b, params=params[i].astype(np.float32),
                predecessor=i - 1 if k > 0 else -1, successor=i + 1 if k < len(segs) - 1 else -1,
                interrupt_frames=interruption_frames(b - a),
                tags=clip.tags if stroke else ()))
    info = {"segmentation": settings.to_dict(),
            "retarget": {r.name: round(r.retarget_error, 5) for r in reports},
            "normalisation": "fitted" if normalisation is None else "given"}
    lib = MotionLibrary(fps=fps, joint_names=tuple(joint_names), clips=clips, segments=segments,
                        param_normalisation=norm, info=info)
    return lib, reports


def check_normalisation(normalisation: dict, source: str = "the normalisation") -> dict:
    """A kinematic-parameter normalisation ``{"names", "B", "W"}`` checked and made JSON-ready
    (plain lists of floats): names T D V A C H, six positive finite B_X (1/raw unit) and W_X.

    Raises:
        GestureSimError: another parameter set, or a missing / non-positive / non-finite value.
    """
    try:
        names = [str(n) for n in normalisation["names"]]
        b = np.asarray(normalisation["B"], dtype=float)
        w = np.asarray(normalisation["W"], dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise GestureSimError(f"{source} is not a kinematic-parameter normalisation "
                              f"(needs names, B and W): {exc}") from None
    if names != list(PARAM_NAMES):
        raise GestureSimError(f"{source} is over the parameters {' '.join(names)}, not "
                              f"{' '.join(PARAM_NAMES)}")
    for key, v in (("B", b), ("W", w)):
        if v.shape != (len(PARAM_NAMES),) or not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise GestureSimError(f"{source}: {key} must be {len(PARAM_NAMES)} positive finite "
                                  f"numbers, got {v.tolist()}")
    return {"names": names, "B": b.tolist(), "W": w.tolist()}


@dataclass
class MotionAnalysis:
    """A motion file retargeted, segmented and parametrised like a library clip.

    Attributes:
        result: the retargeting result (joint angles, root, world key points, error).
        keypoints: (T, K, 3) key points in the pelvis heading frame (m).
        segments: (n, 2) frame ranges ``[start, end)``.
        raw: (n, 6) raw kinematic parameters (s, m, m/s, m/s², 1/m, m).
        params: (n, 6) normalised log parameters (with the given normalisation, or one fitted
            to this motion when none was given).
        normalisation: the B_X / W_X used.
    """

    result: RetargetResult
    keypoints: np.ndarray
    segments: np.ndarray
    raw: np.ndarray
    params: np.ndarray
    normalisation: dict


def analyse_motion(
    path: str | os.PathLike[str], normalisation: dict | None = None, fps: float = 30.0,
    settings: SegmentationSettings | None = None, retargeter: Retargeter | None = None,
) -> MotionAnalysis:
    """Retarget, segment and parametrise one motion file exactly as the library builder does.

    Use it for the inference layer's training take: pass the library's
    ``param_normalisation`` so that both live in one parameter space.
    """
    rt = retargeter or Retargeter()
    motion = resample(read_motion(path, rt.model), fps)
    result = rt.retarget(motion)
    kp = heading_frame(result.root_pos, result.root_quat, result.keypoints)
    segs = np.array(segment_clip(kp[:, :2], fps, settings), dtype=int).reshape(-1, 2)
    raw = raw_parameters(kp[:, :2], kp[:, :2, 2], fps, segs)
    norm = normalisation or fit_normalisation(raw)
    return MotionAnalysis(result, kp, segs, raw, normalise(raw, norm), norm)
