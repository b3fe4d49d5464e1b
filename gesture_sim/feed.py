"""The one feed loop: audio → control steps → physics, block by block in simulated real time.

:func:`feed` drives anything with the pipeline's run-time interface — ``push(blocks)``,
``advance(t)``, ``finish()``, ``time`` — over an (n, c) array of 16 kHz samples, one channel per
voice: each block is pushed, then the physics is advanced to the latest control step (the live
loop's order), and at the end the last steps run and the physics reaches the end of the audio.
:func:`run_file` feeds one person (a file, or samples given as ``y=, sr=`` as librosa takes
them) and :func:`~gesture_sim.conversation.run_conversation` two; the live loop
(:mod:`gesture_sim.app.live`) pushes microphone blocks and advances with the wall clock through
the same pipeline methods.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gesture_sim.audio.sources import check_not_silent  # -60 dBFS: silent (render, train --signs)
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.cpus import usable_cpus
from gesture_sim.errors import GestureSimError

#: Stream seconds of physics a feed lets its sink's physics loops defer
#: (:attr:`gesture_sim.sim.world.PhysicsLoop.defer_s`): the physics runs the same steps in
#: stretches of this length instead of after every control step, which keeps the audio
#: analysis and the control steps in between from running on caches the physics step has
#: just filled (docs/history.md, "deferred physics"). Offline only: nothing reads the state while a
#: feed runs, and the feed runs everything pending before it returns.
DEFER_PHYSICS_S = 0.3
#: Where those deferred stretches run when the process may use two or more cores
#: (:meth:`gesture_sim.sim.world.PhysicsLoop.start_background`): ``"process"``, a forked child
#: process with a copy of the physics state and its own GIL, which hands the state back at the
#: end of the feed (where the OS forks; else a thread); ``"thread"``, a thread of this process
#: (``mj_step`` releases the GIL, the control law's Python shares it); ``"off"``, in this
#: thread. The same steps in the same order every way (BENCHMARKS.md
#: "Speed"). The environment variable ``GESTURE_SIM_PHYSICS_WORKER`` (``process``, ``thread``,
#: ``off``) overrides it (a batch's worker processes set ``off`` when they already fill
#: every core).
PHYSICS_WORKER = "process"
#: The interpreter's thread switch interval (s) while a feed runs the physics on a thread:
#: after each ``mj_step`` the physics thread needs the GIL back for its Python glue, and
#: Python's default (5 ms) would make it wait up to that long for the analysis to yield it,
#: once per control update.
SWITCH_INTERVAL_S = 1e-5



def feed(sink, channels: np.ndarray, *, block_size: int = 160, show_progress: bool = False,
         before_block: Callable[[float], None] | None = None,
         defer_physics_s: float | None = None) -> float:
    """Feed ``channels`` (n, c) float32 16 kHz through ``sink`` (see the module docstring).

    A sink with ``expect(channels)`` is first handed the whole audio: a file is known ahead, and
    the speech analysis prepares per-frame work from it (the same results at the same times).

    ``before_block(t_start)`` runs before each block is pushed (label requests due by then).
    ``defer_physics_s`` (s; 0: off; default :data:`DEFER_PHYSICS_S`, read at the call): see
    :data:`DEFER_PHYSICS_S`; the physics computed is the same either way. Returns the
    wall-clock seconds of the run.
    """
    from gesture_sim.progress import progress

    duration = len(channels) / SAMPLE_RATE
    t0 = time.perf_counter()
    bar = progress(total=round(duration, 1), desc="simulating", enabled=show_progress, unit="s")
    done = 0.0
    b = max(int(block_size), 1)
    if defer_physics_s is None:
        defer_physics_s = DEFER_PHYSICS_S
    loops = _physics_loops(sink) if defer_physics_s > 0 else []
    worker = physics_worker() if loops else None
    switch = sys.getswitchinterval()
    completed = False
    expect = getattr(sink, "expect", None)
    try:
        for loop in loops:
            loop.defer_s = float(defer_physics_s)
            if worker is not None:
                loop.start_background(worker)
        if expect is not None:              # after the fork: the physics process needs none
            expect(channels)                # of it, and starts sooner
        if worker == "thread":
            sys.setswitchinterval(min(switch, SWITCH_INTERVAL_S))
        for start in range(0, len(channels), b):
            t_start = start / SAMPLE_RATE
            chunk = channels[start: start + b]
            if before_block is not None:
                before_block(t_start)
            sink.push([AudioBlock(np.ascontiguousarray(chunk[:, p]), t_start)
                       for p in range(chunk.shape[1])])
            sink.advance(sink.time)
            t_end = (start + len(chunk)) / SAMPLE_RATE
            if t_end - done >= 0.5:
                bar.update(round(t_end - done, 1))
                done = t_end
        sink.finish()
        for loop in loops:
            loop.defer_s = 0.0           # the last advance runs whatever is still pending
        sink.advance(duration)
        for loop in loops:
            loop.flush()
        completed = True
    finally:
        sys.setswitchinterval(switch)
        for loop in loops:
            loop.stop_background(cancel=not completed)
            loop.defer_s = 0.0
    bar.close()
    return time.perf_counter() - t0


def physics_worker() -> str | None:
    """Where a feed runs its deferred physics (:data:`PHYSICS_WORKER`, or the environment's
    ``GESTURE_SIM_PHYSICS_WORKER``): ``"process"`` or ``"thread"``, or None (in the feed's
    own thread: so set, or no second core to run it on)."""
    from gesture_sim.validation import physics_worker_env

    mode = physics_worker_env(os.environ) or PHYSICS_WORKER   # an unknown value: one line
    if mode not in ("process", "thread") or usable_cpus() < 2:
        return None
    return mode


def _physics_loops(sink) -> list:
    """The physics loops ``sink`` steps: its pipeline's body (one person) or its scene (a
    conversation), none without physics."""
    pipeline = getattr(sink, "pipeline", None)
    sim = getattr(pipeline, "sim", None) if pipeline is not None else getattr(sink, "scene", None)
    loop = getattr(sim, "loop", None)
    return [loop] if loop is not None else []


class _One:
    """One pipeline as a feed sink (one channel)."""

    def __init__(self, pipeline) -> None:
        self.pipeline = pipeline

    def expect(self, channels: np.ndarray) -> None:
        self.pipeline.expect_audio(channels[:, 0])

    def push(self, blocks: Sequence[AudioBlock]) -> None:
        self.pipeline.push_audio(blocks[0])

    def advance(self, t: float) -> None:
        self.pipeline.advance(t)

    def finish(self) -> None:
        self.pipeline.finish()

    @property
    def time(self) -> float:
        return self.pipeline.time


@dataclass
class RunResult:
    """A whole file through the pipeline.

    Attributes:
        pipeline: the pipeline after the run (its ``log`` and ``trace()``).
        audio: (n,) float32 16 kHz samples; duration: seconds.
        wall: wall-clock seconds of the run; costs: seconds per stage.
    """

    pipeline: object
    audio: np.ndarray
    duration: float
    wall: float
    costs: dict[str, float]


def run_file(pipeline, audio_path: str | Path | None = None, *, y: np.ndarray | None = None,
             sr: int | None = None, name: str | None = None, block_size: int = 160,
             show_progress: bool = False,
             labels: Sequence[tuple[float, str]] = (), keywords=None,
             transcript: str | Path | None = None,
             words: Sequence[tuple[float, float, str]] | None = None,
             stress: Sequence[float] | None = None) -> RunResult:
    """Feed a file (``audio_path``) or samples (``y=`` (n,) at ``sr=`` Hz, resampled to 16 kHz)
    through the pipeline block by block, in simulated real time (``name``: what an error about
    the samples calls them).

    ``labels`` are semantic gestures requested at given stream times, ``(t_s, "wave")``, as a
    key press would request them live. ``keywords`` (a
    :class:`~gesture_sim.audio.keywords.KeywordTable`) spots the table's words in the audio
    (PocketSphinx, the same decoder the live spotter runs) — or, with ``transcript`` (a TextGrid
    word tier or ``start end word`` lines), reads them from the aligned text — and requests each
    hit's label at the time the spotter knew it (``t_emitted``; the transcript's word end).
    The hits are kept in ``pipeline.log.words``.

    A method whose belief filter reads timed words (``chiu14``: its filter has ``set_words``)
    gets ``words`` (``(start_s, end_s, text)``), else the ``transcript``'s words; it reveals each
    only once said (the filter's latency), as the keyword hits are.

    A method that plans ahead (``planned``) gets the text as known ahead
    (:meth:`~gesture_sim.pipeline.GesturePipeline.know_ahead`): ``words`` or the
    ``transcript``'s words, a TextGrid transcript's phones (with their stress digits), and
    ``stress`` (stressed-syllable times, s) where given.
    """
    samples, what = _samples(audio_path, y, sr)
    check_not_silent(samples, name or what)
    spotted = []
    if keywords is not None:
        from gesture_sim.audio.keywords import spot_file, transcript_keywords

        spotted = (transcript_keywords(transcript, keywords, pipeline.labels)
                   if transcript is not None else spot_file(samples, keywords, pipeline.labels))
        labels = list(labels) + [(w.t_emitted, w.label) for w in spotted if w.label]
    unknown = sorted({lab for _, lab in labels} - set(pipeline.labels))
    if unknown:
        from gesture_sim.methods import no_labels_note

        none = no_labels_note(getattr(pipeline, "method", None),
                              getattr(pipeline, "library", None))
        raise GestureSimError(f"unknown semantic label(s) {', '.join(unknown)}; " + (
            none or f"this library has: {', '.join(pipeline.labels) or 'none'}"))
    pending = sorted(labels)

    def due(t_start: float) -> None:
        while pending and pending[0][0] <= t_start:
            pipeline.trigger_label(pending.pop(0)[1])

    set_words = getattr(pipeline.filter, "set_words", None)
    if set_words is not None and (words is not None or transcript is not None):
        from gesture_sim.audio.keywords import read_word_list

        set_words(list(words) if words is not None else read_word_list(transcript))
    pipeline.reset(expected_s=len(samples) / SAMPLE_RATE + 1.0)
    pipeline.log.words = list(spotted)
    if hasattr(pipeline, "know_ahead") and (words is not None or transcript is not None
                                            or stress is not None):
        pipeline.know_ahead(**_text_ahead(words, transcript, stress))
    wall = feed(_One(pipeline), samples[:, None], block_size=block_size,
                show_progress=show_progress, before_block=due)
    return RunResult(pipeline=pipeline, audio=samples, duration=len(samples) / SAMPLE_RATE,
                     wall=wall, costs={k: v.seconds for k, v in pipeline.costs.items()})


def _text_ahead(words, transcript, stress) -> dict:
    """The ``know_ahead`` arguments of :func:`run_file`'s text: the words (given, or the
    transcript's), a TextGrid transcript's phone tier with its labels as written, the stress
    times given."""
    phones = None
    if transcript is not None:
        from gesture_sim.audio.keywords import read_word_list
        from gesture_sim.audio.textgrid import read_textgrid

        if words is None:
            words = read_word_list(transcript)
        try:
            grid = read_textgrid(transcript)
        except GestureSimError:
            grid = None                     # a plain word list
        if grid is not None and "phones" in grid:
            phones = [(iv.xmin, iv.xmax, iv.text) for iv in grid.tier("phones")
                      if iv.text.strip()]
    return {"words": None if words is None else list(words), "phones": phones,
            "stress": None if stress is None else list(stress)}


def _samples(audio_path: str | Path | None, y: np.ndarray | None, sr: int | None
             ) -> tuple[np.ndarray, str]:
    """(n,) float32 16 kHz samples and a name for messages, from a path or ``y``/``sr``."""
    if (audio_path is None) == (y is None):
        raise GestureSimError("give an audio file or samples (y=, sr=), not both")
    if audio_path is not None:
        from gesture_sim.audio.sources import load_audio

        samples, _info = load_audio(audio_path)
        return samples, str(audio_path)
    if sr is None or int(sr) <= 0:
        raise GestureSimError("samples need their sample rate: sr= (Hz)")
    y = np.asarray(y, dtype=np.float32)
    if y.ndim != 1:
        raise GestureSimError(f"samples must be one channel, shape (n,); got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise GestureSimError("samples contain NaN or infinite values")
    if int(sr) != SAMPLE_RATE:
        from math import gcd

        from scipy.signal import resample_poly

        g = gcd(int(sr), SAMPLE_RATE)
        y = resample_poly(y, SAMPLE_RATE // g, int(sr) // g).astype(np.float32)
    return y, "samples"
