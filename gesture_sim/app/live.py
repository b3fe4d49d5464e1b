"""The live loop: the passive MuJoCo viewer driven by the microphone (or a file) in real time.

One loop on the main thread, one frame at a time at the display rate (default 60 Hz)::

    drain the audio blocks that have arrived (never waits)  -> pipeline.push_audio
    advance physics to the live clock (wall time, pauses excluded) -> pipeline.advance
    hand the overlay texts to the overlay thread; viewer.sync() (never per physics step)
    act on the keys pressed since the last frame; sleep to the next frame deadline

Threads: PortAudio's callback thread (the microphone; it only fills a ring buffer, see
:class:`~gesture_sim.audio.sources.MicrophoneSource`), a pump thread that turns the ring into
:class:`~gesture_sim.contracts.AudioBlock` s on a queue, the viewer's render thread (MuJoCo), and
an overlay thread that calls ``Handle.set_texts``, which blocks until the render thread has
drawn a frame (hundreds of ms under software GL) and releases the GIL while it waits.

Clocks. The *live clock* (the stream time physics is advanced to) starts with the first audio
block pushed and then follows the wall clock, less the time spent paused and less *slip*: when
physics falls more than ``max_lag_s`` behind (a slow machine, a stall), the live clock gives up
the excess instead of making the next frame catch up all at once. Audio blocks are re-stamped
onto one contiguous pipeline clock: audio that arrived while the window opened or while paused
is dropped, and after a slip the same duration of audio is dropped, so audio and physics stay
on one clock. A reset restarts the stream (and the live clock) at 0. Everything dropped is
counted in the stats.

Garbage collection: once the viewer is open, everything allocated so far (the model, the
library, the viewer, ~10^5 objects) is collected once and frozen (:func:`gc.freeze`), so the
collector's full passes during the loop scan only what the loop itself allocates (a full pass
over the start-up heap takes ~65 ms, four frames; in the loop the longest is ~2 ms). The stats
give the number and length of the collections during the loop.

Software GL: without a GPU (Mesa's llvmpipe) the viewer's render thread would start a
rasteriser thread per CPU and take every core from the loop; it is left all CPUs but one
(:func:`gesture_sim.cpus.leave_a_cpu_for_physics`), which removed the clock slips of a
30-minute soak on 2 cores.

Memory: the loop itself keeps bounded buffers only (preallocated timing rings, a bounded audio
queue, a thinned RSS history), so its resident size stays flat over a long run, provided the
pipeline keeps no unbounded history (``GesturePipeline(record=False)`` where available); the
stats sample the RSS once a second and report its slope over the second half of the run.

Decoder workers: a keyword spotter (:class:`~gesture_sim.audio.keywords.KeywordSpotter`) and a
live word recogniser (:class:`~gesture_sim.audio.live_words.LiveWords`), both
:class:`~gesture_sim.audio.decoder_worker.DecoderWorker` s, hang off the loop the same way
(:class:`AttachedDecoder`): each is pushed every block the pipeline is pushed (``push`` never
blocks: the worker decodes in its own thread), polled once a frame, and what it found is handed
on: keyword hits become label requests, words go to the sign filter (``chiu14``:
``pipeline.filter.push_words``, revealed at each word's ``t_emitted``). They are closed when the
loop ends however it ends (window, Ctrl-C, end of a file, an error), and their figures go to
the statistics under ``keywords`` and ``words``.

Without a window (``LiveOptions.headless``, ``live --headless``): the same loop with a
:class:`~gesture_sim.app.viewer.HeadlessViewer`, which draws nothing and has no keys (no
overlay texts are made); the loop still paces itself at ``fps`` and stops on Ctrl-C,
``duration`` or the end of a file. For streaming to an engine or a robot on a machine with no
display.

The pose stream (``LiveOptions.stream``) runs on its own clock:
:class:`~gesture_sim.app.pose_clock.ClockedStream` sends the latest published state at a fixed
rate (60 Hz by default) from its own thread, whatever the viewer's frame rate; the loop only
publishes the state after each physics advance.

The audio feeds live in :mod:`gesture_sim.audio.feeds`, the statistics in
:mod:`gesture_sim.app.live_stats` and the viewer helpers in :mod:`gesture_sim.app.viewer`.
"""

from __future__ import annotations

import contextlib
import gc
import json
import queue
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np

