"""The Levine 2009 body sections: head and lower body, each segmented, clustered and modelled.

The thesis (digest §1.3, §3.2–3.3, §5.3) processes the head, the arms / upper body and the lower
body "separately into three distinct HMMs, since the gestures of these body parts do not always
coincide": each section is cut at the dips of its own joint-speed signal, its segments are
clustered, and its own HMM (start / continuation states, counted T, O, logistic f_i) runs on the
same syllable observations; the three streams are synthesised independently and combined.

Here the **arms** section is the existing one-stream model (:mod:`~gesture_sim.inference.
levine09`): the library's own segments (cut at the hands' speed dips) and the kinematic HMM's
states as clusters. This module adds the **head** and **lower-body** sections:

* **Joints** (by name, the humanoid's columns): head = ``neck_*``, ``head_*``; lower body =
  hips, knees, ankles, toes (the legs the balance controller drives; the pelvis itself is the
  floating root, so its motion shows through the legs); arms (only for
  :func:`segment_section` on a clip) = clavicles, shoulders, elbows, forearms, wrists.
* **Segmentation** (§2.2): the section's speed ``z(t) = sqrt(Σ_j u_j q̇_j²)`` over its joints'
  angles (Gaussian-smoothed positions, central differences; u_j = 1, the thesis's weights are
  not given) is cut at its local minima: the minima of prominence ≥ ``prominence`` × (90th
  percentile of z), at least ``min_length_s`` apart and from the ends (the deeper one wins, the
  thesis's "minimum length"), and segments longer than ``max_length_s`` are split into equal
  parts (its "upper bound on segment length" for long holds). The thesis cuts where z crosses a
  threshold; the minima are the same dips without a threshold to tune per section.
* **Clustering** (§2.3): each segment's descriptor is (log length, start pose of the section's
  joints, the dynamics summary of its key parts: mean |velocity|, max and mean |displacement
  from the start| per axis, each log-rescaled ``log(1 + x / 0.05 rad)``). Key parts: head = the
  neck + head rotation about each axis (3-D, as the thesis); lower body = hip flexion,
  abduction and knee flexion per side (6-D; the thesis uses the feet relative to the pelvis,
  which this joint-angle descriptor stands for without forward kinematics). The distance is the
  thesis's sum of parts ``D = |Δ log len| + w_pose ‖Δ pose‖ + Σ_k ‖Δ summary_k‖`` with the pose
  weight raised (× ``hold_pose_weight``) when either segment is still (its mean z below
  ``still_speed``). Ward's hierarchy is built on the concatenated descriptor (Euclidean, scipy)
  and cut at ``n_clusters``; each cluster's centre is its **medoid** under D (the thesis's
  medoid-constrained Ward keeps sample points as centres), and every segment — training or
  library — belongs to its nearest medoid under D. The medoids are stored, so the library's
  segments are assigned at run time exactly as the training segments were.
* **Model**: :func:`~gesture_sim.inference.levine09.train_levine09` over the section's segments
  and labels, with the arms model's discretiser statistics, so every section sees the same
  observation symbols.

Storage: ``l09_<section>_`` + the Levine09Model arrays, ``medoids`` and ``medoid_still``; the
meta keeps the model's meta, the joint names and the segmentation / clustering settings.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from gesture_sim.contracts import Syllable
from gesture_sim.errors import GestureSimError
from gesture_sim.inference.levine09 import Levine09Model, train_levine09

#: The sections this module models (the arms are the one-stream model itself).
SECTIONS = ("head", "lower")
#: Default number of clusters per section (Table 2.1's numbers are lost; the thesis's set II
#: lower body had two holds and one weight shift).
DEFAULT_CLUSTERS = {"head": 4, "lower": 3}
#: Summary scale of the log rescale (rad).
SUMMARY_SCALE = 0.05
_LEG_PARTS = ("hip", "knee", "ankle", "toe")
_ARM_PARTS = ("clavicle", "shoulder", "elbow", "forearm", "wrist")


def section_joint_names(section: str, joint_names: Sequence[str]) -> tuple[str, ...]:
    """The joints of ``section`` ("head", "arms" or "lower") among ``joint_names``, in order."""
    if section == "head":
        return tuple(j for j in joint_names if j.startswith(("neck_", "head_")))
    if section == "lower":
        return tuple(j for j in joint_names
                     if "_" in j and j.split("_", 1)[1].startswith(_LEG_PARTS))
    if section == "arms":
        return tuple(j for j in joint_names
                     if "_" in j and j.split("_", 1)[1].startswith(_ARM_PARTS))
    raise GestureSimError(f"unknown body section {section!r} (head, arms or lower)")


def _summary_parts(section: str, names: Sequence[str]) -> np.ndarray:
    """(p, len(names)) matrix: the key-part axes of the dynamics summary as sums of columns."""
    names = list(names)

    def rows(groups: list[list[str]]) -> np.ndarray:
        m = np.zeros((len(groups), len(names)))
        for r, g in enumerate(groups):
            for j in g:
                if j in names:
                    m[r, names.index(j)] = 1.0
        return m[m.sum(axis=1) > 0] if m.size else m

    if section == "head":
        return rows([[f"neck_{a}", f"head_{a}"] for a in ("flex", "bend", "twist")])
    if section == "lower":
        return rows([[f"{s}_{j}"] for s in ("left", "right")
                     for j in ("hip_flex", "hip_abduct", "knee_flex")])
    return rows([[f"{s}_{j}"] for s in ("left", "right")
                 for j in ("shoulder_flex", "shoulder_abduct", "elbow_flex")])


@dataclass(frozen=True)
class SectionSettings:
    """Segmentation and clustering settings of one section (see the module docstring).

    Attributes:
        smooth_s: Gaussian smoothing (s) of the joint angles before differencing.
        min_length_s: least distance (s) between two cuts and from a cut to the clip's ends.
        max_length_s: longer segments are split into equal parts no longer than this.
        prominence: a minimum cuts when its prominence is at least this share of the 90th
            percentile of the section's speed.
        still_speed: a segment whose mean speed (rad/s) is below this is still (a hold).
        hold_pose_weight: the pose weight of the distance when either segment is still.
        n_clusters: clusters of the section.
    """

    smooth_s: float = 0.05
    min_length_s: float = 0.2
    max_length_s: float = 1.5
    prominence: float = 0.1
    still_speed: float = 0.1
    hold_pose_weight: float = 3.0
    n_clusters: int = 4

    def to_dict(self) -> dict:
        return asdict(self)


#: Per-section defaults: the head moves fast and briefly, the lower body slowly.
DEFAULT_SETTINGS = {
    "head": SectionSettings(smooth_s=0.05, min_length_s=0.2, max_length_s=1.5,
                            n_clusters=DEFAULT_CLUSTERS["head"]),
    "arms": SectionSettings(smooth_s=0.05, min_length_s=0.3, max_length_s=1.5),
    "lower": SectionSettings(smooth_s=0.1, min_length_s=0.4, max_length_s=3.0,
                             still_speed=0.05, n_clusters=DEFAULT_CLUSTERS["lower"]),
}


def section_speed(qpos: np.ndarray, fps: float, smooth_s: float = 0.0) -> np.ndarray:
    """(T,) speed ``sqrt(Σ_j q̇_j²)`` (rad/s) of the section's joint angles ``qpos`` (T, J)."""
    q = np.asarray(qpos, dtype=float)
    if q.ndim == 1:
        q = q[:, None]
    if len(q) < 2:
        return np.zeros(len(q))
    if smooth_s > 0:
        q = gaussian_filter1d(q, smooth_s * fps, axis=0, mode="nearest")
    vel = np.gradient(q, 1.0 / fps, axis=0)
    return np.sqrt(np.sum(vel * vel, axis=1))


