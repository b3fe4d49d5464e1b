"""Two simulated people in one scene, each with the role the audio gives it (Okwechime 2011).

    person p's own voice   -> its GesturePipeline (prosody, belief, controller, timing layer,
                              face and head signals): gestures while p speaks, rests otherwise
    the partner's voice    -> the same pipeline's listener (signals/listener.py): backchannels
                              (nods, brows, posture shifts) while p listens
    both pipelines' q*(t)  -> one MuJoCo scene of two free-standing PD + balance humanoids
                              (sim/scene.py), stepped together

Who speaks when comes from the audio: a stereo file (one channel per person), or a mono mix plus
a diarization (RTTM; each person's voice is the mix inside that person's turns), or live, the
microphone as the partner. Each person's roles follow from its own voice causally (the timing
layer rests the hands 0.4 s after its own speech stops, so a person who stops speaking comes to
rest first, and the listener never backchannels while its own voice is active); the turns are
kept for the timeline and the checks. Both pipelines are the single-person pipeline, unchanged.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gesture_sim.audio.sources import SILENCE_PEAK
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock, Turn
from gesture_sim.errors import GestureSimError
from gesture_sim.feed import feed
from gesture_sim.methods import method_spec
from gesture_sim.pipeline import GesturePipeline

#: Number of people in a conversation scene.
N_PEOPLE = 2


@dataclass
class ConversationRun:
    """A whole conversation through :class:`Conversation`.

    Attributes:
        conversation: the conversation after the run (its people's logs and traces).
        channels: (n, 2) float32 16 kHz, person p's own voice in column p.
        mix: (n,) the audio of the scene (what the video plays).
        turns: who spoke when (from the RTTM, or found in the channels).
        duration: seconds; wall: wall-clock seconds of the run; costs: seconds per stage and
            person (``"p0.physics"`` is the scene's physics, shared).
    """

    conversation: Conversation
    channels: np.ndarray
    mix: np.ndarray
    turns: list[Turn]
    duration: float
    wall: float
    costs: dict[str, float] = field(default_factory=dict)


class Conversation:
    """Two :class:`~gesture_sim.pipeline.GesturePipeline` people in one physics scene.

    Args:
        library, model, policy: as for the pipeline (one stack, shared by both people).
        method: the speakers' selection method (see :data:`~gesture_sim.methods.METHODS`).
        seeds: one seed per person (its choices, signals and physics noise).
        style: the style dial of both.
        physics: simulate the two bodies (False: targets only).
        distance: metres between the two people (:func:`~gesture_sim.sim.scene.
            conversation_model`).
        record: keep the traces and whole logs (False for the live loop).
        listener_model: both listeners' model (``"rule"`` or ``"okwechime"``,
            :func:`~gesture_sim.signals.listeners.make_listener`).
        interests: each listener's interest in 0..1 (None: the rule's own rates); person p's
            listener is ``interests[p]`` (:meth:`set_interest` changes it while running).
        **kwargs: passed to both pipelines.
    """

    def __init__(self, library, model, policy, *, method: str = "controller",
                 seeds: Sequence[int] = (0, 1), style: float = 0.5, physics: bool = True,
                 distance: float | None = None, record: bool = True, control_library=None,
                 graph=None, listener_model: str = "rule",
                 interests: Sequence[float | None] = (None, None), **kwargs) -> None:
        seeds = [int(s) for s in seeds]
        if len(seeds) != N_PEOPLE:
            raise GestureSimError(f"a conversation has {N_PEOPLE} people: give {N_PEOPLE} seeds")
        interests = list(interests)
        if len(interests) != N_PEOPLE:
            raise GestureSimError(f"interests: one per person ({N_PEOPLE})")
        self.people = [GesturePipeline(library, model, policy, method=method, seed=s,
                                       style=style, physics=False, record=record,
                                       control_library=control_library, graph=graph,
                                       listener=True, listener_model=listener_model,
                                       interest=interests[p], **kwargs)
                       for p, s in enumerate(seeds)]
        for p, person in enumerate(self.people):     # each voice is analysed once
            person.listen_to(self.people[1 - p])
        self.record = record
        self.scene = None
        from gesture_sim.sim.scene import DEFAULT_DISTANCE

        #: Metres between the two people.
        self.distance = DEFAULT_DISTANCE if distance is None else float(distance)
        if physics:
            from gesture_sim.sim.scene import SceneSim, conversation_model

            model_mj = conversation_model(self.distance)
            balance = None
            if self.people[0].legs == "clip":     # the COM follows the legs' weight shifts
                from gesture_sim.sim.tracking import BalanceGains

                balance = BalanceGains(follow_target=True)
            self.scene = SceneSim(model_mj, seeds=seeds, balance=balance)
        self.physics_s = 0.0
        self.reset()

    @classmethod
    def create(cls, library: str | Path | None = None, model: str | Path | None = None, *,
               method: str = "controller", show_progress: bool = False, **kwargs
               ) -> Conversation:
        """Load a library and model folder (defaults: the shipped ones) once for both people."""
        from gesture_sim.loading import load_stack

        spec = method_spec(method)
        stack = load_stack(library, model, policy=spec.policy, graph=spec.graph,
                           show_progress=show_progress)
        return cls(stack.library, stack.model, stack.policy, method=method,
                   control_library=stack.control_library, graph=stack.graph,
                   finger_tracks=stack.finger_tracks, **kwargs)

    def set_interest(self, person: int, interest: float) -> None:
        """Set person ``person``'s listener's interest (0..1) from now on (live keys)."""
        self.people[person]._layer("listener").listener.set_interest(interest)

    def reset(self, expected_s: float = 60.0) -> None:
        """Start a new stream at t = 0: both pipelines, and both bodies standing at rest
        (``expected_s``: how long the stream is expected to run, s, for the trace's buffers)."""
        for person in self.people:
            person.reset()
        if self.scene is not None:
            t0 = time.perf_counter()
            self.scene.reset([person.start_pose() for person in self.people])
            self.scene.begin_trace(record=self.record, expected_s=expected_s)
            self.physics_s = time.perf_counter() - t0

    @property
    def time(self) -> float:
        """Stream time of the latest control step both people have taken (s)."""
        return min(person.time for person in self.people)

    def expect(self, channels: np.ndarray) -> None:
        """Each person's whole voice, ``channels[:, p]``, known ahead (a file; see
        :meth:`~gesture_sim.pipeline.GesturePipeline.expect_audio`)."""
        for p, person in enumerate(self.people):
            person.expect_audio(channels[:, p])

    def push(self, blocks: Sequence[AudioBlock]) -> None:
        """One block of each person's own voice (``blocks[p]``, the same time span for all):
        both voices are analysed first, then each person steps (hearing the other)."""
        if len(blocks) != N_PEOPLE:
            raise GestureSimError(f"need {N_PEOPLE} audio blocks, got {len(blocks)}")
        for person, block in zip(self.people, blocks, strict=True):
            person.push_audio(block, run=False)
        for person in self.people:
            person.run_steps()

    def finish(self) -> None:
        """End of stream: every person's last syllable and steps."""
        for person in self.people:
            person.finish(run=False)
        for person in self.people:
            person.run_steps()

    def advance(self, t: float) -> None:
        """Step both bodies up to stream time ``t`` (s), each following its pipeline's q*."""
        if self.scene is None or not all(p.has_targets for p in self.people):
            return
        t0 = time.perf_counter()
        self.scene.advance_to(t, [person.targets.sample for person in self.people])
        self.physics_s += time.perf_counter() - t0

    def traces(self) -> list:
        """Each body's :class:`~gesture_sim.sim.trace.SimTrace` (single-person layout)."""
        if self.scene is None:
            raise GestureSimError("this conversation runs without physics")
        return self.scene.traces()


def conversation_channels(channels: np.ndarray | None = None, mono: np.ndarray | None = None,
                          turns: Sequence[Turn] | None = None) -> tuple[np.ndarray, list[Turn]]:
    """Each person's own voice, (n, 2) float32, and who spoke when.

    Give either ``channels`` (n, 2): one channel per person (the turns are found in them unless
    given), or ``mono`` (n,) with ``turns`` (a diarization): person p's voice is the mix inside
    p's turns (faded in and out over 10 ms).
    """
    from gesture_sim.audio import turns as tu

    if channels is not None:
        channels = np.asarray(channels, dtype=np.float32)
        if channels.ndim != 2 or channels.shape[1] != N_PEOPLE:
            raise GestureSimError(
                f"a conversation needs {N_PEOPLE} channels, one per person; got "
                f"{channels.shape[1] if channels.ndim == 2 else 1}")
        found = list(turns) if turns is not None else tu.turns_from_channels(channels)
        return channels, found
    if mono is None or turns is None:
        raise GestureSimError("a mono conversation needs a diarization (--rttm FILE)")
    mono = np.asarray(mono, dtype=np.float32).reshape(-1)
    voices = np.stack([tu.voice_of(mono, turns, p) for p in range(N_PEOPLE)], axis=1)
    return voices.astype(np.float32), list(turns)


def run_conversation(conversation: Conversation, channels: np.ndarray, turns: Sequence[Turn], *,
                     mix: np.ndarray | None = None, block_size: int = 160,
                     show_progress: bool = False) -> ConversationRun:
    """Feed two voices (``channels`` (n, 2)) through ``conversation`` block by block, in
    simulated real time (the one feed loop, :func:`gesture_sim.feed.feed`)."""
    channels = np.asarray(channels, dtype=np.float32)
    if len(channels) == 0:
        raise GestureSimError("no audio samples")
    if float(np.max(np.abs(channels))) < SILENCE_PEAK:
        raise GestureSimError("the conversation is silent; nothing to gesture to")
    mix = channels.sum(axis=1) if mix is None else np.asarray(mix, dtype=np.float32)
    conversation.reset(expected_s=len(channels) / SAMPLE_RATE + 1.0)
    wall = feed(conversation, channels, block_size=block_size, show_progress=show_progress)
    costs = {"physics": conversation.physics_s}
    for p, person in enumerate(conversation.people):
        for name, cost in person.costs.items():
            costs[f"p{p}.{name}"] = cost.seconds
    return ConversationRun(conversation=conversation, channels=channels, mix=mix,
                           turns=list(turns), duration=len(channels) / SAMPLE_RATE, wall=wall,
                           costs=costs)
