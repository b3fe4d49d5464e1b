"""The motion library: retargeted clips, their gesture segments and parameters (save/load).

On disk a library is a folder with ``manifest.json`` (format version, frame rate, joint names,
clip metadata with source and licence, segment tags and gestural signs, parameter normalisation,
fingerprint) and ``library.npz`` (all clips concatenated, float32; key points float16; segment
table int32).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import (
    atomic_outputs,
    damaged,
    decoding_errors,
    decoding_exceptions,
)
from gesture_sim.motion.distances import DistanceWeights, SegmentDistances, compute_distances

#: Version of the on-disk format; :meth:`MotionLibrary.load` refuses other major versions.
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
ARRAYS = "library.npz"
#: How to repair a damaged library (the end of every decoding error).
_REBUILD = "rebuild it with 'gesture-sim library build'"


@dataclass
class Clip:
    """One retargeted clip.

    Attributes:
        name: clip name (usually the source file's stem).
        fps: frame rate (Hz), equal to the library's.
        qpos: (T, n_joints) float32 joint positions (rad / m), columns = library.joint_names.
        root_pos: (T, 3) pelvis position (m), feet on the floor.
        root_quat: (T, 4) pelvis orientation (w, x, y, z), facing +x at the start.
        source: where the motion came from (file name, dataset).
        licence: the licence of the source data.
        tags: semantic tags of the whole clip (e.g. ``("wave",)``).
        keypoints: (T, K, 3) key points of the humanoid (see
            :data:`gesture_sim.motion.retarget.KEYPOINTS`) in the pelvis heading frame (m):
            x forward, y left, z height above the floor. Used for segmentation and distances.
        retarget_error: mean retarget error (fraction of arm length), NaN if unknown.
    """

    name: str
    fps: float
    qpos: np.ndarray
    root_pos: np.ndarray
    root_quat: np.ndarray
    source: str
    licence: str
    tags: tuple[str, ...] = ()
    keypoints: np.ndarray | None = None
    retarget_error: float = math.nan

    @property
    def n_frames(self) -> int:
        return int(self.qpos.shape[0])


@dataclass
class Segment:
    """A gesture segment: frames ``[start, end)`` of clip ``clip``.

    Attributes:
        index: position in ``MotionLibrary.segments``.
        clip: index of its clip.
        start, end: frame range in the clip.
        params: (6,) normalised log kinematic parameters (T, D, V, A, C, H).
        predecessor, successor: neighbouring segment indices in the source clip, -1 if none.
        interrupt_frames: three offsets from ``start``, uniformly spaced, 0 < f < length.
        tags: semantic tags (e.g. ``("wave",)`` on the stroke of a wave).
        sign: the Chiu (2014) gestural sign annotated for it (one of
            :data:`gesture_sim.motion.signs.SIGNS`, from ``library build --signs``), ``None``
            when not annotated (:func:`gesture_sim.motion.signs.library_signs` then labels it by
            its form). Saved in the manifest; not part of the fingerprint.
    """

    index: int
    clip: int
    start: int
    end: int
    params: np.ndarray
    predecessor: int
    successor: int
    interrupt_frames: tuple[int, int, int]
    tags: tuple[str, ...] = ()
    sign: str | None = None

    @property
    def length(self) -> int:
        """Number of frames."""
        return self.end - self.start


@dataclass
class MotionLibrary:
    """Clips, segments and kinematic parameters at one frame rate.

    Attributes:
        fps: frame rate of every clip (Hz).
        joint_names: the humanoid's actuated joints, the columns of every ``qpos``.
        clips, segments: the content.
        param_normalisation: ``{"names", "B", "W"}`` used for ``params`` (see
            :mod:`gesture_sim.motion.kinematics`).
        info: free-form build information (segmentation settings, per-file errors ...).
        form_signs: ``(labeller key, (n_segments,) signs)``: every segment's sign by the form
            labeller (:func:`gesture_sim.motion.signs.label_library`, pass 1), computed once
            when the library is saved and stored in the manifest, so that neither
            ``library info`` nor ``--method chiu14`` poses the whole library at start-up;
            ``None`` until then. The key names the labeller's version and settings: labels of
            another key are recomputed. Not part of the fingerprint.
    """

    fps: float
    joint_names: tuple[str, ...]
    clips: list[Clip]
    segments: list[Segment]
    param_normalisation: dict
    info: dict = field(default_factory=dict)
    _fingerprint: str | None = field(default=None, repr=False)
    form_signs: tuple[str, tuple[str, ...]] | None = field(default=None, repr=False)

    # --- views ------------------------------------------------------------------------------

    @property
    def params(self) -> np.ndarray:
        """(n_segments, 6) normalised log parameters, rows = ``segment.params``."""
        if not self.segments:
            return np.zeros((0, 6))
        return np.stack([s.params for s in self.segments]).astype(float)

    @property
    def duration(self) -> float:
        """Total length of the clips (s)."""
        return sum(c.n_frames for c in self.clips) / self.fps

    def segment_qpos(self, i: int) -> np.ndarray:
        """Joint positions (length, n_joints) of segment ``i``."""
        s = self.segments[i]
        return self.clips[s.clip].qpos[s.start:s.end]

    def segment_keypoints(self, i: int) -> np.ndarray:
        """Key points (length, K, 3) of segment ``i`` (heading frame, m)."""
        s = self.segments[i]
        kp = self.clips[s.clip].keypoints
        if kp is None:
            raise GestureSimError(f"clip {self.clips[s.clip].name!r} has no key points")
        return kp[s.start:s.end].astype(float)

    def segments_with_tag(self, tag: str) -> list[int]:
        """Indices of the segments carrying ``tag``."""
        return [s.index for s in self.segments if tag in s.tags]

    def subset(self, clips: list[str] | tuple[str, ...]) -> MotionLibrary:
        """A library of some of these clips (fnmatch patterns on clip names, in this library's
        order), their segments, tags and parameters copied as they are.

        The parameters keep this library's normalisation, so any inference model that fits this
        library fits the subset too; only the control layer (policy, motion graph) must be
        trained for it. Segment indices and the predecessor/successor links are renumbered.

        Raises:
            GestureSimError: a pattern that matches no clip, or no clip chosen.
        """
        from fnmatch import fnmatchcase

        patterns = list(clips)
        unmatched = [p for p in patterns if not any(fnmatchcase(c.name, p) for c in self.clips)]
        if unmatched:
            raise GestureSimError(f"no clip of the library matches {', '.join(unmatched)}")
        keep = [k for k, c in enumerate(self.clips)
                if any(fnmatchcase(c.name, p) for p in patterns)]
        if not keep:
            raise GestureSimError("no clip chosen for the subset library")
        clip_map = {old: new for new, old in enumerate(keep)}
        seg_map: dict[int, int] = {}
        for s in self.segments:
            if s.clip in clip_map:
                seg_map[s.index] = len(seg_map)
        segments = [
            Segment(index=seg_map[s.index], clip=clip_map[s.clip], start=s.start, end=s.end,
                    params=np.array(s.params, dtype=np.float32, copy=True),
                    predecessor=seg_map.get(s.predecessor, -1),
                    successor=seg_map.get(s.successor, -1),
                    interrupt_frames=tuple(s.interrupt_frames), tags=tuple(s.tags),
                    sign=s.sign)
            for s in self.segments if s.index in seg_map]
        chosen = [self.clips[k] for k in keep]
        info = dict(self.info, subset_of={"fingerprint": self.fingerprint,
                                          "clips": [c.name for c in chosen]})
        if isinstance(self.info.get("retarget"), dict):
            info["retarget"] = {c.name: self.info["retarget"][c.name] for c in chosen
                                if c.name in self.info["retarget"]}
        form_signs = None
        if self.form_signs is not None and len(self.form_signs[1]) == len(self.segments):
            form_signs = (self.form_signs[0], tuple(self.form_signs[1][s.index]
                                                    for s in self.segments if s.index in seg_map))
        return MotionLibrary(fps=self.fps, joint_names=tuple(self.joint_names),
                             clips=[replace(c) for c in chosen], segments=segments,
                             param_normalisation=dict(self.param_normalisation), info=info,
                             form_signs=form_signs)

    # --- distances --------------------------------------------------------------------------

    def distances(self, weights: DistanceWeights | None = None) -> SegmentDistances:
        """D_seg, D_sp (n, n) and D_in (n, 3, n) over all segments (see :mod:`.distances`)."""
        from gesture_sim.motion.kinematics import dynamics_signature

        n = len(self.segments)
        if n == 0:
            raise GestureSimError("the motion library has no segments")
        k = self.clips[0].keypoints.shape[1]
        start = np.empty((n, k, 3))
        end = np.empty((n, k, 3))
        inter = np.empty((n, 3, k, 3))
        sig = np.empty((n, 12))
        for ci, clip in enumerate(self.clips):
            idx = [s.index for s in self.segments if s.clip == ci]
            if not idx:
                continue
            kp = clip.keypoints.astype(float)
            ranges = np.array([(self.segments[i].start, self.segments[i].end) for i in idx])
            sig[idx] = dynamics_signature(kp[:, :2], self.fps, ranges)
            for i in idx:
                s = self.segments[i]
                start[i] = kp[s.start]
                end[i] = kp[s.end - 1]
                inter[i] = kp[[s.start + f for f in s.interrupt_frames]]
        lengths = np.array([s.length for s in self.segments], dtype=float)
        pred = np.array([s.predecessor for s in self.segments])
        succ = np.array([s.successor for s in self.segments])
        return compute_distances(lengths, start, end, inter, sig, pred, succ,
                                 weights or DistanceWeights())

    # --- identity -----------------------------------------------------------------------------

    @property
    def fingerprint(self) -> str:
        """Content hash (16 hex digits) of joints, frame rate, clips and segments."""
        if self._fingerprint is None:
            arrays, _ = self._pack()
            h = hashlib.sha256()
            h.update(json.dumps([list(self.joint_names), float(self.fps)]).encode())
            for key in ("qpos", "root_pos", "root_quat", "clip_offsets", "segments", "params"):
                a = np.ascontiguousarray(arrays[key])
                h.update(key.encode() + str(a.dtype).encode() + str(a.shape).encode())
                h.update(a.tobytes())
            self._fingerprint = h.hexdigest()[:16]
        return self._fingerprint

    # --- save / load --------------------------------------------------------------------------

    def _pack(self) -> tuple[dict[str, np.ndarray], dict]:
        offsets = np.cumsum([0] + [c.n_frames for c in self.clips]).astype(np.int64)
        nj = len(self.joint_names)
        cat = lambda xs, shape: (np.concatenate(xs) if xs else np.zeros(shape))  # noqa: E731
        arrays = {
            "qpos": cat([c.qpos for c in self.clips], (0, nj)).astype(np.float32),
            "root_pos": cat([c.root_pos for c in self.clips], (0, 3)).astype(np.float32),
            "root_quat": cat([c.root_quat for c in self.clips], (0, 4)).astype(np.float32),
            "clip_offsets": offsets,
            "segments": np.array(
                [[s.clip, s.start, s.end, s.predecessor, s.successor, *s.interrupt_frames]
                 for s in self.segments], dtype=np.int32).reshape(-1, 8),
            "params": (np.stack([s.params for s in self.segments]) if self.segments
                       else np.zeros((0, 6))).astype(np.float32),
        }
        if self.clips and all(c.keypoints is not None for c in self.clips):
            arrays["keypoints"] = np.concatenate([c.keypoints for c in self.clips]).astype(
                np.float16)
        meta = {
            "clips": [{"name": c.name, "fps": c.fps, "frames": c.n_frames, "source": c.source,
                       "licence": c.licence, "tags": list(c.tags),
                       "retarget_error": None if math.isnan(c.retarget_error)
                       else round(float(c.retarget_error), 5)} for c in self.clips],
            "segment_tags": {str(s.index): list(s.tags) for s in self.segments if s.tags},
        }
        if any(s.sign is not None for s in self.segments):
            meta["segment_signs"] = {str(s.index): s.sign for s in self.segments
                                     if s.sign is not None}
        return arrays, meta

    def save(self, folder: str | os.PathLike[str]) -> None:
        """Write the library into ``folder`` (created if needed). Both files are written under
        temporary names first and renamed together at the end, so a failure (a full disk, a
        signal) leaves the previous library whole."""
        folder = Path(folder)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise GestureSimError(f"cannot create library folder {folder}: {exc.strerror}") from exc
        arrays, meta = self._pack()
        if self.segments:
            from gesture_sim.motion.signs import stored_form_signs

            key, signs = stored_form_signs(self)
            meta["form_signs"] = {"labeller": key, "signs": list(signs)}
        manifest = {
            "format": "gesture_sim.motion_library", "format_version": FORMAT_VERSION,
            "fingerprint": self.fingerprint, "fps": self.fps,
            "joint_names": list(self.joint_names),
            "n_clips": len(self.clips), "n_segments": len(self.segments),
            "duration_s": round(self.duration, 3),
            "param_normalisation": self.param_normalisation, "info": self.info, **meta,
        }
        with atomic_outputs(folder / ARRAYS, folder / MANIFEST) as (npz_tmp, json_tmp):
            with open(npz_tmp, "wb") as fh:
                np.savez_compressed(fh, **arrays)
            json_tmp.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, folder: str | os.PathLike[str]) -> MotionLibrary:
        """Read a library folder written by :meth:`save`; any decoding failure (a truncated
        npz, bad JSON, missing keys) is one GestureSimError naming the file."""
        with decoding_errors(folder, "motion library", _REBUILD):
            return cls._load(folder)

    @classmethod
    def _load(cls, folder: str | os.PathLike[str]) -> MotionLibrary:
        """Read a library folder written by :meth:`save`.

        Raises:
            GestureSimError: missing files, another format version, or a fingerprint mismatch.
        """
        folder = Path(folder)
        try:
            manifest = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise GestureSimError(f"{folder} is not a motion library (no {MANIFEST})") from None
        except (OSError, ValueError) as exc:
            raise damaged(folder / MANIFEST, "motion library manifest", _REBUILD, exc) from exc
        if not isinstance(manifest, dict):
            raise GestureSimError(f"{folder / MANIFEST}: damaged motion library manifest (not a "
                                  f"JSON object); {_REBUILD}")
        if manifest.get("format") != "gesture_sim.motion_library":
            raise GestureSimError(f"{folder / MANIFEST} is not a motion library manifest; "
                                  f"{_REBUILD}")
        if manifest.get("format_version") != FORMAT_VERSION:
            raise GestureSimError(
                f"motion library {folder} has format version {manifest.get('format_version')}, "
                f"this gesture-sim reads version {FORMAT_VERSION}; rebuild it with "
                "'gesture-sim library build'")
        try:
            with np.load(folder / ARRAYS) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except decoding_exceptions() as exc:
            raise damaged(folder / ARRAYS, "motion library arrays", _REBUILD, exc) from exc
        offsets = arrays["clip_offsets"]
        clips = []
        for i, meta in enumerate(manifest["clips"]):
            a, b = int(offsets[i]), int(offsets[i + 1])
            err = meta.get("retarget_error")
            clips.append(Clip(
                name=meta["name"], fps=float(meta["fps"]), qpos=arrays["qpos"][a:b],
                root_pos=arrays["root_pos"][a:b], root_quat=arrays["root_quat"][a:b],
                source=meta["source"], licence=meta["licence"], tags=tuple(meta["tags"]),
                keypoints=arrays["keypoints"][a:b] if "keypoints" in arrays else None,
                retarget_error=math.nan if err is None else float(err)))
        tags = manifest.get("segment_tags", {})
        signs = manifest.get("segment_signs", {})     # absent in libraries built before signs
        segments = [
            Segment(index=i, clip=int(r[0]), start=int(r[1]), end=int(r[2]),
                    params=arrays["params"][i], predecessor=int(r[3]), successor=int(r[4]),
                    interrupt_frames=(int(r[5]), int(r[6]), int(r[7])),
                    tags=tuple(tags.get(str(i), ())),
                    sign=None if signs.get(str(i)) is None else str(signs[str(i)]))
            for i, r in enumerate(arrays["segments"])]
        lib = cls(fps=float(manifest["fps"]), joint_names=tuple(manifest["joint_names"]),
                  clips=clips, segments=segments,
                  param_normalisation=manifest["param_normalisation"],
                  info=manifest.get("info", {}))
        form = manifest.get("form_signs")     # absent in libraries saved before stop 42
        if (isinstance(form, dict) and isinstance(form.get("signs"), list)
                and len(form["signs"]) == len(segments)):
            lib.form_signs = (str(form.get("labeller")), tuple(str(x) for x in form["signs"]))
        if lib.fingerprint != manifest.get("fingerprint"):
            raise GestureSimError(
                f"motion library {folder} is corrupt: its content does not match its "
                f"fingerprint; {_REBUILD}")
        return lib.with_joints_of_humanoid()

    def with_joints_of_humanoid(self) -> MotionLibrary:
        """This library with the humanoid's actuated joints as its columns.

        A library built before joints were added to the humanoid (the face rig's lips, inner
        brows and eyes) has fewer columns; the missing joints get 0 (their rest), in every
        clip. The content is otherwise the same, so the library keeps its fingerprint and the
        inference models and policies trained on it still fit. A library with a joint the
        humanoid does not have is refused.

        Raises:
            GestureSimError: a column names no joint of the humanoid.
        """
        from gesture_sim.sim.humanoid import ACTUATED_JOINTS

        names = tuple(self.joint_names)
        if names == ACTUATED_JOINTS:
            return self
        unknown = [n for n in names if n not in ACTUATED_JOINTS]
        if unknown:
            raise GestureSimError(f"the motion library has joints the humanoid does not have: "
                                  f"{', '.join(unknown[:5])}; {_REBUILD}")
        cols = np.array([ACTUATED_JOINTS.index(n) for n in names], dtype=int)
        clips = []
        for c in self.clips:
            q = np.zeros((c.n_frames, len(ACTUATED_JOINTS)), dtype=c.qpos.dtype)
            q[:, cols] = c.qpos
            clips.append(replace(c, qpos=q))
        return MotionLibrary(fps=self.fps, joint_names=ACTUATED_JOINTS, clips=clips,
                             segments=self.segments, param_normalisation=self.param_normalisation,
                             info=self.info, _fingerprint=self.fingerprint,
                             form_signs=self.form_signs)