def cut_at_minima(speed: np.ndarray, fps: float, settings: SectionSettings) -> np.ndarray:
    """(m, 2) frame ranges ``[start, end)`` covering the signal, cut at the speed's minima."""
    z = np.asarray(speed, dtype=float)
    n = len(z)
    min_len = max(2, int(round(settings.min_length_s * fps)))
    if n < 2 * min_len:
        return np.array([[0, n]], dtype=int) if n else np.zeros((0, 2), dtype=int)
    scale = max(float(np.percentile(z, 90)), 1e-9)
    peaks, _ = find_peaks(-z, distance=min_len, prominence=settings.prominence * scale)
    cuts = [int(p) for p in peaks if min_len <= p <= n - min_len]
    bounds = [0]
    for c in cuts:                      # find_peaks' distance keeps them apart already
        if c - bounds[-1] >= min_len:
            bounds.append(c)
    bounds.append(n)
    max_len = max(2 * min_len, int(round(settings.max_length_s * fps)))
    out: list[tuple[int, int]] = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        parts = int(np.ceil((b - a) / max_len))
        edges = np.round(np.linspace(a, b, parts + 1)).astype(int)
        out.extend((int(x), int(y)) for x, y in zip(edges[:-1], edges[1:], strict=True))
    return np.array(out, dtype=int).reshape(-1, 2)


