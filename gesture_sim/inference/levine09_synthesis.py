"""The Levine 2009 synthesis itself (thesis Ch. 5): the ``--method levine09`` selector.

One call per control step (one library frame, 30 Hz). The 2009 system decides only at syllable
observations and plays the chosen segment frame by frame in between:

1. **Observations.** One discrete prosody symbol per emitted syllable, and one silent
   medium-length symbol per ``silence_chunk_s`` of silence, exactly as the trained model's
   :class:`~gesture_sim.inference.levine09.ObservationStream` produces them. An observation is
   processed at the step where the tracker emits it: the project's tracker emits a syllable
   once the next intensity peak confirms it, so decisions fall on syllable peaks
   (syllable-peak timing, thesis §3.1/§5.4); there is no look-ahead.
2. **Forward update** of α (2S: start states s_i, continuation states c_i) and τ̄ by the
   existing :class:`~gesture_sim.inference.levine09.Levine09Filter` (Eqs. 5.1–5.3).
3. **Direct probabilities** (Eq. 5.4) from the *displayed* previous state — s_i if the playing
   segment started at the previous observation, else c_i — with its true elapsed fraction
   ``τ' = frames shown so far / segment length`` of the concrete segment that is playing:
   ``γ ∝ P(· | displayed) ⊙ O[V_t]``.
4. **Sampling** (not argmax) of A_t from ``normalize(α ⊙ γ)`` with a seeded generator.
   A_t = c_i: keep playing (early termination declined). A_t = s_j: start a segment of
   cluster j *now*, at this observation (early termination of the playing segment).
5. **Segment choice within a cluster** (§5.5): the allowed segments of cluster j whose first
   pose is within ``pose_tolerance`` of the smallest start-pose difference to the frame shown
   last, one picked uniformly at random.
6. **Late termination** (§5.4): when the playing segment has shown its last frame and no
   observation has come, the last observation is re-examined: α_{t-1}, τ̄_{t-1} are restored,
   the update is redone with ``→ c_i`` forbidden (i = the cluster displayed before that
   observation), γ is recomputed likewise, a start state is resampled and its segment starts
   from its first frame at this step. When an observation finds the playing segment with no
   frame left, the update is done with ``→ c_i`` forbidden directly (kind ``"end"``).

Decisions (:class:`~gesture_sim.contracts.Decision`, ``synth.decisions``) are logged at every
observation and at every switch; ``kind`` is ``"start"`` (first segment after a reset),
``"continue"`` (an observation sampled c_i), ``"early"`` (an observation sampled a start state
while the segment had frames left), ``"end"`` (an observation found the segment finished) or
``"late"`` (late termination between observations). ``costs``: ``p`` (probability of the
sampled state under the normalised α ⊙ γ, after masking), ``p_alpha`` and ``p_gamma`` (its α
and γ), ``state`` (index in 0..2S-1: s_i = i, c_i = S + i), ``cluster``, ``continue`` (1/0),
``symbol`` (observation code, -1 for the first start), ``tau`` (true τ' of the displayed
segment), ``candidates`` (segments within the pose tolerance) and ``pose_diff`` (start-pose
difference of the chosen one, NaN without a reference pose).

Adaptations to this project (documented, not in the thesis):

* **Clusters = the kinematic HMM's states** (as in :mod:`~gesture_sim.inference.levine09`'s
  training). Training labels each *training* segment by posterior mass, which needs the training
  take; the model does not store a mapping for the library's segments, so each library segment
  is mapped to the state of highest likelihood ``argmax_i log N(params; μ_i, Σ_i)`` of the
  model's Gaussians (deterministic; ties to the lower index), unless ``clusters`` is given.
* **Body sections.** With a model without sections (every model before them), one HMM for
  the whole body, as before. With a model that has them (``Levine09Model.sections``, see
  :mod:`~gesture_sim.inference.levine09_sections`) and the motion library given
  (``motion_library``), three streams run on the *same* observation symbols, each with its own
  filter, sampling, segment choice, early / late termination and seeded generator: the
  **arms** stream is exactly the one-stream synthesis above (same segments, same draws, so its
  decisions are those of the old path), the **head** and **lower-body** streams play their own
  section segments of the co-speech clips (cut at that section's speed minima). The target is
  composed by joint masks: the arms stream's pose for every joint, then the head stream's
  segment frame for the neck / head joints and the lower-body stream's for the leg joints.
  A section switch is blended over ``section_blend_frames`` steps on that section's joints
  (the pipeline's ramp only follows the arms stream's switches). ``StepResult.segment`` /
  ``frame`` stay the arms stream's; :meth:`Levine09Synthesis.section_frame` gives a section's
  (clip, clip frame) — the pipeline's ``legs="clip"`` stage reads its weight shifts from the
  result's segment, not from the target's leg joints (see the report of issue 29).
* **Allowed segments**: only segments with ``allowed`` true are ever chosen (default: the
  untagged segments, i.e. no emblem). Start states of clusters without an allowed segment get
  probability 0 in the sampling (α itself keeps integrating the evidence unmasked).
* **Pose difference**: Euclidean distance of the library's per-frame pose features
  (``ControlLibrary.features``: RMS key-point distance in metres for the default library,
  joint angles otherwise). The thesis's tolerance is not given; the default
  ``pose_tolerance`` = 0.05 m RMS keeps the segments starting within 5 cm (RMS over the key
  points) of the best match. Without a playing segment (the first start) every allowed
  segment of the cluster is a candidate.
* **Blending** is the pipeline's (its switch ramp), not the thesis's velocity-based slerp.
* **Repeated late termination**: if a replacement segment also ends before the next
  observation (or a segment started *at* an observation does), the same corrected distribution
  (last observation redone with the previously displayed cluster's continuation forbidden) is
  sampled again. The model's α then treats the new segment as started at that observation, so
  it is "not always as far along as it should be" — the thesis's own limitation.
* **First step**: before any observation a segment must be shown; its cluster is sampled from
  the initial α (uniform over the start states, masked as above).

Cost (shipped model, S = 6, 12.5 s of real speech, a shared 2-core machine): a step without an
observation is a frame advance, median 4 µs; a step with a decision (a (2S)² transition build,
two vector products, one draw, the pose search) median about 0.2 ms; mean over all steps
45–100 µs. With the head and lower-body streams (shipped model since issue 29: head S = 4,
lower body S = 3) the mean is about three times that, 110 µs against 35 µs for one stream
(two 62-s BEAT2 files × 3 seeds, same machine). ``mean_step_us`` / ``max_step_us`` report the
measured cost per step (all streams).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gesture_sim.contracts import Decision, Syllable
from gesture_sim.control.controller import StepResult
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.control.ramp import DEFAULT_BLEND_FRAMES, SwitchRamp
from gesture_sim.errors import GestureSimError
from gesture_sim.inference.levine09 import Levine09Filter, Levine09Model

#: Start-pose tolerance (pose-feature units: metres RMS over the key points for the default
#: library) around the smallest start-pose difference within the chosen cluster.
DEFAULT_POSE_TOLERANCE = 0.05

_LOG2PI = float(np.log(2.0 * np.pi))


def clusters_by_likelihood(params: np.ndarray, means: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """(n,) state of highest Gaussian log-likelihood for each segment's parameters (n, 6)."""
    params = np.atleast_2d(np.asarray(params, dtype=float))
    means = np.asarray(means, dtype=float)
    covs = np.asarray(covs, dtype=float)
    ll = np.empty((len(params), len(means)))
    for i in range(len(means)):
        chol = np.linalg.cholesky(covs[i])
        z = np.linalg.solve(chol, (params - means[i]).T)
        ll[:, i] = -0.5 * (np.sum(z * z, axis=0) + params.shape[1] * _LOG2PI) - np.sum(
            np.log(np.diag(chol)))
    return ll.argmax(axis=1)


