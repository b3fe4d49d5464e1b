"""Figures computed from a run's log: the segments that played, how they were left, how the
choice went (co-speech only, replays of the source order), the decision log and latencies.

Pure functions of a :class:`~gesture_sim.feed.RunResult` (duck-typed: ``run.pipeline.log``,
``.dt``, ``.control_library``, ``.segment_name``), used by the render summary, the timeline figure,
the evaluation and the benchmarks.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np


@dataclass
class SegmentSpan:
    """One played piece of a segment.

    Attributes:
        t_start, t_end: when it played (s).
        segment_id: library segment index.
        name: short label (clip name or tag).
        interrupted: whether it was left at an interruption frame (not at its end).
        kind: what started it (``"start"``, ``"end"``, ``"interrupt"``, ``"label"``).
    """

    t_start: float
    t_end: float
    segment_id: int
    name: str = ""
    interrupted: bool = False
    kind: str = "end"



def segment_spans(run: Any) -> list[SegmentSpan]:
    """The played segments as spans: a new span where the segment changes or restarts."""
    log = run.pipeline.log
    spans: list[SegmentSpan] = []
    if not log.step_times:
        return spans
    dt = run.pipeline.dt
    kinds = {round(d.t / dt): d.kind for d in log.decisions
             if not d.costs.get("continue", 0.0)}
    start = 0
    n = len(log.step_times)
    for i in range(1, n + 1):
        end_here = (i == n or log.segments[i] != log.segments[i - 1]
                    or log.frames[i] < log.frames[i - 1])
        if not end_here:
            continue
        seg = int(log.segments[start])
        if seg >= 0:        # -1: at rest, no segment plays
            # left early: the decision that followed was an interruption (or a semantic entry);
            # a segment the timing layer left for rest counts as played out
            nxt = kinds.get(round(log.step_times[i] / dt), "end") if i < n else "end"
            spans.append(SegmentSpan(
                t_start=log.step_times[start], t_end=log.step_times[i - 1] + dt,
                segment_id=seg, name=run.pipeline.segment_name(seg),
                interrupted=(i < n and int(log.segments[i]) >= 0
                             and nxt in ("interrupt", "early", "label")),
                kind=kinds.get(round(log.step_times[start] / dt), "end"),
            ))
        start = i
    return spans


def decision_log(run: Any) -> list[dict[str, Any]]:
    """The controller's decisions as JSON-ready dicts (with the segment's clip name)."""
    out = []
    for d in run.pipeline.log.decisions:
        row = asdict(d)
        row["clip"] = run.pipeline.segment_name(d.segment_id)
        row["costs"] = {k: (None if not np.isfinite(v) else float(v)) for k, v in d.costs.items()}
        out.append(row)
    return out


def selection_summary(run: Any) -> dict[str, float]:
    """Shares of how segments were left: played to completion vs interrupted; repeats."""
    spans = segment_spans(run)
    if not spans:
        return {"segments_played": 0}
    finished = spans[:-1]   # the last one is cut by the end of the audio
    interrupted = sum(s.interrupted for s in finished)
    repeats = sum(a.segment_id == b.segment_id for a, b in zip(spans[:-1], spans[1:],
                                                               strict=True))
    return {
        "segments_played": len(spans),
        "distinct_segments": len({s.segment_id for s in spans}),
        "interrupted_share": interrupted / max(len(finished), 1),
        "completed_share": 1.0 - interrupted / max(len(finished), 1),
        "back_to_back_repeats": repeats,
        "mean_segment_s": float(np.mean([s.t_end - s.t_start for s in spans])),
        **choice_summary(run),
    }


def choice_summary(run: Any) -> dict[str, float]:
    """How the segments were chosen: the share that were not co-speech (emblems or acting clips
    that no label asked for count as unrequested) and the share of transitions that follow the
    source clip's own order (``successors``)."""
    lib = run.pipeline.control_library
    played = [d for d in run.pipeline.log.decisions if not d.costs.get("continue", 0.0)]
    segs = [d.segment_id for d in played]
    cospeech = getattr(lib, "cospeech", None)
    succ = getattr(lib, "successors", None)
    out: dict[str, float] = {}
    if cospeech is not None and segs:
        out["unrequested_emblems"] = float(sum(1 for d in played if not cospeech[d.segment_id]
                                               and d.kind != "label"))
    if succ is not None and len(segs) > 1:
        chained = sum(int(succ[a] == b) for a, b in zip(segs[:-1], segs[1:], strict=True))
        out["source_order_share"] = chained / (len(segs) - 1)
    return out


def latency_summary(run: Any) -> dict[str, float]:
    """Prosody latency (syllable end → emission) and decision latency (emission → next step)."""
    syl = run.pipeline.log.syllables
    if not syl:
        return {}
    prosody = np.array([s.t_emitted - s.t_end for s in syl])
    dt = run.pipeline.dt
    # the first control step at or after emission sees the syllable
    to_step = np.array([np.ceil(s.t_emitted / dt - 1e-9) * dt - s.t_emitted for s in syl])
    return {
        "prosody_latency_median_s": float(np.median(prosody)),
        "prosody_latency_p95_s": float(np.percentile(prosody, 95)),
        "emission_to_belief_max_s": float(to_step.max()),
        "syllable_end_to_belief_median_s": float(np.median(prosody + to_step)),
    }


def following_summary(run: Any) -> dict[str, float]:
    """How the body followed the speech in a run: accents emitted and served by a stroke, the
    median accent-to-stroke delay (s), the share of time at rest, the vocal energy, and — with
    physics — the simulated hands' speed (p99, max, and max over the first 0.3 s: a start-up
    jump shows there), m/s."""
    pipe = run.pipeline
    log = pipe.log
    out: dict[str, float] = {"accents": float(len(log.accents)),
                             "strokes": float(len(log.strokes))}
    if log.accents:
        out["accents_served_share"] = len(log.served) / len(log.accents)
    if log.served:
        out["accent_to_stroke_median_s"] = float(np.median([s - a for a, s in log.served]))
    if log.modes:
        modes = np.asarray(log.modes)
        out["rest_share"] = float(np.mean((modes == "rest") | (modes == "to_rest")))
    if log.energy:
        e = np.asarray(log.energy, dtype=float)
        out.update(energy_mean=float(e.mean()), energy_p5=float(np.percentile(e, 5)),
                   energy_p95=float(np.percentile(e, 95)))
    if getattr(pipe, "sim", None) is not None:
        trace = pipe.trace()
        hands = np.asarray(trace.sim_sites)[:, :2]
        t = np.asarray(trace.time)
        if len(t) > 2:
            v = np.linalg.norm(np.diff(hands, axis=0), axis=2).mean(axis=1) / np.diff(t)
            early = v[t[1:] <= 0.3]
            out.update(hand_speed_p99_m_s=float(np.percentile(v, 99)),
                       hand_speed_max_m_s=float(v.max()),
                       startup_hand_speed_max_m_s=float(early.max()) if early.size else 0.0)
    return out