def segment_section(qpos: np.ndarray, joint_names: Sequence[str], section: str, fps: float,
                    settings: SectionSettings | None = None) -> np.ndarray:
    """(m, 2) segments of one clip (``qpos`` (T, n_joints), columns ``joint_names``) for a
    body section, cut at the minima of that section's own speed."""
    s = settings or DEFAULT_SETTINGS[section]
    names = section_joint_names(section, joint_names)
    if not names:
        raise GestureSimError(f"the joints have no {section} joints")
    cols = [list(joint_names).index(j) for j in names]
    q = np.asarray(qpos, dtype=float)[:, cols]
    return cut_at_minima(section_speed(q, fps, s.smooth_s), fps, s)


def segment_descriptors(q: np.ndarray, segments: np.ndarray, fps: float, parts: np.ndarray,
                        settings: SectionSettings) -> tuple[np.ndarray, np.ndarray]:
    """Per segment the descriptor (m, 1 + J + 3p) and the still flag (m,).

    ``q`` (T, J): the section's joint angles; ``parts`` (p, J): the summary's key-part axes.
    Descriptor: [log length (s), start pose (J), log-rescaled mean |velocity| (p), max
    |displacement| (p), mean |displacement| (p)].
    """
    q = np.asarray(q, dtype=float)
    speed = section_speed(q, fps, settings.smooth_s)
    key = q @ parts.T
    rows, still = [], []
    for a, b in np.asarray(segments, dtype=int):
        k = key[a:b]
        rel = np.abs(k - k[0])
        vel = (np.abs(np.diff(k, axis=0)).mean(axis=0) * fps if b - a > 1
               else np.zeros(k.shape[1]))
        summ = [np.log1p(x / SUMMARY_SCALE) for x in (vel, rel.max(axis=0), rel.mean(axis=0))]
        rows.append(np.concatenate([[np.log(max(b - a, 1) / fps)], q[a], *summ]))
        still.append(float(speed[a:b].mean()) < settings.still_speed)
    return np.array(rows, dtype=float).reshape(len(rows), -1), np.array(still, dtype=bool)


def descriptor_distance(x: np.ndarray, x_still: np.ndarray, y: np.ndarray, y_still: np.ndarray,
                        n_pose: int, settings: SectionSettings) -> np.ndarray:
    """(len(x), len(y)) thesis distance D (module docstring) between descriptor sets."""
    x, y = np.atleast_2d(x), np.atleast_2d(y)
    p = (x.shape[1] - 1 - n_pose) // 3
    d = np.abs(x[:, None, 0] - y[None, :, 0])
    w_pose = np.where(np.asarray(x_still)[:, None] | np.asarray(y_still)[None, :],
                      settings.hold_pose_weight, 1.0)
    sl = slice(1, 1 + n_pose)
    d = d + w_pose * np.linalg.norm(x[:, None, sl] - y[None, :, sl], axis=-1)
    for k in range(3):
        sk = slice(1 + n_pose + k * p, 1 + n_pose + (k + 1) * p)
        d = d + np.linalg.norm(x[:, None, sk] - y[None, :, sk], axis=-1)
    return d