from gesture_sim import interrupt
from gesture_sim.app.live_stats import RSS_PERIOD_S, LiveStats, maxrss_mb
from gesture_sim.app.overlay import (
    KeyAction,
    OverlayState,
    decode_key,
    key_map_lines,
    viewer_texts,
)
from gesture_sim.app.pose_clock import DEFAULT_RATE_HZ, ClockedStream
from gesture_sim.app.viewer import (
    HeadlessViewer,
    NullPump,
    OverlayPump,
    ScreenshotTaker,
    mujoco_of,
    setup_camera,
)
from gesture_sim.audio.feeds import AudioFeed, FileFeed
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.control.style import clip_style
from gesture_sim.cpus import leave_a_cpu_for_physics
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_write_text
from gesture_sim.runlog import PipelineStatus


class Pipeline(Protocol):
    """What the live loop needs of :class:`gesture_sim.pipeline.GesturePipeline` (the MuJoCo
    model and data are found by :func:`mujoco_of`: ``model_mj``/``data`` or ``model``/``data``).
    """

    data: mujoco.MjData
    labels: tuple[str, ...]

    def push_audio(self, block: AudioBlock) -> None: ...
    def advance(self, t: float) -> None: ...
    def status(self) -> PipelineStatus: ...
    def set_style(self, dial: float) -> None: ...
    def trigger_label(self, label: str) -> None: ...
    def reset(self) -> None: ...


@dataclass
class LiveOptions:
    """Settings of :func:`run_live`.

    Attributes:
        duration: stop after this many seconds of wall time (``None``: until the window is
            closed, Ctrl-C, or the end of a non-looping file plus ``tail_s``).
        fps: display rate (Hz) at which the loop syncs the viewer.
        max_lag_s: physics may lag the live clock by this much (s) before the clock slips.
        style: initial style dial, 0 (calm) … 1 (energetic).
        screenshots: (simulation time s, PNG path) pairs to capture during the run: the
            first frame at which the body has reached that time of the stream (pauses and
            slips excluded), so a grab shows the same moment of the speech however slowly the
            machine starts.
        final_screenshot: a PNG captured when the loop ends.
        screenshot_mode: ``"render"`` (offscreen :class:`mujoco.Renderer` from the viewer's
            camera; no overlays) or ``"screen"`` (grab the X screen where the window is; needs
            an X display without a window manager moving the window, e.g. Xvfb).
        stats_path: write the loop statistics (JSON) here at the end.
        shadow_size: shadow-map size for the viewer (pixels); software GL renders 1024 several
            times faster than the scene's 4096.
        tail_s: how long to keep going after a non-looping file ends (s).
        show_keys: show the key map in the viewer; print_keys: print it at start.
        out: where the key map and the end summary go (``None``: stdout).
        stream: a pose sender (:class:`gesture_sim.export.vmc.VmcSender`,
            :class:`gesture_sim.export.json_stream.JsonSender`, or anything with
            ``send(model, qpos, t)`` that never blocks nor raises, and ``stats()``), or a
            :class:`~gesture_sim.app.pose_clock.ClockedStream` around one: it sends the
            body's latest pose at ``stream_rate`` on its own thread, whatever the viewer's
            frame rate (the loop publishes the state after each physics advance; paused: the
            held pose); the sender's ``prepare(model)``, where it has one, is called once
            before the first frame; its figures (protocol, address, frames sent and dropped,
            sent rate, largest gap, bytes, ms per frame) go to the statistics under
            ``stream``. When not one frame goes out in the stream's first second the loop
            stops (``exit_reason`` ``"stream failed: ..."``).
        stream_rate: frames a second of the stream (Hz) when ``stream`` is a bare sender.
        headless: run without a window (:class:`~gesture_sim.app.viewer.HeadlessViewer`):
            the same loop, nothing drawn, no keys; for streaming and robots.
    """

    duration: float | None = None
    fps: float = 60.0
    max_lag_s: float = 0.2
    style: float = 0.5
    screenshots: Sequence[tuple[float, str | Path]] = ()
    final_screenshot: str | Path | None = None
    screenshot_mode: str = "render"
    stats_path: str | Path | None = None
    shadow_size: int | None = 1024
    tail_s: float = 1.0
    show_keys: bool = True
    print_keys: bool = True
    out: Any = None
    stream: Any = None
    stream_rate: float = DEFAULT_RATE_HZ
    headless: bool = False


