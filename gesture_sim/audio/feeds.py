"""Live audio feeds: non-blocking sources of :class:`~gesture_sim.contracts.AudioBlock` s that
a real-time loop polls once per frame.

:class:`MicrophoneFeed` drains a :class:`~gesture_sim.audio.sources.MicrophoneSource` on a pump
thread into a bounded queue (PortAudio's callback only fills a ring buffer);
:class:`FileFeed` plays a file through the live path, paced by the caller's feed clock, and
optionally to the speakers. Both satisfy :class:`AudioFeed`.
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from gesture_sim.audio.sources import DEFAULT_BLOCK_SIZE, FileSource, MicrophoneSource
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.errors import GestureSimError


class AudioFeed(Protocol):
    """A live audio source polled once per frame with the feed clock ``t_feed`` (s: wall time
    since the loop started, pauses excluded); a microphone ignores it, a file is paced by it."""

    description: str

    def start(self) -> None: ...
    def poll(self, t_feed: float) -> list[AudioBlock]: ...
    def set_paused(self, paused: bool) -> None: ...
    def stats(self) -> dict[str, float]: ...
    def close(self) -> None: ...


class MicrophoneFeed:
    """A :class:`MicrophoneSource` drained by a pump thread into a bounded queue.

    Args:
        source: the microphone (or a fake device through its ``stream_factory``).
        max_queue_s: audio (s) the queue holds before the oldest blocks are dropped (counted).

    :meth:`poll` returns every block that has arrived, in order, without waiting. The blocks'
    ``t_start`` is the microphone's stream time (delivered samples / 16 kHz).
    """

    def __init__(self, source: MicrophoneSource, max_queue_s: float = 2.0) -> None:
        self.source = source
        name = source.device_info["name"] if source.device_info else "input device"
        self.description = f"microphone: {name}"
        self._q: queue.Queue[AudioBlock] = queue.Queue(
            maxsize=max(4, int(max_queue_s * SAMPLE_RATE / source.block_size)))
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.queue_dropped_s = 0.0
        self.ended = False

    def start(self) -> None:
        """Open the input stream (errors surface here, as :class:`GestureSimError`)."""
        self.source.start()
        self._thread = threading.Thread(target=self._pump, name="gesture-sim-audio",
                                        daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        try:
            for block in self.source:
                while True:
                    try:
                        self._q.put_nowait(block)
                        break
                    except queue.Full:
                        with contextlib.suppress(queue.Empty):
                            old = self._q.get_nowait()
                            self.queue_dropped_s += len(old.samples) / SAMPLE_RATE
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread by poll()
            self._error = exc
        finally:
            self.ended = True

    def poll(self, t_feed: float) -> list[AudioBlock]:
        """Every block that has arrived since the last call (``t_feed`` is not used)."""
        if self._error is not None:
            err, self._error = self._error, None
            if isinstance(err, GestureSimError):
                raise err
            raise GestureSimError(f"the audio input failed: {err}") from err
        out: list[AudioBlock] = []
        while True:
            try:
                out.append(self._q.get_nowait())
            except queue.Empty:
                return out

    def set_paused(self, paused: bool) -> None:
        """The microphone keeps running; the loop drops what arrives while paused."""

    def stats(self) -> dict[str, float]:
        """PortAudio overflow events, ring-buffer drops and queue drops."""
        s = dict(self.source.stats())
        s["queue_dropped_s"] = round(self.queue_dropped_s, 4)
        return s

    def close(self) -> None:
        """Stop and close the input stream and the pump thread."""
        self.source.stop()
        if self._thread is not None:
            self._thread.join(timeout=2.0)


class FileFeed:
    """An audio file played through the live path, paced by the feed clock.

    ``poll(t_feed)`` returns the 10 ms blocks whose end lies at or before ``t_feed`` (so
    pausing the clock pauses the file). After the end the file repeats (``loop``) or silence
    follows. With ``speakers`` the samples also go to the default output device through a
    sounddevice ``OutputStream`` (silence while paused); without an output device the feed
    plays silently.

    Args:
        path: any file :func:`~gesture_sim.audio.sources.load_audio` reads.
        loop: repeat the file.
        speakers: try to play it to the default output device.
        block_size: samples per block (16 kHz).

    The file is read and converted by :class:`~gesture_sim.audio.sources.FileSource` (errors
    surface on construction); this feed adds the pacing, looping and speaker output.
    """

    def __init__(self, path: str | Path, loop: bool = False, speakers: bool = True,
                 block_size: int = DEFAULT_BLOCK_SIZE) -> None:
        self.source = FileSource(path, block_size)
        self.samples, self.info = self.source.samples, self.source.info
        self.path = Path(path)
        self.loop = loop
        self.block_size = self.source.block_size
        self.want_speakers = speakers
        self.description = f"file: {self.path.name}"
        self._next = 0  # next sample index on the live clock (may exceed len when looping)
        self._out: Any = None
        self._play = 0
        self._paused = False
        self.output_device: str | None = None
        self.output_underflows = 0

    @property
    def duration(self) -> float:
        """Duration of the file (s)."""
        return self.source.duration

    def finished(self, t_feed: float) -> bool:
        """Whether the file has been played through (never when looping)."""
        return not self.loop and t_feed >= self.duration

    def start(self) -> None:
        """Open the speaker stream when there is an output device (silently skip otherwise)."""
        if not self.want_speakers:
            return
        try:
            import sounddevice as sd

            dev = sd.query_devices(kind="output")
            stream = sd.OutputStream(samplerate=SAMPLE_RATE, channels=1, dtype="float32",
                                     callback=self._out_callback)
            stream.start()
        except Exception:  # noqa: BLE001 - no PortAudio, no output device, busy: play silently
            return
        self._out = stream
        self.output_device = str(dev.get("name", "default")) if isinstance(dev, dict) else "default"
        self.description += " (speakers)"

    def _out_callback(self, outdata: np.ndarray, frames: int, time_info: Any,
                      status: Any) -> None:
        if status is not None and getattr(status, "output_underflow", False):
            self.output_underflows += 1
        outdata[:, 0] = self._slice(self._play, frames) if not self._paused else 0.0
        if not self._paused:
            self._play += frames

    def _slice(self, i0: int, n: int) -> np.ndarray:
        """Samples [i0, i0 + n) of the (looped or silence-padded) stream, float32 (n,)."""
        total = len(self.samples)
        if self.loop:
            idx = np.arange(i0, i0 + n) % total
            return self.samples[idx]
        out = np.zeros(n, dtype=np.float32)
        if i0 < total:
            k = min(n, total - i0)
            out[:k] = self.samples[i0 : i0 + k]
        return out

    def poll(self, t_feed: float) -> list[AudioBlock]:
        """The blocks whose end is at or before ``t_feed`` (s on the feed clock: wall time
        since the loop started, pauses excluded)."""
        end = int(math.floor(t_feed * SAMPLE_RATE + 1e-6))
        out = []
        b = self.block_size
        while self._next + b <= end:
            out.append(AudioBlock(self._slice(self._next, b), self._next / SAMPLE_RATE))
            self._next += b
        return out

    def set_paused(self, paused: bool) -> None:
        """Pause the speaker output (the live clock pauses the blocks)."""
        self._paused = paused

    def stats(self) -> dict[str, float]:
        """Output underflows (0 when there are no speakers)."""
        return {"overflow_events": 0, "dropped_samples": 0, "dropped_s": 0.0,
                "output_underflows": self.output_underflows,
                "speakers": self._out is not None}

    def close(self) -> None:
        """Stop the speaker stream."""
        if self._out is not None:
            with contextlib.suppress(Exception):
                self._out.stop()
                self._out.close()
            self._out = None