@dataclass
class SectionClusters:
    """The clusters of one section: medoid descriptors and the settings that made them.

    Attributes:
        section: "head" or "lower". joint_names: the section's joints (descriptor columns).
        settings: segmentation and clustering settings. medoids: (k, d) descriptors of the
        cluster centres. medoid_still: (k,) their still flags.
    """

    section: str
    joint_names: tuple[str, ...]
    settings: SectionSettings
    medoids: np.ndarray
    medoid_still: np.ndarray

    @property
    def n_clusters(self) -> int:
        return int(len(self.medoids))

    def parts(self) -> np.ndarray:
        return _summary_parts(self.section, self.joint_names)

    def columns(self, joint_names: Sequence[str]) -> np.ndarray:
        """Indices of the section's joints among ``joint_names``."""
        names = list(joint_names)
        missing = [j for j in self.joint_names if j not in names]
        if missing:
            raise GestureSimError(f"the library lacks the {self.section} joints {missing}")
        return np.array([names.index(j) for j in self.joint_names], dtype=int)

    def segment(self, qpos: np.ndarray, joint_names: Sequence[str], fps: float) -> np.ndarray:
        """(m, 2) segments of one clip, cut at this section's speed minima."""
        q = np.asarray(qpos, dtype=float)[:, self.columns(joint_names)]
        return cut_at_minima(section_speed(q, fps, self.settings.smooth_s), fps, self.settings)

    def label(self, qpos: np.ndarray, joint_names: Sequence[str], fps: float,
              segments: np.ndarray) -> np.ndarray:
        """(m,) nearest medoid (under D) of each segment of one clip."""
        q = np.asarray(qpos, dtype=float)[:, self.columns(joint_names)]
        desc, still = segment_descriptors(q, segments, fps, self.parts(), self.settings)
        if len(desc) == 0:
            return np.zeros(0, dtype=np.int64)
        d = descriptor_distance(desc, still, self.medoids, self.medoid_still,
                                len(self.joint_names), self.settings)
        return d.argmin(axis=1).astype(np.int64)

    def to_arrays(self, prefix: str) -> dict[str, np.ndarray]:
        return {f"{prefix}medoids": self.medoids,
                f"{prefix}medoid_still": self.medoid_still.astype(np.int8)}

    def meta(self) -> dict:
        return {"joint_names": list(self.joint_names), "settings": self.settings.to_dict()}

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict, prefix: str, section: str
                    ) -> SectionClusters:
        return cls(section, tuple(meta["joint_names"]), SectionSettings(**meta["settings"]),
                   np.asarray(arrays[f"{prefix}medoids"], dtype=float),
                   np.asarray(arrays[f"{prefix}medoid_still"]).astype(bool))


#: Above this many segments of a section the clusters are fitted on a seeded sample of them.
MAX_CLUSTERED_SEGMENTS = 2000