def _status_fields(st: PipelineStatus) -> dict[str, Any]:
    """The overlay's fields of a :class:`~gesture_sim.runlog.PipelineStatus` (no segment
    before the first step)."""
    return {
        "t": float(st.t),
        "level_db": st.level_db,
        "state": st.state,
        "belief": np.asarray(st.belief, dtype=float),
        "segment": st.segment_name or (st.segment if st.segment >= 0 else None),
        "style": st.style,
        "label": st.label,
    }


#: Live words kept for the statistics (the most recent; the counters cover all of them).
WORDS_KEPT = 200


@dataclass
class AttachedDecoder:
    """A decoder worker hanging off the live loop.

    Attributes:
        name: its key in the statistics (``"keywords"``, ``"words"``).
        worker: a :class:`~gesture_sim.audio.decoder_worker.DecoderWorker` (``push``,
            ``poll``, ``close``): it hears every block the pipeline hears.
        take: called with what one ``poll`` found (never with nothing), once a frame.
        report: its figures for the statistics, once the worker is closed.
    """

    name: str
    worker: Any
    take: Callable[[list[Any]], None]
    report: Callable[[], dict[str, Any]] = field(default=dict)


class LiveLoop:
    """The live loop of one session (see the module docstring); run it with :meth:`run`.

    Clocks (all in seconds): *wall* runs from the loop's start; the *feed clock* (paces a
    file) is wall time minus pauses; the *live clock* ``t_live`` is the stream time physics is
    advanced to. It stays at 0 until the first audio block is pushed (so a late or silent
    start costs nothing), then runs with the wall clock, less pauses and slips; a reset
    restarts it at 0 together with the pipeline's stream.

    Args:
        pipeline: a :class:`~gesture_sim.pipeline.GesturePipeline` (or anything with its
            methods); its MuJoCo model and data (:func:`mujoco_of`) are what the viewer shows.
        feed: where the audio comes from (:class:`MicrophoneFeed` or :class:`FileFeed`).
        options: :class:`LiveOptions`.
        viewer_factory: ``mujoco.viewer.launch_passive`` or a stand-in with its signature.
        spotter: a :class:`~gesture_sim.audio.keywords.KeywordSpotter` (or None): its hits
            become label requests (kept in :attr:`keywords`).
        words: a :class:`~gesture_sim.audio.live_words.LiveWords` (or None): its words go to
            the pipeline's sign filter (``pipeline.filter.push_words``; the last
            :data:`WORDS_KEPT` in :attr:`heard`). Words decided on the audio of a stream
            before a reset (``t_emitted`` past the audio pushed since) are left out, counted.

    Both are closed when :meth:`run` ends; until then the caller must close them itself.
    """

    def __init__(self, pipeline: Pipeline, feed: AudioFeed, options: LiveOptions | None = None,
                 viewer_factory: Callable[..., Any] | None = None, spotter: Any = None,
                 words: Any = None) -> None:
        self.pipeline = pipeline
        self.spotter = spotter
        self.keywords: list[Any] = []
        self.words = words
        self.heard: deque[Any] = deque(maxlen=WORDS_KEPT)
        self.words_taken = 0    # words the sign filter took
        self.words_stale = 0    # words of a stream before a reset, left out
        #: the decoder workers that hear the stream (:class:`AttachedDecoder`)
        self.decoders: list[AttachedDecoder] = []
        if spotter is not None:
            self.decoders.append(AttachedDecoder("keywords", spotter, self._take_keywords,
                                                 self._keywords_report))
        if words is not None:
            push = getattr(getattr(pipeline, "filter", None), "push_words", None)
            if push is None:
                raise GestureSimError("live words: this method's belief filter does not read "
                                      "words (only --method chiu14 does)")
            self._push_words = push
            self.decoders.append(AttachedDecoder("words", words, self._take_words,
                                                 self._words_report))
        self.model, self.data = mujoco_of(pipeline)
        self.feed = feed
        self.opt = options or LiveOptions()
        if self.opt.fps <= 0:
            raise GestureSimError(f"fps must be positive, got {self.opt.fps}")
        if self.opt.screenshot_mode not in ("render", "screen"):
            raise GestureSimError(f"screenshot mode must be 'render' or 'screen', got "
                                  f"{self.opt.screenshot_mode!r}")
        self._factory = viewer_factory
        stream = self.opt.stream
        #: the pose stream on its own clock (None: no stream)
        self.stream: ClockedStream | None = (
            None if stream is None else stream if isinstance(stream, ClockedStream)
            else ClockedStream(stream, self.opt.stream_rate))
        self.clock = time.perf_counter
        self.labels = tuple(getattr(pipeline, "labels", ()) or ())
        self.style = clip_style(self.opt.style)
        self.paused = False
        self.show_keys = self.opt.show_keys
        self.stats = LiveStats()
        self._keys: queue.SimpleQueue[int] = queue.SimpleQueue()
        self._stop_reason: str | None = None
        self._started = False  # has the live clock started (first audio pushed)?
        self._base = 0.0  # t_live = wall - base once started
        self._audio_cursor = 0.0  # pipeline time of the next audio sample (s)
        self._audio_debt = 0.0  # audio (s) still to drop after a slip
        self._pause_started: float | None = None
        self._feed_paused = 0.0  # total pause time (s), for the feed clock
        self._pending_after_sync: list[KeyAction] = []

    # ---------------------------------------------------------------- keys and signals
    def key_callback(self, key: int) -> None:
        """Called by the viewer's render thread: queue the key, act on it in the loop."""
        self._keys.put(int(key))

    def request_stop(self, reason: str = "stopped") -> None:
        """Ask the loop to end after the current frame (thread-safe)."""
        if self._stop_reason is None:
            self._stop_reason = reason

    def _apply(self, action: KeyAction, wall: float) -> None:
        p = self.pipeline
        if action.kind == "style":
            self.style = round(clip_style(self.style + action.value), 3)
            p.set_style(self.style)
            self.stats.keys.append(f"style={self.style:.2f}")
        elif action.kind == "pause":
            self._set_paused(not self.paused, wall)
            self.stats.keys.append("pause" if self.paused else "resume")
        elif action.kind == "reset":
            p.reset()
            p.set_style(self.style)
            self._started = False  # the stream restarts at 0 with the next audio
            self._audio_cursor = 0.0
            self._audio_debt = 0.0
            self.stats.keys.append("reset")
        elif action.kind == "label" and action.label is not None:
            p.trigger_label(action.label)
            self.stats.keys.append(f"label={action.label}")
        elif action.kind == "interest" and self.listening:
            listener = p.listener
            now = 0.5 if listener.interest is None else listener.interest   # None: x1 = 0.5
            listener.set_interest(round(now + action.value, 3))
            self.stats.keys.append(f"interest={listener.interest:.2f}")
        elif action.kind == "help":
            self.show_keys = not self.show_keys

    def _interest(self) -> float | None:
        """The listener's interest for the overlay (0.5 for the unscaled rule), or None."""
        if not self.listening:
            return None
        interest = self.pipeline.listener.interest
        return 0.5 if interest is None else float(interest)

    @property
    def listening(self) -> bool:
        """Whether the avatar listens with an interest dial (``live --listen``)."""
        return getattr(getattr(self.pipeline, "listener", None), "set_interest", None) is not None

    def _set_paused(self, paused: bool, wall: float) -> None:
        if paused == self.paused:
            return
        self.paused = paused
        self.feed.set_paused(paused)
        if paused:
            self._pause_started = wall
        elif self._pause_started is not None:
            dt = wall - self._pause_started
            self._base += dt
            self._feed_paused += dt
            self.stats.paused_s += dt
            self._pause_started = None

    def _handle_keys(self, wall: float) -> None:
        for action in self._pending_after_sync:
            self._apply(action, wall)
        self._pending_after_sync = []
        while True:
            try:
                key = self._keys.get_nowait()
            except queue.Empty:
                return
            action = decode_key(key, self.labels, self.listening)
            if action is None:
                continue
            if action.deferred:
                self._pending_after_sync.append(action)
            else:
                self._apply(action, wall)

    # ---------------------------------------------------------------- decoder workers
    def _take_keywords(self, hits: list[Any]) -> None:
        for hit in hits:
            self.keywords.append(hit)
            if hit.label in self.labels:
                self.pipeline.trigger_label(hit.label)

    def _keywords_report(self) -> dict[str, Any]:
        return {**self.spotter.stats.to_dict(), "hits": [
            {"word": k.word, "t_end": k.t_end, "t_emitted": k.t_emitted, "label": k.label}
            for k in self.keywords]}

    def _take_words(self, words: list[Any]) -> None:
        # t_emitted is the end of the audio pushed when a word was decided: past the audio of
        # this stream, the word was heard before a reset
        fresh = [w for w in words if w.t_emitted <= self._audio_cursor + 1e-3]
        self.words_stale += len(words) - len(fresh)
        if fresh:
            self.words_taken += int(self._push_words(fresh))
            self.heard.extend(fresh)

    def _words_report(self) -> dict[str, Any]:
        return {**self.words.stats.to_dict(), "taken": self.words_taken,
                "stale": self.words_stale,
                "heard": [{"text": w.text, "start_s": w.start_s, "end_s": w.end_s,
                           "t_emitted": w.t_emitted} for w in self.heard]}

    def _close_decoders(self) -> None:
        """Close every decoder worker (each, whatever the others do) and report them; once."""
        attached, self.decoders = self.decoders, []
        failed: list[Exception] = []
        for att in attached:
            try:
                att.worker.close()
                # what the worker found after the last frame's poll is counted in its
                # figures: taken here, so that the counters and the lists agree
                rest = att.worker.poll()
                if rest:
                    att.take(rest)
            except Exception as exc:  # noqa: BLE001 - the others are closed first
                failed.append(exc)
            self.stats.decoders[att.name] = att.report()
        if failed:
            raise failed[0]

    # ---------------------------------------------------------------- audio
    def _push_audio(self, blocks: list[AudioBlock], wall: float) -> None:
        """Re-stamp blocks onto the contiguous pipeline clock and push them."""
        for block in blocks:
            x = block.samples
            if self.paused:
                self.stats.audio_dropped_paused_s += len(x) / SAMPLE_RATE
                continue
            if self._audio_debt > 0:
                n_drop = min(len(x), int(round(self._audio_debt * SAMPLE_RATE)))
                x = x[n_drop:]
                self._audio_debt = 0.0 if n_drop == 0 else max(
                    self._audio_debt - n_drop / SAMPLE_RATE, 0.0)
                self.stats.audio_dropped_slip_s += n_drop / SAMPLE_RATE
                if len(x) == 0:
                    continue
            if not self._started:
                self._started = True
                self._base = wall - self._audio_cursor
            block_out = AudioBlock(x, self._audio_cursor)
            self.pipeline.push_audio(block_out)
            for att in self.decoders:
                att.worker.push(block_out)              # never blocks: a worker decodes
            self._audio_cursor += len(x) / SAMPLE_RATE
            self.stats.audio_pushed_s += len(x) / SAMPLE_RATE

    # ---------------------------------------------------------------- main
    def run(self) -> LiveStats:
        """Open the viewer, run until the window closes, Ctrl-C, ``duration`` or the end of
        the file; return the statistics (also written to ``options.stats_path``). The decoder
        workers are closed however it ends."""
        try:
            return self._run()
        finally:
            self._close_decoders()   # a no-op unless it failed before the loop's own clean-up

    def _run(self) -> LiveStats:
        opt, p = self.opt, self.pipeline
        model, data = self.model, self.data
        st = self.stats
        st.maxrss_start_mb = maxrss_mb()
        out = opt.out if opt.out is not None else sys.stdout
        if opt.print_keys and opt.headless:
            print("gesture-sim live --headless: no window; Ctrl-C to stop", file=out)
            print(f"audio: {self.feed.description}", file=out, flush=True)
        elif opt.print_keys:
            print("gesture-sim live - keys (in the viewer window):", file=out)
            for line in key_map_lines(self.labels, self.listening):
                print(f"  {line}", file=out)
            print(f"audio: {self.feed.description}", file=out, flush=True)
        if opt.shadow_size:
            model.vis.quality.shadowsize = int(min(model.vis.quality.shadowsize,
                                                   opt.shadow_size))
        p.set_style(self.style)
        factory = self._factory
        if factory is None and opt.headless:
            factory = HeadlessViewer.launch
        elif factory is None:
            leave_a_cpu_for_physics()
            import mujoco.viewer

            factory = mujoco.viewer.launch_passive
        shots = sorted((float(t), Path(pth)) for t, pth in opt.screenshots)
        taker = ScreenshotTaker(model, opt.screenshot_mode)
        old_sigint = None
        if threading.current_thread() is threading.main_thread():
            old_sigint = signal.signal(signal.SIGINT, self._on_sigint)
        before = set(threading.enumerate())
        viewer = None
        viewer_threads: set[threading.Thread] = set()
        pump: OverlayPump | NullPump | None = None
        stream = self.stream
        try:
            self.feed.start()
            viewer = factory(model, data, key_callback=self.key_callback,
                             show_left_ui=False, show_right_ui=False)
            viewer_threads = set(threading.enumerate()) - before
            setup_camera(viewer, model, data)
            if stream is not None:
                stream.prepare(model)    # its set-up before the loop, not in frame one
            pump = NullPump() if opt.headless else OverlayPump(viewer)
            # audio that arrived while the window opened is stale: drop it
            stale = self.feed.poll(0.0)
            st.audio_dropped_at_start_s = sum(len(b.samples) for b in stale) / SAMPLE_RATE
            with _start_up_heap_frozen(st):
                if stream is not None:
                    stream.start(model, data)    # its own thread and clock from here on
                self._loop(viewer, pump, taker, shots)
            if opt.final_screenshot is not None:
                taker.save(viewer, data, opt.final_screenshot)
                st.screenshots.append(str(opt.final_screenshot))
        finally:
            self._close_decoders()     # first: no worker outlives the loop
            if stream is not None:
                stream.stop()
            if pump is not None:
                pump.stop()
            self.feed.close()
            taker.close()
            if viewer is not None:
                with contextlib.suppress(Exception):
                    viewer.close()
            for th in viewer_threads:
                th.join(timeout=10.0)  # let GLFW shut down before the interpreter does
            if old_sigint is not None:
                signal.signal(signal.SIGINT, old_sigint)
            st.maxrss_end_mb = maxrss_mb()
            st.source = self.feed.stats()
            st.body = getattr(getattr(self.pipeline, "body", None), "name", "")
            if stream is not None:
                st.stream = stream.stats()
        if opt.stats_path is not None:
            atomic_write_text(opt.stats_path, json.dumps(st.to_dict(), indent=1) + "\n")
        return st

    def _on_sigint(self, signum: int, frame: Any) -> None:
        if self._stop_reason is not None:  # second Ctrl-C: stop now
            raise KeyboardInterrupt
        self.request_stop("interrupted (Ctrl-C)")

    def _should_stop(self, viewer: Any, wall: float, feed_t: float) -> bool:
        opt = self.opt
        # a SIGTERM/SIGINT whose raise Python dropped (it arrived inside a gc callback, say)
        # still ends the loop: the command line's handler recorded it
        interrupt.check()
        if self._stop_reason is not None:
            return True
        if self.stream is not None and self.stream.failed:
            self.request_stop(f"stream failed: no frame went out to {self.stream.address} "
                              f"({self.stream.sender.stats().get('last_error') or 'refused'})")
        elif not viewer.is_running():
            self.request_stop("window closed")
        elif opt.duration is not None and wall >= opt.duration:
            self.request_stop("duration reached")
        elif isinstance(self.feed, FileFeed) and opt.duration is None and not self.paused \
                and self.feed.finished(feed_t - opt.tail_s):
            self.request_stop("end of audio")
        return self._stop_reason is not None

    def _loop(self, viewer: Any, pump: OverlayPump | NullPump, taker: ScreenshotTaker,
              shots: list[tuple[float, Path]]) -> None:
        opt, p, st, data = self.opt, self.pipeline, self.stats, self.data
        frame_dt = 1.0 / opt.fps
        timestep = float(self.model.opt.timestep)
        t0 = self.clock()
        deadline = t0
        last_sync: float | None = None
        next_rss = 0.0
        recent_rt: deque[tuple[float, float]] = deque(maxlen=int(opt.fps) + 1)
        t_live = 0.0
        while True:
            wall = self.clock() - t0
            feed_t = wall - self._feed_paused - (
                wall - self._pause_started if self._pause_started is not None else 0.0)
            if self._should_stop(viewer, wall, feed_t):
                if self._stop_reason == "end of audio":
                    # the blocks that arrived since the last frame (a slow frame on a busy
                    # machine can span a few hundred ms): every sample of the file is pushed
                    self._push_audio(self.feed.poll(feed_t), wall)
                break
            work_start = self.clock()
            self._push_audio(self.feed.poll(feed_t), wall)
            for att in self.decoders:
                found = att.worker.poll()
                if found:
                    att.take(found)
            steps = 0
            if not self.paused:
                t_live = wall - self._base if self._started else 0.0
                t_before = float(data.time)
                lag = t_live - t_before
                if self._started and lag > opt.max_lag_s:
                    slip = lag - opt.max_lag_s  # give the excess up instead of catching up
                    self._base += slip
                    self._audio_debt += slip
                    st.slipped_s += slip
                    t_live -= slip
                p.advance(t_live)
                advanced = max(float(data.time) - t_before, 0.0)
                st.sim_s += advanced
                steps = int(round(advanced / timestep))
                st.steps.add(steps)
                if self._started:
                    st.lag.add(max(t_live - float(data.time), 0.0))
            if self.stream is not None:
                self.stream.publish(data)   # its thread sends it on the stream's own clock
            if not opt.headless:       # the overlay's texts: only for a window
                fields = _status_fields(p.status())
                recent_rt.append((wall, st.sim_s))
                realtime = 0.0
                if len(recent_rt) > 1 and recent_rt[-1][0] > recent_rt[0][0]:
                    realtime = (recent_rt[-1][1] - recent_rt[0][1]) / (recent_rt[-1][0]
                                                                       - recent_rt[0][0])
                pump.submit(viewer_texts(OverlayState(
                    t=float(data.time), level_db=fields["level_db"], state=fields["state"],
                    belief=fields["belief"], segment=fields["segment"],
                    style=self.style if fields["style"] is None else float(fields["style"]),
                    label=fields["label"], paused=self.paused, steps_per_frame=steps,
                    realtime=realtime, source=self.feed.description,
                    interest=self._interest(),
                ), self.labels, show_keys=self.show_keys, listening=self.listening))
            st.work_ms.add(1e3 * (self.clock() - work_start))
            viewer.sync()
            synced = self.clock()
            if last_sync is not None:
                st.frame_dt.add(synced - last_sync)
            last_sync = synced
            st.frames += 1
            self._handle_keys(synced - t0)
            while shots and float(data.time) >= shots[0][0]:
                _, path = shots.pop(0)
                taker.save(viewer, data, path)
                st.screenshots.append(str(path))
                last_sync = None  # a screenshot's pause is not a frame time
            if wall >= next_rss:
                st.sample_rss(wall)
                next_rss = wall + RSS_PERIOD_S
            deadline += frame_dt
            now = self.clock()
            if deadline < now - frame_dt:  # more than a frame late: restart the schedule
                deadline = now
            time.sleep(max(deadline - now, 0.0))
        end = self.clock()
        if self._pause_started is not None:
            st.paused_s += end - t0 - self._pause_started
        st.wall_s = end - t0
        st.exit_reason = self._stop_reason or ""


