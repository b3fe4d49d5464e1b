"""A decoder behind a worker thread: ``push`` audio blocks, ``poll`` what it found.

:class:`DecoderWorker` is the machinery that :class:`~gesture_sim.audio.keywords.KeywordSpotter`
and :class:`~gesture_sim.audio.live_words.LiveWords` share: a bounded queue of
:class:`~gesture_sim.contracts.AudioBlock` s that ``push`` appends to without ever blocking (past
``max_queue_s`` of backlog whole blocks are dropped and counted), a worker thread that decodes
them in order, ``poll`` for what was found since the last poll, ``finish`` (a short silence so
that whatever is open at the end is decided, then join the worker) and ``close`` (stop without
flushing). With ``threaded=False`` ``push`` decodes in place (deterministic: files, tests).
Worker errors surface as :class:`~gesture_sim.errors.GestureSimError` from ``poll``/``finish``.

A subclass gives :meth:`DecoderWorker._feed` (decode one block: the items found and whether
the stream restarted) and :meth:`DecoderWorker._close_decoder`, and calls
:meth:`DecoderWorker._start_worker` once its decoder exists. The live loop
(:class:`gesture_sim.app.live.LiveLoop`) drives any of them the same way.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.errors import GestureSimError

__all__ = ["DecoderWorker", "WorkerStats"]

T = TypeVar("T")


@dataclass
class WorkerStats:
    """The counters every decoder worker keeps.

    Attributes:
        pushed_s: audio pushed (s).
        decoded_s: audio the worker took in (s).
        dropped_s, dropped_blocks: audio / blocks dropped because the queue was full.
        cpu_s: thread CPU time the worker spent (s); ``cpu_s / decoded_s`` is its share of one
            core in real time.
        max_backlog_s: largest queue length seen (s of audio).
        restarts: gaps in the stream (after drops) that restarted the decoder.
        lag_s: wall-clock delays from pushing the block that completed an item to the item
            being found (s), one per item.
    """

    pushed_s: float = 0.0
    decoded_s: float = 0.0
    dropped_s: float = 0.0
    dropped_blocks: int = 0
    cpu_s: float = 0.0
    max_backlog_s: float = 0.0
    restarts: int = 0
    lag_s: list[float] = field(default_factory=list)

    @property
    def core_share(self) -> float:
        """CPU seconds per second of audio taken in (share of one core at real time)."""
        return self.cpu_s / self.decoded_s if self.decoded_s > 0 else 0.0

    def _common_dict(self) -> dict[str, float | int]:
        return {"pushed_s": round(self.pushed_s, 3), "decoded_s": round(self.decoded_s, 3),
                "dropped_s": round(self.dropped_s, 3), "dropped_blocks": self.dropped_blocks,
                "cpu_s": round(self.cpu_s, 4), "core_share": round(self.core_share, 4),
                "max_backlog_s": round(self.max_backlog_s, 3), "restarts": self.restarts}

    def _lag_dict(self) -> dict[str, float]:
        lag = np.asarray(self.lag_s) if self.lag_s else np.zeros(1)
        return {"lag_median_s": round(float(np.median(lag)), 4),
                "lag_max_s": round(float(np.max(lag)), 4)}


class DecoderWorker(Generic[T]):
    """``push`` blocks, ``poll`` items; a worker thread decodes (module docstring).

    Args:
        stats: the subclass's counters (a :class:`WorkerStats`).
        max_queue_s: backlog (s of audio) past which pushed blocks are dropped (counted).
        threaded: ``False`` decodes inside ``push``.

    Class attributes: ``what`` names the worker in errors, ``thread_name`` its thread,
    ``flush_s`` the silence :meth:`finish` appends.
    """

    what = "decoder"
    thread_name = "decoder-worker"
    flush_s = 0.3

    def __init__(self, stats: Any, *, max_queue_s: float = 3.0, threaded: bool = True) -> None:
        self.stats = stats
        self.max_queue_s = float(max_queue_s)
        self._threaded = bool(threaded)
        self._queue: deque[tuple[AudioBlock, float, bool] | None] = deque()
        self._queued_s = 0.0
        self._found: deque[T] = deque()
        self._error: BaseException | None = None
        self._cond = threading.Condition()
        self._closed = False
        self._finished = False
        self._pushed_end = 0.0
        self._thread: threading.Thread | None = None

    def _start_worker(self) -> None:
        """Start the thread (threaded and active only); call once the decoder exists."""
        if self._threaded and self.active:
            self._thread = threading.Thread(target=self._run, name=self.thread_name,
                                            daemon=True)
            self._thread.start()

    @property
    def active(self) -> bool:
        """Whether there is anything to decode (an inactive worker takes blocks, does nothing)."""
        return True

    # -- the subclass's part ------------------------------------------------------------------

    def _feed(self, block: AudioBlock, flush: bool) -> tuple[list[T], bool]:
        """Decode one block (``flush``: the closing silence of :meth:`finish`); the items it
        decided, and whether the stream restarted before it (a gap)."""
        raise NotImplementedError

    def _close_decoder(self) -> None:
        """Free the decoder (called once the worker is done with it)."""

    # -- producer side ------------------------------------------------------------------------

    def push(self, block: AudioBlock) -> None:
        """Hand a block to the worker; drops it (counted) when the backlog is full."""
        if self._closed or self._finished:
            raise GestureSimError(f"{self.what}: push after finish/close")
        dur = len(block.samples) / SAMPLE_RATE
        self.stats.pushed_s += dur
        self._pushed_end = block.t_end
        if not self.active:
            return
        if not self._threaded:
            self._decode(block, time.perf_counter())
            return
        with self._cond:
            if self._queued_s + dur > self.max_queue_s:
                self.stats.dropped_s += dur
                self.stats.dropped_blocks += 1
                return
            self._queue.append((block, time.perf_counter(), False))
            self._queued_s += dur
            self.stats.max_backlog_s = max(self.stats.max_backlog_s, self._queued_s)
            self._cond.notify()

    def poll(self) -> list[T]:
        """What was found since the last poll, in the order found (never blocks)."""
        self._raise_error()
        out: list[T] = []
        while self._found:
            out.append(self._found.popleft())
        return out

    def finish(self, timeout_s: float = 10.0) -> list[T]:
        """End of stream: decode the backlog and a short silence, join the worker, and return
        what was not yet polled. A worker still busy after ``timeout_s`` is left to finish in
        the background (its later items are lost); the backlog is reported in :attr:`stats`."""
        if self._finished or self._closed:
            return self.poll()
        self._finished = True
        if self.active:
            pad = AudioBlock(np.zeros(int(self.flush_s * SAMPLE_RATE), np.float32),
                             self._pushed_end)
            if self._threaded:
                with self._cond:
                    self._queue.append((pad, time.perf_counter(), True))
                    self._queue.append(None)
                    self._cond.notify()
                if self._thread is not None:
                    self._thread.join(timeout_s)
            else:
                self._decode(pad, time.perf_counter(), flush=True)
                self._close_decoder()
        return self.poll()

    def close(self) -> None:
        """Stop the worker (without flushing) and free the decoder."""
        if self._closed:
            return
        self._closed = True
        with self._cond:
            self._queue.clear()
            self._queue.append(None)
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(5.0)
        else:
            self._close_decoder()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def decode_all(self, samples: np.ndarray, block_size: int = 160,
                   stats: Any = None) -> list[T]:
        """Push float32 16 kHz samples (n,) in ``block_size`` blocks, finish and close; every
        item, in the order found (deterministic with ``threaded=False``). ``stats``: filled
        with the run's counters when given."""
        from gesture_sim.audio.sources import iter_blocks

        out: list[T] = []
        for block in iter_blocks(np.asarray(samples, dtype=np.float32), block_size):
            self.push(block)
            out.extend(self.poll())
        out.extend(self.finish())
        self.close()
        if stats is not None:
            stats.__dict__.update(self.stats.__dict__)
        return out

    # -- worker side --------------------------------------------------------------------------

    def _decode(self, block: AudioBlock, pushed_at: float, flush: bool = False) -> None:
        c0 = time.thread_time()
        found, restarted = self._feed(block, flush)
        self.stats.cpu_s += time.thread_time() - c0
        if not flush:
            self.stats.decoded_s += len(block.samples) / SAMPLE_RATE
        self.stats.restarts += int(restarted)
        if found:
            lag = time.perf_counter() - pushed_at
            self.stats.lag_s.extend([lag] * len(found))
            self._found.extend(found)

    def _run(self) -> None:
        try:
            while True:
                with self._cond:
                    while not self._queue:
                        self._cond.wait()
                    item = self._queue.popleft()
                    if item is not None and not item[2]:
                        self._queued_s -= len(item[0].samples) / SAMPLE_RATE
                if item is None:
                    break
                self._decode(*item)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer thread
            self._error = exc
        finally:
            self._close_decoder()

    def _raise_error(self) -> None:
        if self._error is not None:
            exc, self._error = self._error, None
            if isinstance(exc, GestureSimError):
                raise exc
            raise GestureSimError(f"{self.what} failed: {type(exc).__name__}: {exc}") from exc