def fit_section_clusters(section: str, joint_names: Sequence[str],
                         qpos_list: Sequence[np.ndarray], segment_lists: Sequence[np.ndarray],
                         fps_list: Sequence[float], settings: SectionSettings
                         ) -> tuple[SectionClusters, list[np.ndarray]]:
    """Ward's hierarchy on the descriptors, cut at ``settings.n_clusters``, medoid centres;
    returns the clusters and each take's labels (nearest medoid)."""
    names = section_joint_names(section, joint_names)
    cols = [list(joint_names).index(j) for j in names]
    parts = _summary_parts(section, names)
    descs, stills = [], []
    for q, segs, fps in zip(qpos_list, segment_lists, fps_list, strict=True):
        d, st = segment_descriptors(np.asarray(q, dtype=float)[:, cols], segs, fps, parts,
                                    settings)
        descs.append(d)
        stills.append(st)
    x, still = np.concatenate(descs), np.concatenate(stills)
    if len(x) > MAX_CLUSTERED_SEGMENTS:
        # a large corpus: the hierarchy and the medoids on a seeded sample (Ward's linkage and
        # the medoid distances grow with the square of the count); every segment of every take
        # is then labelled by its nearest medoid below, as the library's are at run time
        pick = np.sort(np.random.default_rng(0).choice(len(x), MAX_CLUSTERED_SEGMENTS,
                                                       replace=False))
        x, still = x[pick], still[pick]
    k = max(1, min(settings.n_clusters, len(x)))
    if k == 1:
        raw = np.ones(len(x), dtype=int)
    else:
        raw = fcluster(linkage(x, method="ward"), t=k, criterion="maxclust")
    n_pose = len(names)
    d_all = descriptor_distance(x, still, x, still, n_pose, settings)
    medoids = []
    for c in np.unique(raw):
        idx = np.flatnonzero(raw == c)
        medoids.append(int(idx[np.argmin(d_all[np.ix_(idx, idx)].sum(axis=1))]))
    clusters = SectionClusters(section, names, settings, x[medoids].copy(), still[medoids].copy())
    labels = [descriptor_distance(d, st, clusters.medoids, clusters.medoid_still, n_pose,
                                  settings).argmin(axis=1).astype(np.int64)
              for d, st in zip(descs, stills, strict=True)]
    return clusters, labels


@dataclass
class SectionModel:
    """One body section's clusters and its Levine 2009 HMM."""

    section: str
    clusters: SectionClusters
    model: Levine09Model
    info: dict = field(default_factory=dict)

    def to_arrays(self, prefix: str) -> dict[str, np.ndarray]:
        return self.model.to_arrays(prefix) | self.clusters.to_arrays(prefix)

    def meta(self) -> dict:
        return {"model": self.model.meta(), "clusters": self.clusters.meta(), "info": self.info}

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict, prefix: str, section: str) -> SectionModel:
        model = Levine09Model.from_arrays(arrays, meta["model"], prefix)
        clusters = SectionClusters.from_arrays(arrays, meta["clusters"], prefix, section)
        if clusters.n_clusters != model.n_clusters:
            raise GestureSimError(f"the {section} section has {clusters.n_clusters} medoids "
                                  f"but a model of {model.n_clusters} clusters")
        return cls(section, clusters, model, dict(meta.get("info", {})))


def load_levine09(arrays: dict, meta: dict, prefix: str = "l09_") -> Levine09Model:
    """A stored Levine 2009 model with its body sections (``meta["sections"]``, where stored).

    Args:
        arrays: the model file's arrays; meta: its JSON part (:meth:`Levine09Model.meta`);
        prefix: the arrays' key prefix.
    """
    model = Levine09Model.from_arrays(arrays, meta, prefix)
    if meta.get("sections"):
        model.sections = {name: SectionModel.from_arrays(arrays, m, f"{prefix}{name}_", name)
                          for name, m in meta["sections"].items()}
    return model


