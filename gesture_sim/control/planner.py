"""Planned, not bent: for speech known ahead, choose the sequence of the library's real co-speech
segments and where each starts so that the clips' *own* strokes fall on the stressed syllables
and accents (issue 51).

The causal timing layer (:class:`~gesture_sim.control.synchrony.SyncPlayer`) hears an accent
after it was said and bends whatever clip plays to reach a stroke (playback up to 1.5 ×, holds,
amplitude × 0.6–1.5 × the extent normalisation): the coupling is bought with warps a viewer
sees. When the whole speech is known before it plays (a file, a text-to-speech voice with its
word timings, a transcript), :func:`plan_speech` instead searches, by dynamic programming over
segments × start times on the control grid (the motion-graph search of Kovar et al. 2002 and
Arikan & Forsyth 2002, adapted: the graph's nodes are the library's co-speech segments played
whole, the edges the MDP's successor costs, and the objective is the speech's targets rather
than a path), the plan minimising, per phrase:

* **strokes on targets**: for each hand-speed peak of a placed segment (its own stroke marks,
  :func:`~gesture_sim.control.synchrony.stroke_marks`, computed once), shifted by the learnt
  lead, ``w_stroke · (min((d / σ)², 1) − β)`` with d the distance to the nearest target (so a
  peak on a target earns ``−β w``, one far from any ``(1 − β) w``), less ``cover_reward · w``
  for each further target within ``±cover_s``; a peak in a pause pays the far cost;
* **join cost**: the MDP's successor cost ``D_sp(a, b)`` (pose and velocity at the switch) ×
  ``w_join``;
* **warp**: ``w_rate · ln(r)²`` for a playback rate r (a few rates inside the bounds the real
  take's stroke phases show) and ``w_hold`` per second of a hold between two segments (at most
  ``max_hold_s``, the real take's hold length);
* **repetition**: ``repeat_cost`` for a segment among the last ``repeat_window`` of the path;
* **the inference layer's belief as a prior**: ``w_prior · (b(t) · η_b − min_b' b(t) · η_b')``,
  the MDP's per-frame fit cost η under the belief at the segment's start (0: no prior);
* **energy**: ``−w_energy · z_b · e(t)``, the segment's mean hand speed (z over the pool)
  against the voice's energy e ∈ [−1, 1] (livelier speech, faster segments).

Pauses of at least ``rest_pause_s`` are rest (the hands retract, as the causal path does); a
phrase's plan may begin up to ``lead_in_s`` before its voice onset (a speaker prepares the first
stroke before the word). :class:`PlannedPlayer` plays the plan nearly unbent: each segment at
its planned rate, holds as planned, the amplitude only nudged by the voice within
``energy_gain``; requested emblems play through as in the causal path.

Everything here works on arrays (times in s on the stream clock, frames at the library's fps);
the speech analysis that finds the targets is :mod:`gesture_sim.audio.known`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

import numpy as np

from gesture_sim.contracts import Decision
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.control.synchrony import (
    SpeechCue,
    SyncPlayer,
    SyncSettings,
    SyncStep,
    stroke_marks,
)

#: The lead (s) of a stroke apex after its target, measured on the real take 2_scott_0_1_1
#: (``tools/stroke_timing.py``): median stressed-vowel centre → nearest hand-speed peak
#: −0.007 s (131 vowels with a peak within 0.3 s), accent → peak −0.027 s: the speaker's
#: apexes sit on the stressed vowel.
MEASURED_LEAD_S = 0.0
#: The real take's stroke rise times (dip → peak) have quartiles 0.23 / 0.27 / 0.37 s: a rate
#: change inside (0.73, 1.14) keeps a stroke within the speaker's own middle half of durations.
MEASURED_RATE_BOUNDS = (0.73, 1.14)
#: The real take's holds during speech (hands under 0.1 m/s): median 0.17 s, 90 % under 0.28 s.
MEASURED_HOLD_Q75_S = 0.22


@dataclass(frozen=True)
class PlanSettings:
    """Settings of the planner (costs are dimensionless, on the scale of the MDP's ``D_sp``).

    Attributes:
        lead_s: aimed time of a stroke apex after its target (s; :data:`MEASURED_LEAD_S`).
        sigma_s: distance (s) at which a stroke is as far as any from its target.
        hit_reward: β, the share of ``stroke_weight`` a peak on a target earns.
        stroke_weight, join_weight: as in the module docstring.
        rates: the playback rates a segment may be planned at (inside
            :data:`MEASURED_RATE_BOUNDS`); ``(1.0,)``: unbent.
        rate_weight: cost × ln(rate)².
        max_hold_s: longest hold between two segments (s; 0: none).
        hold_weight: cost per second of hold.
        repeat_cost, repeat_window: the repetition cost and how many items back it looks.
        prior_weight: weight of the belief prior (0: the plan ignores the inference layer).
        energy_weight: weight of the energy term.
        grid_s: the start-time grid (s); the library's frame period when None.
        rest_pause_s: a pause at least this long is rest.
        lead_in_s: a phrase's first segment may start this long before its voice onset.
        tail_s: after a phrase's last voiced frame the motion may run on this long before the
            retraction (the causal path's ``rest_after_s``).
        energy_gain: the player's amplitude nudge ``1 + energy_gain · e`` (0: none).
        accent_weight: the weight of an accent target against a stressed syllable's (1).
        peak_prominence: a stroke peak's prominence in the segment's hand speed (m/s; the
            timing layer's by default).
        cover_s, cover_reward: a peak with more than one target within ``±cover_s`` earns
            ``cover_reward · stroke_weight`` for each further one (up to two): one stroke can
            serve a cluster of stressed syllables, as the evaluation's ±0.2 s window counts.
        blend_s: the player's switch ramp (s; the causal path's 0.5 s). 0.2 s kept a few
            more of each clip's own strokes but raised the jerk (kinematic, take 0_3_3: 64
            against 53 m/s³, the discriminator 0.78 against 0.72; ``tools/planner_sweep.py``).
    """

    lead_s: float = MEASURED_LEAD_S
    sigma_s: float = 0.1
    hit_reward: float = 0.6
    stroke_weight: float = 8.0
    join_weight: float = 1.0
    rates: tuple[float, ...] = (0.88, 1.0, 1.13)
    rate_weight: float = 60.0
    max_hold_s: float = 0.2
    hold_weight: float = 10.0
    repeat_cost: float = 25.0
    repeat_window: int = 30
    prior_weight: float = 1.0
    energy_weight: float = 2.0
    grid_s: float | None = None
    rest_pause_s: float = 0.6
    lead_in_s: float = 0.3
    tail_s: float = 0.4
    energy_gain: float = 0.2
    accent_weight: float = 0.5
    peak_prominence: float = SyncSettings.peak_prominence
    cover_s: float = 0.2
    cover_reward: float = 0.6
    blend_s: float = 0.5

    def to_dict(self) -> dict:
        return asdict(self)

    def unbent(self) -> PlanSettings:
        """The same plan search without the nudge: rate 1, no holds, no amplitude change."""
        from dataclasses import replace

        return replace(self, rates=(1.0,), max_hold_s=0.0, energy_gain=0.0)


class PlanItem(NamedTuple):
    """One planned segment: ``segment`` played from its first frame at ``t_start`` (s) at
    ``rate`` (× its own speed) to its last frame; ``t_end`` (s) its last frame's time."""

    segment: int
    t_start: float
    rate: float
    t_end: float


@dataclass
class Plan:
    """A whole stream's plan.

    Attributes:
        items: the planned segments, in time order (a hold fills a gap between two items of
            one phrase: the earlier's last frame is held).
        phrases: (start, end) of each planned phrase (s): outside them the hands rest.
        targets: the target times (s) the plan aimed strokes at.
        strokes: the planned stroke apex times (s).
        cost: the plan's total cost; seconds: the planning wall time.
        fps: the library's frame rate (Hz): a playhead is in its frames.
    """

    items: list[PlanItem] = field(default_factory=list)
    phrases: list[tuple[float, float]] = field(default_factory=list)
    targets: np.ndarray = field(default_factory=lambda: np.zeros(0))
    strokes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cost: float = 0.0
    seconds: float = 0.0
    fps: float = 30.0

    def at(self, t: float) -> tuple[int, float]:
        """(index of the item playing at ``t``, its playhead in frames) — a hold after an item
        shows its last frame; (-1, 0.0) outside every phrase."""
        for lo, hi in self.phrases:
            if lo - 1e-9 <= t < hi:
                break
        else:
            return -1, 0.0
        starts = self._starts()
        i = int(np.searchsorted(starts, t + 1e-9)) - 1
        if i < 0:
            return -1, 0.0
        it = self.items[i]
        if not (lo - 1e-9 <= it.t_start < hi):
            return -1, 0.0
        return i, float(max(0.0, t - it.t_start) * it.rate * self.fps)

    def _starts(self) -> np.ndarray:
        s = getattr(self, "_s", None)
        if s is None or len(s) != len(self.items):
            s = np.array([it.t_start for it in self.items], dtype=float)
            self._s = s
        return s


@dataclass
class PlanLibrary:
    """What the planner reads of the library, computed once (co-speech segments only).

    Attributes:
        pool: (A,) library indices of the co-speech segments.
        lengths: (A,) frames. peaks: per segment its stroke peaks (frame offsets).
        join: (A, A) ``D_sp`` among them (inf on the diagonal).
        speed_z: (A,) each segment's mean hand speed, z over the pool.
        fps: frame rate (Hz).
        eta: (A, S) the MDP's per-frame fit cost under each hidden state (None: no prior).
    """

    pool: np.ndarray
    lengths: np.ndarray
    peaks: list[np.ndarray]
    join: np.ndarray
    speed_z: np.ndarray
    fps: float
    eta: np.ndarray | None = None

    @classmethod
    def from_control_library(cls, lib: ControlLibrary, eta: np.ndarray | None = None,
                             prominence: float = SyncSettings.peak_prominence) -> PlanLibrary:
        """From a :class:`ControlLibrary` (``eta``: (n, S) over all its segments, or None)."""
        pool = np.nonzero(lib.cospeech)[0]
        lengths = lib.lengths[pool].astype(np.int64)
        peaks, mean_v = [], []
        for i in pool:
            v = (np.asarray(lib.hand_speed(int(i)), float) if lib.hand_speed is not None
                 else np.zeros(int(lib.lengths[i])))
            peaks.append(stroke_marks(v, prominence).peaks.astype(float))
            mean_v.append(float(v.mean()) if v.size else 0.0)
        mv = np.asarray(mean_v)
        z = (mv - mv.mean()) / (mv.std() + 1e-9)
        join = np.array(lib.d_sp[np.ix_(pool, pool)], dtype=float)
        np.fill_diagonal(join, np.inf)
        e = None if eta is None else np.asarray(eta, dtype=float)[pool]
        return cls(pool, lengths, peaks, join, z, float(lib.fps), e)


@dataclass(frozen=True)
class Speech:
    """The speech known ahead, as the planner reads it (times in s).

    Attributes:
        duration_s: the stream's length.
        targets: (M,) times strokes should fall on (stressed-vowel centres, accents).
        weights: (M,) each target's weight (1: a stressed vowel or an accent).
        phrases: (start, end) of each stretch of speech, pauses shorter than the rest pause
            merged by the planner.
        belief: (K, S) the inference layer's belief at the control steps ``k / fps``, or None.
        energy: (K,) the voice's energy in [-1, 1] at the control steps, or None.
    """

    duration_s: float
    targets: np.ndarray
    phrases: list[tuple[float, float]]
    weights: np.ndarray | None = None
    belief: np.ndarray | None = None
    energy: np.ndarray | None = None


def merge_phrases(spans: list[tuple[float, float]], min_pause_s: float
                  ) -> list[tuple[float, float]]:
    """Speech spans (s) with the pauses shorter than ``min_pause_s`` closed."""
    out: list[list[float]] = []
    for a, b in sorted(spans):
        if out and a - out[-1][1] < min_pause_s:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([float(a), float(b)])
    return [(a, b) for a, b in out]


def _stroke_costs(offsets: np.ndarray, starts: np.ndarray, targets: np.ndarray,
                  weights: np.ndarray, voiced: list[tuple[float, float]], cfg: PlanSettings
                  ) -> np.ndarray:
    """(len(starts),) the stroke term of one segment whose peaks sit ``offsets`` (s) after
    each of its candidate ``starts`` (s)."""
    if offsets.size == 0:
        return np.zeros(len(starts))
    times = starts[:, None] + offsets[None, :] - cfg.lead_s        # (n, k) aimed targets
    far = np.full(times.shape, 1.0)
    if targets.size:
        j = np.clip(np.searchsorted(targets, times), 1, max(len(targets) - 1, 1))
        if len(targets) == 1:
            d = np.abs(times - targets[0])
            w = np.full(times.shape, weights[0])
        else:
            lo, hi = targets[j - 1], targets[j]
            dl, dh = np.abs(times - lo), np.abs(times - hi)
            pick = dl <= dh
            d = np.where(pick, dl, dh)
            w = np.where(pick, weights[j - 1], weights[j])
        far = np.minimum((d / cfg.sigma_s) ** 2, 1.0)
        far = np.where(far < 1.0, 1.0 - w * (1.0 - far), 1.0)     # a heavier target pulls more
    cost = far - cfg.hit_reward
    if targets.size and cfg.cover_reward > 0:
        # a peak whose window holds several targets serves each of them
        cw = np.concatenate([[0.0], np.cumsum(weights)])
        n_cov = (cw[np.searchsorted(targets, times + cfg.cover_s, side="right")]
                 - cw[np.searchsorted(targets, times - cfg.cover_s, side="left")])
        cost = cost - cfg.cover_reward * np.clip(n_cov - 1.0, 0.0, 2.0)
    peak_t = starts[:, None] + offsets[None, :]
    inside = np.zeros(times.shape, bool)
    for a, b in voiced:
        inside |= (peak_t >= a) & (peak_t <= b)
    cost = np.where(inside, cost, 1.0 - cfg.hit_reward)
    return cfg.stroke_weight * cost.sum(axis=1)


def plan_phrase(pl: PlanLibrary, t_on: float, t_off: float, speech: Speech,
                cfg: PlanSettings, voiced: list[tuple[float, float]] | None = None,
                history: tuple[int, ...] = ()) -> tuple[list[PlanItem], float]:
    """The cheapest sequence of segments covering one phrase ``[t_on, t_off]`` (s) (see the
    module docstring); ``voiced``: the speech spans inside it (peaks outside pay the far cost;
    default the whole phrase); ``history``: pool indices played before (repetition).

    Returns (items, cost)."""
    fps = pl.fps
    h = cfg.grid_s or 1.0 / fps
    t0 = t_on - cfg.lead_in_s
    n_need = int(np.ceil((t_off - t0) / h))
    n_lead = int(round(cfg.lead_in_s / h))
    a_n = len(pl.pool)
    rates = np.asarray(cfg.rates, dtype=float)
    n_gap = int(round(cfg.max_hold_s / h)) + 1
    dur = np.maximum(1, np.round((pl.lengths[:, None] - 1) / fps / rates[None, :] / h)
                     ).astype(int)                                   # (A, R) grid steps
    n_tot = n_need + int(dur.max()) + n_gap + 2
    grid = t0 + h * np.arange(n_tot)
    voiced = voiced if voiced is not None else [(t_on, t_off)]
    targets = np.asarray(speech.targets, dtype=float)
    weights = (np.ones(len(targets)) if speech.weights is None
               else np.asarray(speech.weights, dtype=float))
    order = np.argsort(targets)
    targets, weights = targets[order], weights[order]
    # the stroke term of every (segment, rate) at every grid start
    stroke = np.empty((a_n, len(rates), n_tot))
    for a in range(a_n):
        for r, rate in enumerate(rates):
            stroke[a, r] = _stroke_costs(pl.peaks[a] / fps / rate, grid, targets, weights,
                                         voiced, cfg)
    stroke_t = np.ascontiguousarray(np.transpose(stroke, (1, 2, 0)))   # (R, n_tot, A)
    warp = (cfg.rate_weight * np.log(rates) ** 2)[:, None] + \
        (cfg.hold_weight * h * np.arange(n_gap))[None, :]               # (R, G)
    extra = np.zeros((a_n, n_tot))                                       # prior and energy
    k_of = np.clip(np.round(np.maximum(grid, 0.0) * fps).astype(int), 0, None)
    if speech.belief is not None and pl.eta is not None and cfg.prior_weight > 0:
        b = np.asarray(speech.belief, dtype=float)
        fit = b[np.minimum(k_of, len(b) - 1)] @ pl.eta.T                  # (n_tot, A)
        extra += cfg.prior_weight * (fit - fit.min(axis=1, keepdims=True)).T
    if speech.energy is not None and cfg.energy_weight > 0:
        e = np.asarray(speech.energy, dtype=float)
        extra -= cfg.energy_weight * pl.speed_z[:, None] * e[np.minimum(k_of, len(e) - 1)][None]
    w = max(int(cfg.repeat_window), 1)
    value = np.full((n_tot + 1, a_n), np.inf)
    back = np.full((n_tot + 1, a_n, 4), -1, dtype=np.int64)   # (t before, prev, rate, gap)
    hist = np.full((n_tot + 1, a_n, w), -1, dtype=np.int64)   # the path's last segments
    cols = np.arange(a_n)
    n_r = len(rates)
    g_idx = np.arange(n_gap)

    def relax(t_from: int, prev: np.ndarray, m: np.ndarray) -> None:
        """Push the costs ``m`` (A,) of entering each segment after ``prev`` (A,) at grid
        ``t_from`` (+ each gap, at each rate) into the states their ends reach, keeping the
        cheapest arrival at each (end, segment). At one rate the gaps reach distinct ends, so
        each rate's pushes are one vectorised update."""
        n_g = min(n_gap, n_tot - t_from)
        gs = g_idx[:n_g]
        sl = slice(t_from, t_from + n_g)
        starts = t_from + gs                                               # (G,)
        base = m[None, :] + extra[:, sl].T                                 # (G, A)
        for r in range(n_r):
            c = base + stroke_t[r, sl] + warp[r, :n_g, None]               # (G, A)
            end = np.minimum(starts[:, None] + dur[None, :, r], n_tot)     # (G, A)
            ok = (c < value[end, cols]) & (starts[:, None] + dur[None, :, r] <= n_tot)
            if not ok.any():
                continue
            gi, a = np.nonzero(ok)
            e = end[gi, a]
            value[e, a] = c[gi, a]
            pv = prev[a]
            back[e, a, 0], back[e, a, 1], back[e, a, 2], back[e, a, 3] = t_from, pv, r, gs[gi]
            hist[e, a, 0] = a
            hist[e, a, 1:] = hist[t_from, pv, :w - 1]

    # from rest: the first segment starts anywhere in the lead-in (and up to the onset)
    rec = [a for a in history[-w:] if 0 <= a < a_n]
    rep0 = np.zeros(a_n)
    rep0[rec] = cfg.repeat_cost
    before = np.full(w - 1, -1, dtype=np.int64)      # the phrases before, most recent first
    recent = np.asarray(rec[::-1][:w - 1], dtype=np.int64)
    before[:len(recent)] = recent
    for s in range(0, n_lead + 1):
        for r in range(len(rates)):
            c = rep0 + stroke[:, r, s] + warp[r, 0] + extra[:, s]
            end = s + dur[:, r]
            ok = (end <= n_tot) & (c < value[np.minimum(end, n_tot), cols])
            a, e = cols[ok], end[ok]
            value[e, a] = c[ok]
            back[e, a] = np.stack([np.full(len(a), -1), np.full(len(a), s),
                                   np.full(len(a), r), np.zeros(len(a), int)], axis=1)
            hist[e, a, 0] = a
            hist[e, a, 1:] = before
    join = cfg.join_weight * pl.join
    for t in range(1, n_need):
        live = np.nonzero(np.isfinite(value[t]))[0]
        if live.size == 0:
            continue
        rep = np.zeros((live.size, a_n))
        hl = hist[t, live]                                                   # (L, W)
        rows = np.repeat(np.arange(live.size), w).reshape(live.size, w)
        okh = hl >= 0
        rep[rows[okh], hl[okh]] = cfg.repeat_cost
        total = value[t, live][:, None] + join[live] + rep                   # (L, A)
        best_i = np.argmin(total, axis=0)
        m = total[best_i, cols]                                              # (A,)
        relax(t, live[best_i], m)
    fin = value[n_need:]
    if not np.isfinite(fin).any():
        return [], np.inf
    te, a = np.unravel_index(int(np.argmin(fin)), fin.shape)
    te, a = int(te) + n_need, int(a)
    cost = float(value[te, a])
    items: list[PlanItem] = []
    while True:
        t_prev, prev, r, g = (int(x) for x in back[te, a])
        start = te - int(dur[a, r])   # (= the gap's end; from rest: back's prev is the start)
        items.append(PlanItem(int(pl.pool[a]), float(grid[start]), float(rates[r]),
                              float(grid[start] + (pl.lengths[a] - 1) / fps / rates[r])))
        if t_prev < 0:
            break
        te, a = t_prev, prev
    items.reverse()
    return items, cost


def plan_speech(pl: PlanLibrary, speech: Speech, cfg: PlanSettings | None = None) -> Plan:
    """The plan of a whole stream: each phrase (speech spans with the pauses shorter than
    ``rest_pause_s`` merged) planned by :func:`plan_phrase`, in order, the repetition cost
    reading the segments of the phrases before."""
    cfg = cfg or PlanSettings()
    t_wall = time.perf_counter()
    spans = [(float(a), float(b)) for a, b in speech.phrases if b > a]
    phrases = merge_phrases(spans, cfg.rest_pause_s)
    plan = Plan(targets=np.sort(np.asarray(speech.targets, dtype=float)), fps=pl.fps)
    index = {int(s): i for i, s in enumerate(pl.pool)}
    history: list[int] = []
    strokes: list[float] = []
    for on, off in phrases:
        voiced = [(max(a, on), min(b, off)) for a, b in spans if b > on and a < off]
        items, cost = plan_phrase(pl, on, off, speech, cfg, voiced, tuple(history))
        if not items:
            continue
        plan.items.extend(items)
        plan.cost += cost
        end = min(max(items[-1].t_end, off), off + cfg.tail_s, speech.duration_s + 1.0)
        plan.phrases.append((items[0].t_start, end))
        for it in items:
            a = index[it.segment]
            history.append(a)
            strokes.extend(it.t_start + pl.peaks[a] / pl.fps / it.rate)
    plan.strokes = np.asarray(strokes, dtype=float)
    plan.seconds = time.perf_counter() - t_wall
    return plan


class PlanChooser:
    """The plan's decisions, logged as a control layer logs them (``decisions``); label
    requests and style go to ``controller`` (the emblems are served as on the causal path)."""

    def __init__(self, controller) -> None:
        self.controller = controller
        self.decisions: list[Decision] = []

    @property
    def label(self) -> int:
        return int(getattr(self.controller, "label", 0) or 0)


class PlannedPlayer(SyncPlayer):
    """Plays a :class:`Plan` (the timing layer's machinery — pose, switch ramp, the real-speed
    bounds, rest and breathing — without its causal bending).

    Each control step shows the planned item's frame at its planned rate (a hold shows the
    previous item's last frame); a change of item starts the switch ramp; outside the plan's
    phrases the hands retract to rest and breathe. The amplitude is the clip's own, nudged by
    the voice's energy within ``1 ± energy_gain`` (the real take's apex speeds vary with a
    coefficient of variation of 0.43). A label request (``chooser.label``) plays the
    controller's emblem through at its own pace, then the plan resumes.

    Args:
        library: the control library; controller: the control layer that serves labels
            (``decide_start``); plan: the plan (replaceable: :meth:`set_plan`);
        energy_gain: as :attr:`PlanSettings.energy_gain`; settings: the timing layer's other
            settings (rest, ramp, speed bounds).
    """

    def __init__(self, library: ControlLibrary, controller, plan: Plan | None = None,
                 energy_gain: float = 0.2, settings: SyncSettings | None = None,
                 path=None) -> None:
        from dataclasses import replace

        base = settings or SyncSettings()
        base = replace(base, energy_gain=float(energy_gain), gain_range=(1.0, 1.0),
                       energy_rate=0.0)
        self.plan_chooser = PlanChooser(controller)
        super().__init__(library, controller, base, path=path)
        self.plan = plan or Plan()

    def set_plan(self, plan: Plan) -> None:
        self.plan = plan

    def reset(self) -> None:
        super().reset()
        self._item = -1
        self._emblem = False
        self.plan_chooser.decisions = []

    def step(self, t: float, belief: np.ndarray, cue: SpeechCue) -> SyncStep:
        """One control step at ``t`` (s): the plan's frame (``cue`` gives the energy and the
        label requests; its accents are only logged)."""
        self.log.accents.extend(float(a) for a in cue.accents)
        gain = self._gain(float(np.clip(cue.energy, -1.0, 1.0)))
        decision: Decision | None = None
        if self.chooser.label and not self._emblem:
            decision = self.chooser.decide_start(belief, t)
            self._enter(decision, blend=True)
            self._close_rest(t)
            self._emblem, self.mode = True, "play"
        if self._emblem:
            a = self.segment
            last = int(self.library.lengths[a]) - 1
            stroke = self._cross(t, a, self.p, self.p + 1.0)
            self.p = min(self.p + 1.0, float(last))
            if self.p >= last:
                self._emblem, self._item = False, -1       # the plan resumes next step
            return self._show(t, a, gain, decision, "play", stroke)
        i, p = self.plan.at(t)
        if i < 0:
            if self.mode not in ("rest", "to_rest"):
                self.mode = "to_rest"
                self._rest_from, self._rest_k = self._last.copy(), 0
                self._rest_v = self._last_v.copy()
                self.log.rest_spans.append([t, float("inf")])
            self._item = -1
            return self._rest_step(t, gain)
        it = self.plan.items[i]
        last = float(self.library.lengths[it.segment] - 1)
        mode = "hold" if p > last else "play"
        p = min(p, last)
        stroke = False
        if i != self._item:
            seg = int(it.segment)
            decision = Decision(t=t, segment_id=seg, frame=int(self.library.starts[seg]),
                                kind="start" if self.mode in ("rest", "to_rest") else "end",
                                costs={"continue": 0.0, "rate": it.rate})
            self.plan_chooser.decisions.append(decision)
            self._close_rest(t)
            successor = (self.segment >= 0 and int(self.library.successors[self.segment]) == seg
                         and self.p >= int(self.library.lengths[self.segment]) - 2)
            self.segment, self.p = seg, 0.0
            if not successor:
                self._start_blend()
            self._item = i
        else:
            stroke = self._cross(t, it.segment, self.p, p)
        self.p = p
        return self._show(t, it.segment, gain, decision, mode, stroke)

    def _cross(self, t: float, a: int, p0: float, p1: float) -> bool:
        pk = self.marks(a).peaks
        hit = bool(np.any((pk > p0 + 1e-9) & (pk <= p1 + 1e-9)))
        if hit:
            self.log.strokes.append(t)
        return hit

    def _show(self, t: float, a: int, gain: float, decision, mode: str,
              stroke: bool) -> SyncStep:
        self.mode = "stroke" if stroke else mode
        q = self._limit(self._ramp(self._pose(a, self.p, gain)))
        self._last_v = q - self._last
        self._last = q
        return SyncStep(t=t, segment=a, frame=int(np.floor(self.p)), target=q,
                        decision=decision, mode=self.mode, stroke=stroke, rate=1.0, gain=gain)