def _gaussians(state_model: Any) -> tuple[np.ndarray, np.ndarray]:
    """(means, covs) of a GestureModel, KinematicHMM or StateModel (duck-typed)."""
    src = getattr(state_model, "hmm", state_model)
    means = getattr(src, "means", None)
    covs = getattr(src, "covars", getattr(src, "covs", None))
    if means is None or covs is None:
        raise GestureSimError("the Levine 2009 synthesis needs the model's state Gaussians")
    return np.asarray(means, dtype=float), np.asarray(covs, dtype=float)


def cospeech_mask(motion_library: Any) -> np.ndarray:
    """(n,) bool: untagged segments of co-speech clips (source BEAT) of a MotionLibrary;
    all untagged segments when no clip is co-speech."""
    segs = list(motion_library.segments)
    untagged = np.array([not s.tags for s in segs], dtype=bool)
    beat = np.array(["BEAT" in motion_library.clips[s.clip].source.upper() for s in segs],
                    dtype=bool)
    return untagged & beat if np.any(untagged & beat) else untagged


@dataclass
class _LastObservation:
    """What the late-termination rollback needs to redo an observation."""

    snapshot: tuple[np.ndarray, np.ndarray, float]
    t: float
    code: int
    prev_state: int          # displayed state before the observation (0..2S-1)
    tau: float               # its true elapsed fraction τ' at the observation