def train_sections(
    syllable_lists: Sequence[Sequence[Syllable]], qpos_lists: Sequence[np.ndarray],
    joint_names: Sequence[str], motion_fps: Sequence[float], rate_hz: float,
    durations_s: Sequence[float], stats: dict, silence_chunk_s: float,
    settings: dict[str, SectionSettings] | None = None, sections: Sequence[str] = SECTIONS,
    pseudo_count: float = 0.5,
) -> dict[str, SectionModel]:
    """Segment, cluster and count each section over the takes.

    Args:
        syllable_lists: per take, the tracker's syllables (as for the arms model).
        qpos_lists: per take, (T, n_joints) joint angles, columns ``joint_names``.
        motion_fps, rate_hz, durations_s, silence_chunk_s, pseudo_count: as
            :func:`~gesture_sim.inference.levine09.train_levine09`.
        stats: the arms model's discretiser statistics (same symbols in every section).
        settings: per section; default :data:`DEFAULT_SETTINGS`.
    """
    settings = settings or {}
    out: dict[str, SectionModel] = {}
    for name in sections:
        s = settings.get(name, DEFAULT_SETTINGS[name])
        segs = [segment_section(q, joint_names, name, fps, s)
                for q, fps in zip(qpos_lists, motion_fps, strict=True)]
        clusters, labels = fit_section_clusters(name, joint_names, qpos_lists, segs, motion_fps,
                                                s)
        model = train_levine09(syllable_lists, segs, labels, clusters.n_clusters, motion_fps,
                               rate_hz, durations_s, silence_chunk_s=silence_chunk_s,
                               pseudo_count=pseudo_count, stats=stats)
        lengths = np.concatenate([np.diff(g, axis=1)[:, 0] for g in segs])
        info = {"segments": int(len(lengths)), "clusters": clusters.n_clusters,
                "mean_segment_s": float(lengths.mean() / np.mean(motion_fps)),
                "cluster_sizes": np.bincount(np.concatenate(labels),
                                             minlength=clusters.n_clusters).tolist()}
        out[name] = SectionModel(name, clusters, model, info)
    return out


class SectionLibrary:
    """One section's segments of a motion library's clips, as the 2009 synthesis reads a
    library (``n_segments``, ``lengths``, ``starts``, ``tags``, ``segment_qpos``,
    ``frame_features``, ``features``).

    Args:
        library: a :class:`~gesture_sim.motion.library.MotionLibrary` (clips with qpos).
        clusters: the section's :class:`SectionClusters`.
        clips: indices of the clips to segment (default: the co-speech clips,
            :func:`cospeech_clips`).
    """

    def __init__(self, library, clusters: SectionClusters, clips: Sequence[int] | None = None
                 ) -> None:
        self.clusters_model = clusters
        self.joint_names = tuple(library.joint_names)
        self.fps = float(library.fps)
        self.cols = clusters.columns(self.joint_names)
        self._clips = list(library.clips)
        clip_ids = list(cospeech_clips(library) if clips is None else clips)
        rows, labels = [], []
        for c in clip_ids:
            q = self._clips[c].qpos
            segs = clusters.segment(q, self.joint_names, self.fps)
            segs = segs[np.diff(segs, axis=1)[:, 0] >= 2]
            if len(segs) == 0:
                continue
            labels.append(clusters.label(q, self.joint_names, self.fps, segs))
            rows.extend((c, int(a), int(b)) for a, b in segs)
        if not rows:
            raise GestureSimError(f"no {clusters.section} segments in the library's clips")
        table = np.array(rows, dtype=np.int64)
        self.clip = table[:, 0]
        self.starts = table[:, 1]
        self.ends = table[:, 2]
        self.lengths = self.ends - self.starts
        self.labels = np.concatenate(labels)
        self.tags: tuple[tuple[str, ...], ...] = ((),) * len(self.lengths)
        self.frame_features = self.features

    @property
    def n_segments(self) -> int:
        return int(len(self.lengths))

    def segment_qpos(self, i: int) -> np.ndarray:
        """(length_i, n_joints) joint angles of section segment ``i`` (the whole clip rows)."""
        return self._clips[int(self.clip[i])].qpos[self.starts[i]:self.ends[i]]

    def features(self, i: int) -> np.ndarray:
        """(length_i, J) the section's joint angles (rad): the start-pose difference."""
        return np.asarray(self.segment_qpos(i), dtype=float)[:, self.cols]


def cospeech_clips(library) -> list[int]:
    """Clips the section streams play: untagged clips of a co-speech source (BEAT), or every
    untagged clip when none is co-speech (as the arms' co-speech mask)."""
    clips = list(library.clips)
    untagged = [i for i, c in enumerate(clips) if not c.tags]
    beat = [i for i in untagged if "BEAT" in str(getattr(clips[i], "source", "")).upper()]
    return beat or untagged or list(range(len(clips)))
