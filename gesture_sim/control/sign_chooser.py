"""Realisation by gestural sign (Chiu 2014 §5.2; digest §5.3) behind the timing layer.

:class:`SignChooser` is a :class:`~gesture_sim.control.protocols.SegmentChooser`: the timing
layer (:class:`~gesture_sim.control.synchrony.SyncPlayer`) decides *when* (strokes on accents,
holds, rest in silence), this chooser decides *which* segment from the belief over the 14 signs
that the sign filter (:class:`~gesture_sim.inference.sign_model.SignFilter`) gives at each step:

* **The sign for now** is the belief's argmax.
* **At an interruption point** of the playing segment it continues while the predicted sign is
  the playing segment's sign, and switches when the sign changed (or when the timing layer
  prefers a switch: no stroke left with an accent pending). At a segment's end it always
  chooses.
* **The choice** (the thesis's clip choice): among the segments carrying the sign, the one
  whose duration (s) is closest to the requested one; segments within ``tie_s`` of the closest
  are tied and the smoothest join wins — the library's own transition costs from the playing
  frame (``d_sp`` at a segment's end, ``d_in`` at interruption frame k: the joint-distance
  costs of :mod:`gesture_sim.control.costs`), the playing and the last ``recent`` chosen
  segments left out when another is tied. The requested duration is the predicted sign run
  still to come, ``frame_s / (1 - P(stay))`` from the chain's self-transition, capped at the
  median co-speech segment length: the library's segments are gesture phases (0.3–1.5 s),
  not the thesis's whole gestures, so a run of one sign is realised by several of its segments.
* **Signs the co-speech segments lack** fall back to emblem segments carrying the sign
  (``emblem_fallback``), else to Beats, else to any co-speech segment.

Every choice is kept in ``choices`` as ``(t, predicted sign, chosen segment, its sign)``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from gesture_sim.contracts import Decision
from gesture_sim.control.inputs import ControlLibrary

#: The 14 sign names (the order of :data:`gesture_sim.motion.signs.SIGNS`; the control stage does
#: not import the inference or motion stages).
SIGNS: tuple[str, ...] = (
    "Rest", "Palm-face-up", "Head-nod", "Wipe", "Whole", "Frame", "Dismiss", "Block", "Shrug",
    "More-or-less", "Process", "Deictic.Other", "Deictic.Self", "Beats")


class SignChooser:
    """Segment choice by predicted sign (module docstring).

    Args:
        library: the control library.
        segment_signs: (n_segments,) the sign of every segment (names of :data:`SIGNS`).
        stay: (14,) the sign chain's self-transition probabilities per frame (for the
            requested duration), or None (the default segment length).
        frame_s: the sign model's frame length (s).
        seed: breaks exact ties.
        tie_s: durations within this of the closest one are tied (s).
        emblem_fallback: a sign no co-speech segment has may use an emblem segment with it.
        recent: the last this many chosen segments are left out of a tie when another
            candidate is tied (no loop over a few segments).
    """

    def __init__(self, library: ControlLibrary, segment_signs: Sequence[str],
                 stay: np.ndarray | None = None, frame_s: float = 1.0, seed: int = 0,
                 tie_s: float = 0.3, emblem_fallback: bool = True, recent: int = 4) -> None:
        n = library.n_segments
        if len(segment_signs) != n:
            raise ValueError(f"{len(segment_signs)} segment signs for {n} segments")
        self.library = library
        self.seed = seed
        self.tie_s = float(tie_s)
        self.recent = int(recent)
        self.frame_s = float(frame_s)
        self.stay = None if stay is None else np.clip(np.asarray(stay, float), 0.0, 0.999)
        self.segment_signs = [str(s) for s in segment_signs]
        self.tags: tuple[str, ...] = ()
        self.durations = np.asarray(library.lengths, dtype=float) / float(library.fps)
        cos = np.asarray(library.cospeech, dtype=bool)
        adaptor = (np.zeros(n, bool) if library.adaptor is None
                   else np.asarray(library.adaptor, dtype=bool))
        idx = {s: i for i, s in enumerate(SIGNS)}
        sign_ix = np.array([idx.get(s, idx["Beats"]) for s in self.segment_signs])
        self.sign_of_segment = sign_ix
        self.default_s = float(np.median(self.durations[cos]))
        #: per sign, the segments that realise it and where they come from
        self.pools: list[np.ndarray] = []
        self.pool_source: list[str] = []
        beats = np.nonzero(cos & (sign_ix == idx["Beats"]))[0]
        for i in range(len(SIGNS)):
            own = np.nonzero(cos & (sign_ix == i))[0]
            emb = np.nonzero(~cos & ~adaptor & (sign_ix == i))[0]
            if len(own):
                self.pools.append(own)
                self.pool_source.append("co-speech")
            elif emblem_fallback and len(emb):
                self.pools.append(emb)
                self.pool_source.append("emblem")
            elif len(beats):
                self.pools.append(beats)
                self.pool_source.append("Beats (fallback)")
            else:
                self.pools.append(np.nonzero(cos)[0])
                self.pool_source.append("co-speech (fallback)")
        self._pool_sets = [set(p.tolist()) for p in self.pools]
        self._points = library.decision_points()
        self.n_last = library.n_interrupts
        self.reset()

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.label = 0
        self.decisions: list[Decision] = []
        self.choices: list[tuple[float, str, int, str]] = []
        self._recent: deque[int] = deque(maxlen=self.recent)

    def set_style(self, dial: float) -> None:
        """No style dial: the sign decides."""

    def request_label(self, label: str, t: float | None = None) -> bool:
        return False

    def decision_point(self, segment: int, frame: int) -> int:
        return int(self._points[segment].get(int(frame), -1))

    def decide_start(self, belief: np.ndarray, t: float) -> Decision:
        return self._choose(belief, t, "start", -1, -1)

    def decide_at(self, belief: np.ndarray, a: int, k: int, t: float,
                  prefer_switch: bool = False) -> Decision:
        sign = self.sign(belief)
        end = k >= self.n_last
        same = int(self.sign_of_segment[a]) == sign or a in self._pool_sets[sign]
        if not end and not prefer_switch and same:
            return Decision(t=t, segment_id=a, frame=int(self.library.starts[a]),
                            kind="interrupt", costs={"continue": 1.0, "sign": float(sign)})
        return self._choose(belief, t, "end" if end else "interrupt", a, k)

    # ------------------------------------------------------------------ choice
    @staticmethod
    def sign(belief: np.ndarray) -> int:
        """The predicted sign index of a belief (14,)."""
        b = np.asarray(belief, dtype=float)
        return int(np.argmax(b)) if b.shape == (len(SIGNS),) else len(SIGNS) - 1

    def requested_s(self, sign: int) -> float:
        """The duration (s) asked of the next segment of ``sign``."""
        if self.stay is None:
            return self.default_s
        run = self.frame_s / (1.0 - float(self.stay[sign]))
        return float(min(run, self.default_s))

    def join_costs(self, a: int, k: int, pool: np.ndarray) -> np.ndarray:
        """(len(pool),) transition cost into each candidate from segment a at decision point
        k (its end when k is the last; 0 from rest)."""
        if a < 0:
            return np.zeros(len(pool))
        if k >= self.n_last:
            c = np.asarray(self.library.d_sp, dtype=float)[a, pool]
        else:
            c = np.asarray(self.library.d_in, dtype=float)[a, k, pool]
        return np.where(np.isfinite(c), c, 1e9)

    def _choose(self, belief: np.ndarray, t: float, kind: str, a: int, k: int) -> Decision:
        sign = self.sign(belief)
        pool = self.pools[sign]
        want = self.requested_s(sign)
        err = np.abs(self.durations[pool] - want)
        tied = err <= err.min() + self.tie_s
        recent = {*self._recent, a}
        fresh = tied & ~np.isin(pool, list(recent))
        if fresh.any():
            tied = fresh
        cand = pool[tied]
        join = self.join_costs(a, k, cand)
        best = np.flatnonzero(join <= join.min() + 1e-9)
        pick = int(best[self.rng.integers(len(best))]) if len(best) > 1 else int(best[0])
        seg = int(cand[pick])
        d = Decision(t=t, segment_id=seg, frame=int(self.library.starts[seg]), kind=kind,
                     costs={"continue": 0.0, "sign": float(sign),
                            "duration_error_s": float(abs(self.durations[seg] - want)),
                            "join": float(join[pick])})
        self.decisions.append(d)
        self.choices.append((float(t), SIGNS[sign], seg, self.segment_signs[seg]))
        self._recent.append(seg)
        return d
