"""Statistics of a live run (:class:`LiveStats`): frame times, physics steps per frame, lag,
audio drops and memory, in bounded buffers so that a long run keeps a flat resident size."""

from __future__ import annotations

import math
import os
import resource
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gesture_sim.running import RunningStat

#: Frames kept for the timing percentiles (10 min at 60 Hz): bounded, so memory stays flat.
TIMING_WINDOW = 36_000
#: Seconds between RSS samples; samples kept (a bounded, thinned history).
RSS_PERIOD_S = 1.0
RSS_SAMPLES = 600


class RunningWindow:
    """Running mean/std/max over everything, percentiles over the last ``n`` values.

    The recent values live in a preallocated ring (touched at creation), so a long run does
    not grow the process.
    """

    def __init__(self, n: int = TIMING_WINDOW) -> None:
        self._ring = np.full(n, np.nan)
        self._stat = RunningStat(form="welford")
        self.max = -math.inf

    def add(self, x: float) -> None:
        self._ring[self.count % len(self._ring)] = x
        self._stat.update(x)
        self.max = max(self.max, x)

    @property
    def count(self) -> int:
        return self._stat.n

    @property
    def mean(self) -> float:
        return self._stat.mean

    @property
    def std(self) -> float:
        return math.sqrt(self._stat.var) if self.count > 1 else 0.0

    def pct(self, q: float) -> float:
        return float(np.nanpercentile(self._ring, q)) if self.count else 0.0


def rss_mb() -> float:
    """Current resident set size (MiB), from /proc (0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


def maxrss_mb() -> float:
    """Peak resident set size of this process so far (MiB; Linux reports KiB)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / 2**20 if sys.platform == "darwin" else r / 1024


@dataclass
class LiveStats:
    """What one live run measured (written by ``--stats``; see :meth:`to_dict`)."""

    frames: int = 0
    wall_s: float = 0.0
    paused_s: float = 0.0
    sim_s: float = 0.0
    slipped_s: float = 0.0
    audio_pushed_s: float = 0.0
    audio_dropped_paused_s: float = 0.0
    audio_dropped_slip_s: float = 0.0
    audio_dropped_at_start_s: float = 0.0
    frame_dt: RunningWindow = field(default_factory=RunningWindow)
    #: The figures of each decoder worker that heard the stream, by name (``"keywords"``: the
    #: keyword spotter, ``"words"``: the live word recogniser); each is a top-level key of
    #: :meth:`to_dict`.
    decoders: dict[str, dict[str, Any]] = field(default_factory=dict)
    steps: RunningWindow = field(default_factory=RunningWindow)
    work_ms: RunningWindow = field(default_factory=RunningWindow)
    lag: RunningWindow = field(default_factory=RunningWindow)
    gc_ms: RunningWindow = field(default_factory=RunningWindow)
    gc_frozen: int = 0
    maxrss_start_mb: float = 0.0
    maxrss_end_mb: float = 0.0
    rss: list[tuple[float, float]] = field(default_factory=list)
    source: dict[str, Any] = field(default_factory=dict)
    keys: list[str] = field(default_factory=list)
    exit_reason: str = ""
    screenshots: list[str] = field(default_factory=list)
    #: The pose stream's figures (frames sent, dropped, ...; only when a stream ran).
    stream: dict[str, Any] = field(default_factory=dict)
    #: The body driven (``humanoid``, ``g1``, ``h1``, a robot map's name; "" when unknown).
    body: str = ""

    @property
    def keywords(self) -> dict[str, Any]:
        """The keyword spotter's figures (empty when none listened)."""
        return self.decoders.get("keywords", {})

    @property
    def words(self) -> dict[str, Any]:
        """The live word recogniser's figures (empty when none listened)."""
        return self.decoders.get("words", {})

    def sample_rss(self, t: float) -> None:
        """Record (t, RSS MiB); halves the history when full so it stays bounded."""
        self.rss.append((round(t, 2), round(rss_mb(), 2)))
        if len(self.rss) > RSS_SAMPLES:
            self.rss = self.rss[::2]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures: frame time (ms), physics steps per frame, real-time share, audio
        drops (s), memory (MiB) with the RSS slope over the second half of the run (MiB per
        minute, least squares; ~0 when memory stays flat)."""
        rt_wall = max(self.wall_s - self.paused_s, 1e-9)
        rss = np.array(self.rss) if self.rss else np.zeros((0, 2))
        half = rss[len(rss) // 2 :]  # after the warm-up (windows, caches, first allocations)
        slope = 0.0
        if len(half) >= 3 and np.ptp(half[:, 0]) > 0:
            slope = float(np.polyfit(half[:, 0], half[:, 1], 1)[0] * 60.0)
        out = {
            "frames": self.frames,
            "wall_s": round(self.wall_s, 3),
            "paused_s": round(self.paused_s, 3),
            "sim_s": round(self.sim_s, 3),
            "percent_real_time": round(100.0 * self.sim_s / rt_wall, 1),
            "fps": round(self.frames / max(self.wall_s, 1e-9), 2),
            "physics_steps_per_frame": {"mean": round(self.steps.mean, 2),
                                        "p95": self.steps.pct(95), "max": self.steps.max
                                        if self.steps.count else 0},
            "frame_time_ms": {"mean": round(1e3 * self.frame_dt.mean, 3),
                              "p50": round(1e3 * self.frame_dt.pct(50), 3),
                              "p95": round(1e3 * self.frame_dt.pct(95), 3),
                              "max": round(1e3 * self.frame_dt.max, 3)
                              if self.frame_dt.count else 0.0,
                              "jitter_std": round(1e3 * self.frame_dt.std, 3)},
            "loop_work_ms": {"mean": round(self.work_ms.mean, 3),
                             "p95": round(self.work_ms.pct(95), 3)},
            "physics_lag_ms": {"mean": round(1e3 * self.lag.mean, 2),
                               "p95": round(1e3 * self.lag.pct(95), 2)},
            "slipped_s": round(self.slipped_s, 4),
            "gc": {"frozen_objects": self.gc_frozen, "collections": self.gc_ms.count,
                   "pause_ms_mean": round(self.gc_ms.mean, 3),
                   "pause_ms_max": round(self.gc_ms.max, 3) if self.gc_ms.count else 0.0},
            "audio": {"pushed_s": round(self.audio_pushed_s, 3),
                      "dropped_while_paused_s": round(self.audio_dropped_paused_s, 3),
                      "dropped_on_slip_s": round(self.audio_dropped_slip_s, 3),
                      "dropped_at_start_s": round(self.audio_dropped_at_start_s, 3),
                      **self.source},
            "memory": {"maxrss_start_mb": round(self.maxrss_start_mb, 1),
                       "maxrss_end_mb": round(self.maxrss_end_mb, 1),
                       "rss_first_mb": rss[0, 1].item() if len(rss) else None,
                       "rss_last_mb": rss[-1, 1].item() if len(rss) else None,
                       "rss_max_mb": rss[:, 1].max().item() if len(rss) else None,
                       "rss_slope_second_half_mb_per_min": round(slope, 3),
                       "rss_series": [list(r) for r in self.rss[:: max(len(self.rss) // 60, 1)]]},
            "keys": self.keys[-50:],
            "exit_reason": self.exit_reason,
            "screenshots": self.screenshots,
        }
        out.update((name, figures) for name, figures in self.decoders.items() if figures)
        if self.stream:
            out["stream"] = self.stream
        if self.body:
            out["body"] = self.body
        return out