@contextlib.contextmanager
def _start_up_heap_frozen(stats: LiveStats):
    """Collect and freeze the start-up heap for the loop; time every collection inside it
    (``stats.gc_ms``, ms each); unfreeze at the end."""
    gc.collect()
    gc.freeze()
    stats.gc_frozen = gc.get_freeze_count()
    started: list[float] = []

    def timer(phase: str, info: dict) -> None:
        if phase == "start":
            started.append(time.perf_counter())
        elif started:
            stats.gc_ms.add(1e3 * (time.perf_counter() - started.pop()))

    gc.callbacks.append(timer)
    try:
        yield
    finally:
        gc.callbacks.remove(timer)
        gc.unfreeze()


def run_live(pipeline: Pipeline, feed: AudioFeed, options: LiveOptions | None = None,
             viewer_factory: Callable[..., Any] | None = None, spotter: Any = None,
             words: Any = None) -> LiveStats:
    """Run one live session (see :class:`LiveLoop`); returns its :class:`LiveStats` (with the
    keyword spotter's figures in ``stats.keywords`` and the live words' in ``stats.words``
    when they listen). The spotter and the word recogniser are closed whatever happens."""
    try:
        loop = LiveLoop(pipeline, feed, options, viewer_factory, spotter=spotter, words=words)
    except BaseException:
        for worker in (spotter, words):
            if worker is not None:
                worker.close()
        raise
    return loop.run()
