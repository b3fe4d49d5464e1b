"""What the control layer needs from the motion library and the inference model, as plain arrays.

The control layer codes against these two small containers, not against the library and model
classes, so that it can be trained and tested on synthetic libraries and swapped onto any library
(Gesture Controllers §7: "segments attach to the hidden states only through their kinematic
parameters"). Thin constructors adapt the real classes: :meth:`ControlLibrary.from_motion_library`
and :meth:`StateModel.from_inference`.

Conventions:
    * frames are counted from a segment's first frame (offset 0) unless a name says ``clip``;
    * a segment has ``K`` interruption frames (3 in the paper) and ``K + 1`` *decision points*:
      the interruption frames and the last frame ``length - 1``;
    * ``transition[i, j] = P(state j at t+1 | state i at t)``: rows sum to one.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gesture_sim.control.style import style_of
from gesture_sim.errors import GestureSimError

#: Number of kinematic parameters per segment: (T, D, V, A, C, H).
N_PARAMS = 6


def array_fingerprint(*arrays: np.ndarray, extra: str = "") -> str:
    """A short content hash of some arrays (dtype, shape and bytes) and a string."""
    h = hashlib.sha256(extra.encode())
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


@dataclass
class ControlLibrary:
    """The parts of a motion library the control layer reads.

    Attributes:
        lengths: (n,) int, segment lengths (frames), each >= 2.
        interrupt_frames: (n, K) int, interruption offsets from the segment start,
            ``0 < f < length``, non-decreasing along a row. An offset equal to ``length - 1``
            coincides with the last frame and is treated as the end (no interruption there).
        params: (n, 6) normalised log kinematic parameters (T, D, V, A, C, H).
        d_sp: (n, n) successor cost D_sp[i, j] of playing j after i has finished.
        d_in: (n, K, n) interruption cost D_in[i, k, j] of jumping from interruption frame k of i
            to the first frame of j (the library's penalty already included).
        tags: per segment, its tags (e.g. ``("wave",)``) for semantic labels.
        fps: frame rate (Hz); one control step = one frame.
        fingerprint: content hash of the library; a policy stores it and refuses a mismatch.
            :meth:`from_motion_library` hashes the adaptor mask into it when it found any, since
            a policy's unlabelled choices depend on which segments are co-speech.
        starts: (n,) int, first frame of each segment in its clip (for ``Decision.frame``).
        segment_qpos: ``i -> (length_i, n_joints)`` joint-angle targets (rad/m), or ``None``.
        frame_features: ``i -> (length_i, d)`` per-frame pose features whose Euclidean distance
            measures how different two frames look (for mid-clip semantic entries); defaults to
            ``segment_qpos``.
        pose_scale: cost per unit of ``frame_features`` distance, on the scale of ``d_in``.
        interrupt_penalty: the penalty included in ``d_in`` (also charged on semantic entries).
        joint_names: names of the columns of ``segment_qpos``.
        cospeech: (n,) bool, segments the controller may choose without a semantic label
            (co-speech motion; emblems, acting clips and self-touches only play when a label
            asks for them). Default: every segment.
        adaptor: (n,) bool, segments that are self-touches (a hand at the head, face or neck:
            :mod:`gesture_sim.motion.adaptors`), out of ``cospeech``; default: none.
        hand_speed: ``i -> (length_i,)`` mean speed of the two hands (m/s) per frame of segment
            ``i``, or ``None``; the synchrony layer finds the strokes in it.
        successors: (n,) int, the segment that followed each one in its source clip (-1: none),
            for reporting how often the controller replays the source order.
        rest_pose: (n_joints,) the pose the hands rest in when nobody speaks (rad), drawn from
            the library's own co-speech frames (:func:`rest_pose_from_frames`), or ``None``.
        hand_extent: (n,) mean distance (m) of the hands from their rest position over each
            segment, or ``None``: how large a gesture is, for the voice's amplitude control.
        styles: per segment, the performance style of its clip ('normal', 'tired', 'active'
            ...; '' unknown), from which the style tones are fitted.
    """

    lengths: np.ndarray
    interrupt_frames: np.ndarray
    params: np.ndarray
    d_sp: np.ndarray
    d_in: np.ndarray
    tags: tuple[tuple[str, ...], ...]
    fps: float
    fingerprint: str
    starts: np.ndarray | None = None
    segment_qpos: Callable[[int], np.ndarray] | None = None
    frame_features: Callable[[int], np.ndarray] | None = None
    pose_scale: float = 1.0
    interrupt_penalty: float = 0.0
    joint_names: tuple[str, ...] = ()
    cospeech: np.ndarray | None = None
    hand_speed: Callable[[int], np.ndarray] | None = None
    successors: np.ndarray | None = None
    rest_pose: np.ndarray | None = None
    styles: tuple[str, ...] = ()
    hand_extent: np.ndarray | None = None
    adaptor: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.lengths = np.asarray(self.lengths, dtype=np.int64)
        self.interrupt_frames = np.asarray(self.interrupt_frames, dtype=np.int64)
        self.params = np.asarray(self.params, dtype=float)
        self.d_sp = np.asarray(self.d_sp, dtype=float)
        self.d_in = np.asarray(self.d_in, dtype=float)
        if self.starts is None:
            self.starts = np.zeros(len(self.lengths), dtype=np.int64)
        self.starts = np.asarray(self.starts, dtype=np.int64)
        if len(self.tags) != len(self.lengths):
            missing = len(self.lengths) - len(self.tags)
            self.tags = tuple(tuple(t) for t in self.tags) + ((),) * missing
        n = len(self.lengths)
        self.cospeech = (np.ones(n, bool) if self.cospeech is None
                         else np.asarray(self.cospeech, dtype=bool))
        self.successors = (np.full(n, -1, np.int64) if self.successors is None
                           else np.asarray(self.successors, dtype=np.int64))
        self.adaptor = (np.zeros(n, bool) if self.adaptor is None
                        else np.asarray(self.adaptor, dtype=bool))
        self.validate()

    # ------------------------------------------------------------------ shape helpers
    @property
    def n_segments(self) -> int:
        return int(len(self.lengths))

    @property
    def n_interrupts(self) -> int:
        """K, the number of interruption frames per segment."""
        return int(self.interrupt_frames.shape[1])

    @property
    def duration_s(self) -> float:
        """Total length of all segments (s)."""
        return float(self.lengths.sum() / self.fps)

    def decision_frames(self) -> np.ndarray:
        """(n, K + 1) int: the interruption offsets, then the last frame ``length - 1``."""
        return np.concatenate([self.interrupt_frames, (self.lengths - 1)[:, None]], axis=1)

    def decision_points(self) -> list[dict[int, int]]:
        """Per segment, ``{frame: k}``: the decision frames a chooser answers at (interruption
        frames strictly inside the segment, and the last frame), k their column in
        :meth:`decision_frames` (the last frame's k is ``n_interrupts``); the first k wins where
        two offsets fall on one frame."""
        frames = self.decision_frames()
        last_k = frames.shape[1] - 1
        points: list[dict[int, int]] = [dict() for _ in range(self.n_segments)]
        for a in range(self.n_segments):
            for k, f in enumerate(frames[a]):
                if 0 < f < self.lengths[a] - 1 or k == last_k:
                    points[a].setdefault(int(f), k)
        return points

    def valid_interrupts(self) -> np.ndarray:
        """(n, K) bool: interruption frames strictly inside the segment (not the last frame)."""
        r = self.interrupt_frames
        return (r > 0) & (r < (self.lengths - 1)[:, None])

    def segments_with_tag(self, tag: str) -> np.ndarray:
        """Indices of the segments carrying ``tag``."""
        return np.array([i for i, t in enumerate(self.tags) if tag in t], dtype=np.int64)

    def all_tags(self) -> tuple[str, ...]:
        """The sorted set of tags used by any segment."""
        return tuple(sorted({t for tags in self.tags for t in tags}))

    def validate(self) -> None:
        """Raise :class:`GestureSimError` when the arrays do not fit together."""
        n = self.n_segments
        if n < 2:
            raise GestureSimError(
                f"the control layer needs a library of at least 2 segments, got {n}")
        if self.interrupt_frames.ndim != 2 or self.interrupt_frames.shape[0] != n:
            raise GestureSimError("interrupt_frames must have shape (n_segments, K)")
        k = self.n_interrupts
        if self.params.shape != (n, N_PARAMS):
            raise GestureSimError(f"params must have shape ({n}, 6), got {self.params.shape}")
        if self.d_sp.shape != (n, n) or self.d_in.shape != (n, k, n):
            raise GestureSimError(
                f"distance tables have shapes {self.d_sp.shape} and {self.d_in.shape}; "
                f"expected ({n}, {n}) and ({n}, {k}, {n})")
        if np.any(self.lengths < 2):
            raise GestureSimError("every segment needs at least 2 frames")
        r = self.interrupt_frames
        if k and (np.any(r < 1) or np.any(r > (self.lengths - 1)[:, None])
                  or np.any(np.diff(r, axis=1) < 0)):
            raise GestureSimError(
                "interruption frames must be increasing offsets inside each segment")
        if self.cospeech.shape != (n,) or not self.cospeech.any():
            raise GestureSimError("cospeech must be an (n_segments,) mask with a True entry")
        if self.successors.shape != (n,):
            raise GestureSimError("successors must have shape (n_segments,)")
        if self.adaptor.shape != (n,):
            raise GestureSimError("adaptor must be an (n_segments,) mask")
        if not (np.all(np.isfinite(self.params)) and np.all(np.isfinite(self.d_sp))
                and np.all(np.isfinite(self.d_in))):
            raise GestureSimError("library parameters and distances must be finite")

    # ------------------------------------------------------------------ frames
    def features(self, i: int) -> np.ndarray:
        """(length_i, d) pose features of segment ``i`` (for frame-to-frame distances)."""
        fn = self.frame_features or self.segment_qpos
        if fn is None:
            raise GestureSimError(
                "this library has no per-frame poses (needed for semantic entries)")
        return np.asarray(fn(i), dtype=float)

    # ------------------------------------------------------------------ adaptor
    @classmethod
    def from_motion_library(cls, library: Any, distances: Any = None) -> ControlLibrary:
        """Adapt a :class:`gesture_sim.motion.library.MotionLibrary` (duck-typed).

        Reads ``segments`` (length, interrupt_frames, start, tags), ``params``, ``fps``,
        ``fingerprint``, ``segment_qpos`` and ``distances()`` (D_sp, D_in with its penalty).
        Co-speech are the segments of untagged clips that are no self-touch
        (:func:`~gesture_sim.motion.adaptors.adaptor_segments`, on the humanoid's kinematics);
        a self-touch gets the tag :data:`~gesture_sim.motion.adaptors.SELF_TOUCH_TAG`, so a
        policy trained for the library has it as a semantic label, as the emblems are.
        The scale of the frame-to-frame pose distance used for semantic entries is fitted so that
        ``pose_scale * ||qpos(frame f of a) - qpos(frame 0 of b)|| + penalty`` matches D_in in the
        least-squares sense over the library.
        """
        segs = list(library.segments)
        dist = distances if distances is not None else library.distances()
        lengths = np.array([s.length for s in segs], dtype=np.int64)
        interrupts = np.array([tuple(s.interrupt_frames) for s in segs], dtype=np.int64)
        starts = np.array([s.start for s in segs], dtype=np.int64)
        tags = tuple(tuple(s.tags) for s in segs)
        penalty = float(getattr(dist, "interrupt_penalty", 0.0))
        clips = list(getattr(library, "clips", ()))
        # Co-speech: segments of untagged clips (a tagged clip is an emblem or acting clip)
        # that are no self-touch (an adaptor plays only when a label asks for it).
        cospeech = (np.array([not clips[s.clip].tags for s in segs], dtype=bool) if clips
                    else np.ones(len(segs), bool))
        if not cospeech.any():
            cospeech[:] = True
        adaptor = _self_touches(library, np.nonzero(cospeech)[0])
        if adaptor.any() and not (cospeech & ~adaptor).any():
            adaptor[:] = False          # a library of self-touches only: keep them co-speech
        fingerprint = str(library.fingerprint)
        if adaptor.any():
            from gesture_sim.motion.adaptors import SELF_TOUCH_TAG

            cospeech &= ~adaptor
            tags = tuple(t + (SELF_TOUCH_TAG,) if adaptor[i] and SELF_TOUCH_TAG not in t else t
                         for i, t in enumerate(tags))
            fingerprint = array_fingerprint(adaptor, extra=fingerprint)
        successors = np.array([getattr(s, "successor", -1) for s in segs], dtype=np.int64)
        features = None
        hand_speed = None
        if callable(getattr(library, "segment_keypoints", None)):
            try:
                library.segment_keypoints(0)

                def features(i: int) -> np.ndarray:      # RMS key-point distance, as D_in
                    kp = library.segment_keypoints(i)
                    return kp.reshape(len(kp), -1) / np.sqrt(kp.shape[1])
            except GestureSimError:
                features = None
        if features is not None:
            fps = float(library.fps)

            def hand_speed(i: int) -> np.ndarray:      # key points 0, 1: the hands
                kp = library.segment_keypoints(i)[:, :2]
                if len(kp) < 2:
                    return np.zeros(len(kp))
                return np.linalg.norm(np.gradient(kp, axis=0), axis=-1).mean(axis=1) * fps
        rest = extent = None
        if hand_speed is not None:
            idx = np.nonzero(cospeech)[0]
            qs = np.concatenate([np.asarray(library.segment_qpos(i)) for i in idx])
            hands = np.concatenate([library.segment_keypoints(i)[:, :2] for i in idx])
            sp = np.concatenate([hand_speed(i) for i in idx])
            rest, rest_frames = rest_pose_from_frames(qs, hands[:, :, 2].mean(axis=1), sp,
                                                      return_frames=True)
            rest_hands = np.median(hands[rest_frames], axis=0)                 # (2, 3)
            extent = np.array([np.linalg.norm(library.segment_keypoints(i)[:, :2] - rest_hands,
                                              axis=-1).mean() for i in range(len(segs))])
        lib = cls(
            lengths=lengths, interrupt_frames=interrupts, params=np.asarray(library.params),
            d_sp=np.asarray(dist.d_sp), d_in=np.asarray(dist.d_in), tags=tags,
            fps=float(library.fps), fingerprint=fingerprint, starts=starts,
            segment_qpos=library.segment_qpos, frame_features=features,
            interrupt_penalty=penalty,
            joint_names=tuple(getattr(library, "joint_names", ())),
            cospeech=cospeech, hand_speed=hand_speed, successors=successors, rest_pose=rest,
            hand_extent=extent, adaptor=adaptor,
            styles=tuple(style_of(clips[s.clip].name) for s in segs) if clips else (),
        )
        lib.pose_scale = fit_pose_scale(lib)
        return lib


def _self_touches(library: Any, indices: np.ndarray) -> np.ndarray:
    """(n,) bool: which of the segments ``indices`` of a motion library are self-touches; none
    when the library has no humanoid joint poses to tell (a synthetic or foreign library)."""
    n = len(library.segments)
    names = tuple(getattr(library, "joint_names", ()) or ())
    if not len(indices) or not names or not callable(getattr(library, "segment_qpos", None)):
        return np.zeros(n, bool)
    from gesture_sim.motion.adaptors import adaptor_segments

    try:
        return adaptor_segments(library, indices)
    except GestureSimError:
        return np.zeros(n, bool)


def rest_pose_from_frames(qpos: np.ndarray, hand_height: np.ndarray, hand_speed: np.ndarray,
                          share: float = 0.05, return_frames: bool = False):
    """A rest pose from real frames: the median pose of the frames whose hands are both low and
    slow (the ``share`` of frames with the lowest sum of height rank and speed rank).

    Args:
        qpos: (T, n_joints) joint angles; hand_height: (T,) mean hand height (m);
        hand_speed: (T,) mean hand speed (m/s).
    Returns:
        (n_joints,) the rest pose (and, with ``return_frames``, the indices of those frames).
    """
    qpos = np.asarray(qpos, dtype=float)
    rank = (np.argsort(np.argsort(hand_height)) + np.argsort(np.argsort(hand_speed)))
    k = max(1, int(round(share * len(qpos))))
    frames = np.argsort(rank)[:k]
    pose = np.median(qpos[frames], axis=0)
    return (pose, frames) if return_frames else pose


def fit_pose_scale(lib: ControlLibrary, max_pairs: int = 20000, seed: int = 0) -> float:
    """Least-squares scale c with ``c * ||feat(a, r_k) - feat(b, 0)|| ≈ D_in[a, k, b] - penalty``.

    Uses up to ``max_pairs`` random (a, k, b) triples; returns 1.0 when the library has no poses.
    """
    if lib.frame_features is None and lib.segment_qpos is None:
        return 1.0
    rng = np.random.default_rng(seed)
    n, k = lib.n_segments, lib.n_interrupts
    m = min(max_pairs, n * k * n)
    a = rng.integers(0, n, m)
    kk = rng.integers(0, k, m)
    b = rng.integers(0, n, m)
    first = np.stack([lib.features(i)[0] for i in range(n)])
    inter = [lib.features(i)[lib.interrupt_frames[i]] for i in range(n)]
    inter_arr = np.stack(inter)                                      # (n, K, d)
    d = np.linalg.norm(inter_arr[a, kk] - first[b], axis=-1)
    y = lib.d_in[a, kk, b] - lib.interrupt_penalty
    denom = float(d @ d)
    return float(d @ y / denom) if denom > 0 else 1.0


@dataclass
class StateModel:
    """The parts of the inference model the control layer reads.

    Attributes:
        means: (S, 6) mean kinematic parameters of each hidden state.
        covs: (S, 6, 6) full covariances.
        transition: (S, S) row-stochastic, ``transition[i, j] = P(j at t+1 | i at t)`` per
            control step (one frame).
        fingerprint: content hash of the model.
    """

    means: np.ndarray
    covs: np.ndarray
    transition: np.ndarray
    fingerprint: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.means = np.asarray(self.means, dtype=float)
        self.covs = np.asarray(self.covs, dtype=float)
        self.transition = np.asarray(self.transition, dtype=float)
        s = len(self.means)
        if self.means.shape != (s, N_PARAMS) or self.covs.shape != (s, N_PARAMS, N_PARAMS):
            raise GestureSimError("state model needs means (S, 6) and covariances (S, 6, 6)")
        if self.transition.shape != (s, s):
            raise GestureSimError(f"transition matrix must be ({s}, {s})")
        rows_ok = np.allclose(self.transition.sum(axis=1), 1.0, atol=1e-6)
        if np.any(self.transition < 0) or not rows_ok:
            raise GestureSimError("transition matrix rows must be probability distributions")
        if not self.fingerprint:
            self.fingerprint = array_fingerprint(self.means, self.covs, self.transition)

    @property
    def n_states(self) -> int:
        return int(len(self.means))

    @classmethod
    def from_inference(cls, model: Any) -> StateModel:
        """Adapt the inference layer's model (duck-typed).

        Looks for HMM output Gaussians as ``means``/``covars`` or ``means``/``covs`` (directly or on
        ``model.hmm``), and the CRF's normalised transition matrix as ``transition_matrix()`` /
        ``transition`` (row-stochastic) or ``T`` (column-stochastic, as in the paper's Appendix A).
        """
        src = getattr(model, "hmm", model)
        means = getattr(src, "means", None)
        if means is None:
            means = src.means_
        covs = next((getattr(src, n) for n in ("covs", "covars", "covariances", "covars_")
                     if getattr(src, n, None) is not None), None)
        if covs is None:
            raise GestureSimError("inference model has no state covariances")
        trans = None
        for holder in (model, getattr(model, "crf", None)):
            if holder is None:
                continue
            tm = getattr(holder, "transition_matrix", None)
            if tm is not None:
                trans = np.asarray(tm() if callable(tm) else tm)
                break
            if getattr(holder, "transition", None) is not None:
                trans = np.asarray(holder.transition)
                break
            if getattr(holder, "T", None) is not None:
                trans = np.asarray(holder.T).T
                break
        if trans is None:
            raise GestureSimError("inference model has no transition matrix")
        if (not np.allclose(trans.sum(axis=1), 1.0, atol=1e-6)
                and np.allclose(trans.sum(axis=0), 1.0)):
            trans = trans.T
        means, covs = np.asarray(means, dtype=float), np.asarray(covs, dtype=float)
        # The training data's hash alone is not enough: retraining on the same data with other
        # settings (e.g. another number of states) must give another fingerprint.
        fingerprint = array_fingerprint(means, covs, np.asarray(trans, dtype=float),
                                        extra=str(getattr(model, "fingerprint", "")))
        return cls(means=means, covs=covs, transition=trans, fingerprint=fingerprint)
