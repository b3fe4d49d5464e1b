"""The online gesture controller (Gesture Controllers §7.2): one call per control step.

At every step the controller advances the playing segment by one frame. When the frame it has
just shown is a decision point (an interruption frame or the last frame), it first scores every
candidate e at (a, k) by its belief-weighted value

    Σ_m d_m Σ_i b(i) V_m(e, a, k, i)   (+ the novelty term ``repeat_cost``, when set)

and takes the lowest (``temperature`` 0, the paper's rule and this class's default) or draws one
with probability ∝ exp(-(value - best) / temperature) (adapted; the pipeline's default is a
temperature of 2 cost units and a novelty term, :mod:`gesture_sim.methods`)
(candidates: continue — at interruption frames only —, frame 0 of any other segment, and, while a
semantic label is pending, a mid-clip entry into a matching segment), using the newest belief
``b`` and the style dial's tone weights ``d``. Each decision is recorded as a
:class:`gesture_sim.contracts.Decision` with its cost terms:

* ``fit``: ``Σ_i b(i) η_{a'}(i)``, the expected kinematic mismatch per frame of the chosen segment;
* ``smoothness``: the weighted switch cost S (0 for continue);
* ``total``: the chosen entry's belief-weighted value (fit now and later, smoothness, discounted);
* ``runner_up``: the second-best value (``inf`` when there was one candidate);
* ``continue``: 1.0 when the segment simply continued, else 0.0;
* ``label_delay``: for a decision that satisfied a semantic label, seconds since it was requested.

The emitted target for a step is the chosen clip frame's joint angles (``segment_qpos``). One
decision is a gather of the surviving candidates' value rows and a small matrix-vector product
(a few µs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gesture_sim.contracts import Decision
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.control.policy import KIND_CONTINUE, KIND_SEMANTIC, Policy
from gesture_sim.control.style import dial_weights
from gesture_sim.errors import GestureSimError


@dataclass
class StepResult:
    """What one control step produced.

    Attributes:
        t: stream time of the step (s).
        segment: playing segment index; frame: its frame offset (from the segment start).
        target: (n_joints,) joint-angle target (rad/m), or ``None`` if the library has no poses.
        decision: the decision taken at this step, if any.
    """

    t: float
    segment: int
    frame: int
    target: np.ndarray | None
    decision: Decision | None


class GestureController:
    """Plays library segments chosen online by a trained :class:`Policy`.

    Args:
        policy: the trained policy (checked against ``library``'s fingerprint).
        library: the library the policy was trained for.
        style: the style dial in [-1, 1] (calm ↔ energetic); ignored with one tone.
        t0: stream time of the first step (s).
        temperature: 0 (default) takes the paper's argmin. A positive value (cost units) picks a
            candidate at random with probability ∝ exp(-(value - best) / temperature) — a
            seeded, near-optimal stochastic choice in the spirit of Okwechime's stochastic
            subsequence selection, which trades a little expected cost for variety (measured in
            docs/history.md). Candidates a semantic label calls for are never traded away: their
            values are lower than any other's by the label cost.
        seed: seeds that random choice (the controller is deterministic for a seed).
        repeat_cost: a novelty term (cost units, the values' own; 0, the default, leaves every
            decision as it was, bit for bit). Without a pending label, a candidate that enters
            a segment (a switch, or a start) pays ``repeat_cost * exp(-age / repeat_tau_s)``,
            where ``age`` is the stream time (s) since that segment was last chosen or last
            seen playing at a decision point (never: no cost); continuing pays nothing. Real
            speakers do not replay the same gesture back to back, and the MDP alone, whose
            state is the playing segment only, cannot know what it played a few seconds ago.
            Measured by ``tools/sweep.py novelty`` (issue 31).
        repeat_tau_s: the decay time (s) of that cost; must be > 0.
        sample_state: False (default): decide on the belief's expected values, as the paper
            does. True: without a pending label, *whether* to leave the playing segment is
            still decided on the expected values, but *which* segment to enter (at a switch,
            and at a start) is decided on the values of one hidden state ``i ~ b`` drawn for
            it (posterior sampling; seeded, from the same generator as the softmin). The
            expected cost under a diffuse belief is lowest for segments between the likely
            states' kinematics, so the argmin keeps choosing those; a drawn state chooses
            segments near *its* kinematics, each state as often as the belief holds it. The
            recorded ``fit`` is still the expected one under ``b``; ``total`` and ``runner_up``
            are the drawn state's.
    """

    def __init__(self, policy: Policy, library: ControlLibrary, style: float = 0.0,
                 t0: float = 0.0, temperature: float = 0.0, seed: int = 0,
                 repeat_cost: float = 0.0, repeat_tau_s: float = 10.0,
                 sample_state: bool = False) -> None:
        if temperature < 0:
            raise GestureSimError(f"temperature must be >= 0, got {temperature}")
        if repeat_cost < 0:
            raise GestureSimError(f"repeat_cost must be >= 0, got {repeat_cost}")
        if not repeat_tau_s > 0:
            raise GestureSimError(f"repeat_tau_s must be > 0, got {repeat_tau_s}")
        self.temperature = float(temperature)
        self.repeat_cost = float(repeat_cost)
        self.repeat_tau_s = float(repeat_tau_s)
        self.sample_state = bool(sample_state)
        self.seed = seed
        policy.check(library)
        self.policy = policy
        self.library = library
        self.dt = 1.0 / library.fps
        self.t0 = t0
        n = library.n_segments
        self._points = [np.full(int(length), -1, dtype=np.int64) for length in library.lengths]
        for a in range(n):
            for k in range(policy.n_points):
                f = int(policy.frames[a, k])
                if policy.entries(0, a, k).stop > policy.entries(0, a, k).start:
                    self._points[a][f] = k
        self._qpos_cache: dict[int, np.ndarray] = {}
        self.set_style(style)
        self.reset()

    # ------------------------------------------------------------------ settings
    def set_style(self, dial: float) -> None:
        """Set the style dial in [-1, 1] (blend weights of the tones)."""
        self.style = float(dial)
        self._tone_w = dial_weights(self.style, self.policy.tones)
        self._eta_blend = np.tensordot(self._tone_w, self.policy.eta, axes=1)   # (n, S)
        self._start_blend = np.tensordot(self._tone_w, self.policy.start_values, axes=1)

    def request_label(self, label: str, t: float | None = None) -> bool:
        """Ask for a semantic gesture (e.g. ``"wave"``); False if the policy has no such label."""
        li = self.policy.label_index(label)
        if li <= 0:
            return False
        self.label = li
        self._label_t = self._now() if t is None else t
        return True

    def reset(self) -> None:
        """Forget the playing segment, pending label and decision log."""
        self.segment = -1
        self.frame = -1
        self.label = 0
        self._label_t = 0.0
        self.steps = 0
        self.decisions: list[Decision] = []
        self._rng = np.random.default_rng(self.seed)
        self._chosen = -1  # the segment of the last decision (a start never replays it)
        # stream time (s) each segment was last chosen or seen playing (for ``repeat_cost``)
        self._last_played = np.full(self.library.n_segments, -np.inf)

    # ------------------------------------------------------------------ stepping
    def _now(self) -> float:
        return self.t0 + self.steps * self.dt

    def _belief(self, belief: np.ndarray) -> np.ndarray:
        b = np.asarray(belief, dtype=float)
        if b.shape != (self.policy.n_states,):
            raise GestureSimError(
                f"belief has shape {b.shape}, the policy expects ({self.policy.n_states},)")
        total = b.sum()
        return b / total if total > 0 else np.full(len(b), 1.0 / len(b))

    def decision_point(self, segment: int, frame: int) -> int:
        """The decision point index at a frame of a segment, or -1."""
        return int(self._points[segment][frame])

    def target(self, segment: int, frame: int) -> np.ndarray | None:
        """(n_joints,) joint-angle target of a library frame, or None without poses."""
        if self.library.segment_qpos is None:
            return None
        q = self._qpos_cache.get(segment)
        if q is None:
            q = np.asarray(self.library.segment_qpos(segment))
            self._qpos_cache[segment] = q
        return q[frame]

    def step(self, belief: np.ndarray, t: float | None = None) -> StepResult:
        """Advance one control step with the current belief (S,); returns the frame to show."""
        t = self._now() if t is None else t
        b = self._belief(belief)
        decision = None
        if self.segment < 0:
            decision = self.decide_start(b, t)
            self.segment, self.frame = decision.segment_id, 0
        else:
            k = self.decision_point(self.segment, self.frame)
            if k >= 0:
                decision = self.decide_at(b, self.segment, k, t)
                self.segment = decision.segment_id
                self.frame = decision.frame - int(self.library.starts[decision.segment_id])
            else:
                self.frame += 1
        if decision is not None:
            self.decisions.append(decision)
        self.steps += 1
        return StepResult(t=t, segment=self.segment, frame=self.frame,
                          target=self.target(self.segment, self.frame), decision=decision)

    def _choose(self, scores: np.ndarray) -> int:
        """Index of the chosen candidate: argmin, or a softmin draw with a temperature."""
        best = int(np.argmin(scores))
        if self.temperature <= 0.0 or len(scores) < 2:
            return best
        z = (scores[best] - scores) / self.temperature
        p = np.where(np.isfinite(scores), np.exp(np.maximum(z, -50.0)), 0.0)
        return int(self._rng.choice(len(scores), p=p / p.sum()))

    def repeat_penalty(self, segments: np.ndarray, t: float) -> np.ndarray:
        """The novelty term ``repeat_cost * exp(-age / repeat_tau_s)`` of entering each of
        ``segments`` at stream time ``t`` (s) (zeros where never played, or with no cost)."""
        segments = np.asarray(segments, dtype=np.int64)
        if self.repeat_cost <= 0.0:
            return np.zeros(len(segments))
        age = t - self._last_played[segments]
        return self.repeat_cost * np.exp(-np.maximum(age, 0.0) / self.repeat_tau_s)

    def _decision_belief(self, b: np.ndarray) -> np.ndarray:
        """The belief a decision weighs its values with: ``b``, or with ``sample_state`` a
        one-hot draw of a hidden state from it (never while a label is pending)."""
        if not self.sample_state or self.label:
            return b
        out = np.zeros(len(b))
        out[int(self._rng.choice(len(b), p=b))] = 1.0
        return out

    def decide_start(self, belief: np.ndarray, t: float) -> Decision:
        """The first segment of a stream (or after rest): the lowest start value among the
        co-speech segments, or among the segments a pending label asks for (which it
        satisfies). A start after rest does not replay the segment played just before it (the
        start values have no smoothness term to keep it from doing so), unless it is the only
        one allowed. Does not change the playing segment."""
        b = self._belief(belief)
        scores = self._start_blend @ self._decision_belief(b)
        allowed = np.array(self.library.cospeech, dtype=bool)
        kind = "start"
        if self.label:
            tagged = self.library.segments_with_tag(self.policy.labels[self.label])
            if len(tagged):
                allowed = np.zeros(len(scores), bool)
                allowed[tagged] = True
                kind = "label"
        if 0 <= self._chosen < len(allowed) and allowed.sum() > 1:
            allowed[self._chosen] = False
        scores = np.where(allowed, scores, np.inf)
        penalty = None
        if self.repeat_cost > 0.0 and kind == "start":
            penalty = self.repeat_penalty(np.arange(len(scores)), t)
            scores = scores + penalty
        a = self._choose(scores)
        self._chosen = a
        self._last_played[a] = t
        finite = np.sort(scores[np.isfinite(scores)])
        costs = {"fit": float(self._eta_blend[a] @ b), "smoothness": 0.0,
                 "total": float(scores[a]),
                 "runner_up": float(finite[1]) if len(finite) > 1 else float("inf"),
                 "continue": 0.0}
        if penalty is not None:
            costs["repeat"] = float(penalty[a])
        if kind == "label":
            costs["label_delay"] = float(t - self._label_t)
            self.label = 0
        return Decision(t=t, segment_id=a, frame=int(self.library.starts[a]), kind=kind,
                        costs=costs)

    def decide_at(self, belief: np.ndarray, a: int, k: int, t: float,
                  prefer_switch: bool = False) -> Decision:
        """The decision at decision point ``k`` of segment ``a`` (continue, switch, or a
        semantic entry while a label is pending). ``Decision.frame`` is the clip frame to play
        next; a pending label it satisfies is cleared. Does not change the playing segment.
        ``prefer_switch``: leave the segment here if any other candidate exists (the timing
        layer's early termination)."""
        return self._decide(self._belief(belief), a, k, t, prefer_switch)

    def _decide(self, b: np.ndarray, a: int, k: int, t: float,
                prefer_switch: bool = False) -> Decision:
        pol = self.policy
        weights = np.outer(self._tone_w, b).ravel()              # kron(tone_w, b)
        label = self.label
        sl, scores = pol.scores(weights, label, a, k)
        if len(scores) == 0:                        # label state without entries: fall back
            label = 0
            sl, scores = pol.scores(weights, 0, a, k)
        cont = pol.row_kind[pol.cand[sl]] == KIND_CONTINUE
        if prefer_switch and not self.label:
            if cont.any() and not cont.all():
                scores = np.where(cont, np.inf, scores)
        self._last_played[a] = t
        penalty = None
        if self.repeat_cost > 0.0 and not self.label:
            rows = pol.cand[sl]
            penalty = np.where(cont, 0.0, self.repeat_penalty(pol.row_seg[rows], t))
            scores = scores + penalty
        j = self._choose(scores)
        if self.sample_state and not self.label and not cont[j]:
            # leave, as decided on the expected values; which segment: on a drawn state's
            drawn = np.outer(self._tone_w, self._decision_belief(b)).ravel()
            _, scores = pol.scores(drawn, label, a, k)
            scores = np.where(cont, np.inf, scores if penalty is None else scores + penalty)
            j = self._choose(scores)
        finite = np.sort(scores[np.isfinite(scores)])
        runner = float(finite[1]) if len(finite) > 1 else float("inf")
        e = sl.start + j
        row = int(pol.cand[e])
        kind_e = int(pol.row_kind[row])
        seg, frame = int(pol.row_seg[row]), int(pol.row_frame[row])
        self._chosen = seg
        self._last_played[seg] = t
        costs = {"fit": float(self._eta_blend[seg] @ b), "smoothness": float(pol.smooth[e]),
                 "total": float(scores[j]), "runner_up": runner,
                 "continue": float(kind_e == KIND_CONTINUE)}
        if penalty is not None:
            costs["repeat"] = float(penalty[j])
        if k == pol.n_points - 1:
            why = "end"
        else:
            why = "interrupt"
        if self.label and pol.row_resets[row]:
            costs["label_delay"] = float(t - self._label_t)
            why = "label" if kind_e == KIND_SEMANTIC or kind_e == KIND_CONTINUE else why
            self.label = 0
        return Decision(t=t, segment_id=seg, frame=int(self.library.starts[seg]) + frame,
                        kind=why, costs=costs)


@dataclass
class OnlineRun:
    """The result of :func:`run_online`: per step the segment and frame offset shown."""

    segments: np.ndarray
    frames: np.ndarray
    decisions: list[Decision]


def run_online(controller: GestureController, beliefs: np.ndarray,
               labels: dict[int, str] | None = None,
               style: np.ndarray | None = None) -> OnlineRun:
    """Drive a controller with a (T, S) belief sequence; ``labels`` maps step -> label request,
    ``style`` an optional (T,) dial per step. Returns the frames shown."""
    beliefs = np.asarray(beliefs, dtype=float)
    segs = np.empty(len(beliefs), dtype=np.int64)
    frames = np.empty(len(beliefs), dtype=np.int64)
    labels = labels or {}
    for t, b in enumerate(beliefs):
        if style is not None:
            controller.set_style(float(style[t]))
        if t in labels:
            controller.request_label(labels[t])
        r = controller.step(b)
        segs[t], frames[t] = r.segment, r.frame
    return OnlineRun(segments=segs, frames=frames, decisions=list(controller.decisions))