class Levine09Synthesis:
    """The 2009 synthesis (see the module docstring) as a per-step selector.

    Args:
        model: the trained 2009 HMM (``GestureModel.baseline``).
        library: the control library whose segments are played.
        seed: seeds the state sampling and the segment choice (deterministic for a seed).
        allowed: (n_segments,) bool, the segments it may choose; default: untagged segments.
        clusters: (n_segments,) int, cluster (= HMM state) of each segment; computed from
            ``state_model``'s Gaussians by maximum likelihood when not given.
        state_model: anything with the state Gaussians (a GestureModel, its ``hmm``, or a
            control ``StateModel``); needed when ``clusters`` is not given.
        pose_tolerance: start-pose tolerance (pose-feature units) around the minimum.
        motion_library: the :class:`~gesture_sim.motion.library.MotionLibrary` whose clips the
            head and lower-body streams cut into their sections' segments; without it (or
            without ``model.sections``) the synthesis is the one stream.
        section_blend_frames: steps over which a section stream's switch is blended in.
    """

    def __init__(self, model: Levine09Model, library: ControlLibrary, seed: int = 0,
                 allowed: np.ndarray | None = None, *, clusters: np.ndarray | None = None,
                 state_model: Any = None,
                 pose_tolerance: float = DEFAULT_POSE_TOLERANCE,
                 motion_library: Any = None,
                 section_blend_frames: int = DEFAULT_BLEND_FRAMES) -> None:
        self.model = model
        self.library = library
        self.seed = int(seed)
        self.pose_tolerance = float(pose_tolerance)
        n, s = library.n_segments, model.n_clusters
        if clusters is None:
            if state_model is None:
                raise GestureSimError(
                    "Levine09Synthesis needs the segments' clusters or the model's Gaussians "
                    "(pass state_model=the GestureModel)")
            means, covs = _gaussians(state_model)
            if len(means) != s:
                raise GestureSimError(
                    f"the state model has {len(means)} states, the 2009 model {s} clusters")
            clusters = clusters_by_likelihood(library.params, means, covs)
        self.clusters = np.asarray(clusters, dtype=np.int64)
        if self.clusters.shape != (n,) or np.any((self.clusters < 0) | (self.clusters >= s)):
            raise GestureSimError(f"clusters must be ({n},) ints in [0, {s})")
        if allowed is None:
            allowed = np.array([not t for t in library.tags], dtype=bool)
        self.allowed = np.asarray(allowed, dtype=bool)
        if self.allowed.shape != (n,):
            raise GestureSimError(f"allowed must be a ({n},) bool array")
        if not np.any(self.allowed):
            raise GestureSimError("no segment is allowed for the Levine 2009 synthesis")
        self.members = [np.flatnonzero(self.allowed & (self.clusters == j)) for j in range(s)]
        #: (S,) clusters that have at least one allowed segment.
        self.has_members = np.array([len(m) > 0 for m in self.members], dtype=bool)
        self._start_mask = np.concatenate([self.has_members, np.ones(s, dtype=bool)])
        self._feat0 = None
        if library.frame_features is not None or library.segment_qpos is not None:
            self._feat0 = np.stack([library.features(i)[0] for i in range(n)])
        self._qpos: dict[int, np.ndarray] = {}
        self._feat: dict[int, np.ndarray] = {}
        self.filter = Levine09Filter(model)
        #: The head / lower-body streams (empty: the one-stream synthesis).
        self.sections: list[_SectionStream] = []
        if model.sections and getattr(motion_library, "clips", None):
            self.sections = _section_streams(model, library, motion_library, self.seed,
                                             pose_tolerance, section_blend_frames)
        self.reset()

    # ------------------------------------------------------------------ settings
    def request_label(self, label: str, t: float | None = None) -> bool:
        """The 2009 system has no semantic labels: always False."""
        return False

    def set_style(self, dial: float) -> None:
        """The 2009 system has no style input: no-op."""

    def reset(self) -> None:
        """Forget the playing segment, the filter state and the decision log."""
        self.filter.reset()
        self.segment = -1
        self.frame = -1
        self.state = -1                 # displayed HMM state (s_i = i, c_i = S + i)
        self.decisions: list[Decision] = []
        self._last: _LastObservation | None = None
        self._rng = np.random.default_rng(self.seed)
        self.n_steps = 0
        self.total_s = 0.0
        self.max_step_s = 0.0
        for sec in getattr(self, "sections", ()):
            sec.reset()

    @property
    def mean_step_us(self) -> float:
        """Mean measured cost of a step (µs) since the last reset."""
        return 1e6 * self.total_s / max(self.n_steps, 1)

    @property
    def max_step_us(self) -> float:
        """Largest measured cost of a step (µs) since the last reset."""
        return 1e6 * self.max_step_s

    # ------------------------------------------------------------------ frames
    def target(self, segment: int, frame: int) -> np.ndarray | None:
        """(n_joints,) joint-angle target of a library frame, or None without poses."""
        if self.library.segment_qpos is None:
            return None
        q = self._qpos.get(segment)
        if q is None:
            q = self._qpos[segment] = np.asarray(self.library.segment_qpos(segment))
        return q[frame]

    def _pose(self, segment: int, frame: int) -> np.ndarray:
        f = self._feat.get(segment)
        if f is None:
            f = self._feat[segment] = self.library.features(segment)
        return f[frame]

    # ------------------------------------------------------------------ the 2009 rules
    def direct(self, prev_state: int, tau: float, code: int, forbid: Sequence[int] = ()
               ) -> np.ndarray:
        """γ (2S,) ∝ P(A_t | displayed A_{t-1}, its true τ') ⊙ O[V_t] (Eq. 5.4)."""
        m = self.model
        s = m.n_clusters
        tau_p = np.zeros(s)
        tau_p[prev_state % s] = tau
        row = m.step_transitions(tau_p, forbid)[prev_state] * m.emit[:, code]
        total = row.sum()
        return row / total if total > 0 else np.full(2 * s, 1.0 / (2 * s))

    def _sample(self, dist: np.ndarray, fallback: np.ndarray) -> tuple[int, float]:
        """Draw a state from ``dist`` masked to reachable starts; ``fallback`` if it is all 0."""
        p = np.where(self._start_mask, dist, 0.0)
        total = p.sum()
        if not total > 0:
            p = np.where(self._start_mask, fallback, 0.0)
            total = p.sum()
        if not total > 0:               # nothing left: any cluster with an allowed segment
            p = np.concatenate([self.has_members.astype(float), np.zeros(len(dist) // 2)])
            total = p.sum()
        p = p / total
        k = int(self._rng.choice(len(p), p=p))
        return k, float(p[k])

    def _choose_segment(self, cluster: int) -> tuple[int, int, float]:
        """(segment, candidates, pose difference) of the §5.5 choice within a cluster."""
        cand = self.members[cluster]
        if self.segment < 0 or self._feat0 is None:
            return int(cand[self._rng.integers(len(cand))]), len(cand), float("nan")
        ref = self._pose(self.segment, max(self.frame, 0))   # the frame shown last
        d = np.linalg.norm(self._feat0[cand] - ref, axis=1)
        near = np.flatnonzero(d <= d.min() + self.pose_tolerance)
        k = int(near[self._rng.integers(len(near))])
        return int(cand[k]), len(near), float(d[k])

    def _decision(self, t: float, kind: str, state: int, p: float, alpha: np.ndarray,
                  gamma: np.ndarray, code: int, tau: float, extra: tuple[int, float] | None
                  ) -> Decision:
        s = self.model.n_clusters
        cont = state >= s
        costs = {"p": p, "p_alpha": float(alpha[state]), "p_gamma": float(gamma[state]),
                 "state": float(state), "cluster": float(state % s),
                 "continue": float(cont), "symbol": float(code), "tau": float(tau)}
        if extra is not None:
            costs["candidates"], costs["pose_diff"] = float(extra[0]), extra[1]
        frame = 0 if not cont else self.frame + 1
        return Decision(t=t, segment_id=self.segment,
                        frame=int(self.library.starts[self.segment]) + frame, kind=kind,
                        costs=costs)

    def _start(self, cluster: int) -> tuple[int, float]:
        seg, n_cand, diff = self._choose_segment(cluster)
        self.segment = seg
        self.frame = -1                  # frame 0 is shown at this step
        self.state = cluster
        return n_cand, diff

    def _observe(self, t: float, code: int) -> Decision:
        """One observation at step t: update α/τ̄, γ from the displayed state, sample A_t."""
        s = self.model.n_clusters
        nxt = self.frame + 1
        length = int(self.library.lengths[self.segment])
        finished = nxt > length - 1
        tau = nxt / length
        prev = self.state
        forbid = (prev % s,) if finished else ()
        self._last = _LastObservation(self.filter.snapshot(), t, code, prev, tau)
        self.filter.observe(t, code, forbid)
        gamma = self.direct(prev, tau, code, forbid)
        alpha = self.filter.alpha
        k, p = self._sample(alpha * gamma, gamma)
        if k >= s:                       # c_i: the displayed motion continues
            self.state = k
            return self._decision(t, "continue", k, p, alpha, gamma, code, tau, None)
        extra = self._start(k)
        return self._decision(t, "end" if finished else "early", k, p, alpha, gamma, code, tau,
                              extra)

    def _late(self, t: float) -> Decision:
        """Late termination: redo the last observation with → c_i forbidden, restart now."""
        s = self.model.n_clusters
        last = self._last
        if last is None:                 # no observation yet: the prior, as for the first start
            alpha = self.filter.alpha
            gamma = np.full(2 * s, 1.0 / (2 * s))
            k, p = self._sample(np.where(np.arange(2 * s) < s, alpha, 0.0), gamma)
            extra = self._start(k)
            return self._decision(t, "late", k, p, alpha, gamma, -1, 1.0, extra)
        forbid = (last.prev_state % s,)
        self.filter.restore(last.snapshot)
        self.filter.observe(last.t, last.code, forbid)
        gamma = self.direct(last.prev_state, last.tau, last.code, forbid)
        alpha = self.filter.alpha
        starts = np.arange(2 * s) < s
        k, p = self._sample(np.where(starts, alpha * gamma, 0.0), np.where(starts, gamma, 0.0))
        extra = self._start(k)
        return self._decision(t, "late", k, p, alpha, gamma, last.code, last.tau, extra)

    def section_frame(self, name: str) -> tuple[int, int] | None:
        """(clip index, frame in the clip) the section stream ``name`` shows now, or None
        (no such stream, or before the first step)."""
        for sec in self.sections:
            if sec.name == name:
                return sec.clip_frame()
        return None

    def step(self, t: float, syllables: Sequence[Syllable] = ()) -> StepResult:
        """One control step at time t (s) with the syllables emitted since the last step."""
        t0 = time.perf_counter()
        codes = self.filter.stream.advance(t, syllables)
        shown = self._play(t, codes)
        target = self.target(self.segment, self.frame)
        if self.sections and target is not None:
            target = np.array(target, dtype=float)
            for sec in self.sections:
                sec.play(t, codes, target)
        dt = time.perf_counter() - t0
        self.n_steps += 1
        self.total_s += dt
        self.max_step_s = max(self.max_step_s, dt)
        return StepResult(t=t, segment=self.segment, frame=self.frame, target=target,
                          decision=shown)

    def _play(self, t: float, codes: Sequence[int]) -> Decision | None:
        """The stream's decisions at step t for the observation symbols ``codes``; advances
        the frame; returns the decision to show (None: the segment plays on)."""
        shown: Decision | None = None
        if self.segment < 0:
            s = self.model.n_clusters
            alpha = self.filter.alpha
            uniform = np.full(2 * s, 1.0 / (2 * s))
            k, p = self._sample(np.where(np.arange(2 * s) < s, alpha, 0.0), uniform)
            extra = self._start(k)
            shown = self._decision(t, "start", k, p, alpha, uniform, -1, 0.0, extra)
            self.decisions.append(shown)
        for code in codes:
            d = self._observe(t, code)
            self.decisions.append(d)
            if shown is None or not d.costs["continue"]:
                shown = d
        if self.frame + 1 > int(self.library.lengths[self.segment]) - 1:
            d = self._late(t)            # reached the end with no observation (or c_i sampled
            self.decisions.append(d)     # on the last frame): late termination
            shown = d
        self.frame += 1
        return shown


class _SectionStream:
    """One body section's stream: a one-stream synthesis over the section's segments, the
    joint columns it writes into the composed target and the blend of its switches."""

    def __init__(self, name: str, synth: Levine09Synthesis, source: Any, columns: np.ndarray,
                 blend_frames: int) -> None:
        self.name = name
        self.synth = synth
        self.source = source            # the SectionLibrary
        self.columns = np.asarray(columns, dtype=int)
        self.ramp = SwitchRamp(blend_frames)
        self.reset()

    def reset(self) -> None:
        self.synth.reset()
        self.ramp.reset()
        self._last: np.ndarray | None = None

    @property
    def decisions(self) -> list[Decision]:
        return self.synth.decisions

    def clip_frame(self) -> tuple[int, int] | None:
        s = self.synth
        if s.segment < 0:
            return None
        return int(self.source.clip[s.segment]), int(self.source.starts[s.segment] + s.frame)

    def play(self, t: float, codes: Sequence[int], target: np.ndarray) -> None:
        """Advance on the shared symbols and write the section's joints into ``target``."""
        s = self.synth
        d = s._play(t, codes)
        q = np.asarray(s.target(s.segment, s.frame), dtype=float)[self.columns]
        if d is not None and not d.costs.get("continue", 0.0):
            self.ramp.start(self._last)
        q = self.ramp(q)
        self._last = q.copy()
        target[self.columns] = q


def _section_streams(model: Levine09Model, library: ControlLibrary, motion_library: Any,
                     seed: int, pose_tolerance: float, blend_frames: int
                     ) -> list[_SectionStream]:
    """The head / lower-body streams of a model with sections, over the library's clips."""
    from gesture_sim.inference.levine09_sections import SECTIONS, SectionLibrary

    names = tuple(library.joint_names) or tuple(motion_library.joint_names)
    out = []
    for k, name in enumerate(n for n in SECTIONS if n in model.sections):
        sec = model.sections[name]
        src = SectionLibrary(motion_library, sec.clusters)
        sub_seed = int(np.random.SeedSequence([int(seed), k + 1]).generate_state(1)[0])
        synth = Levine09Synthesis(sec.model, src, seed=sub_seed,
                                  allowed=np.ones(src.n_segments, dtype=bool),
                                  clusters=src.labels, pose_tolerance=pose_tolerance)
        out.append(_SectionStream(name, synth, src, sec.clusters.columns(names), blend_frames))
    return out
