"""``gesture-sim live --listen``: the avatar listens to the microphone (Okwechime's listener).

The live loop pushes every block it receives to its pipeline; :class:`ListeningPipeline` makes
that block the *partner's* speech (the human user talking to the avatar) and gives the avatar's
own voice as silence, so that the one causal pipeline runs unchanged: its timing layer keeps the
hands at rest (the avatar does not speak), and its listener layer
(:mod:`gesture_sim.signals.listener`) nods and raises the brows at the pauses the user's speech
invites. Everything else (viewer, overlay, keys, stats) is the pipeline's own.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gesture_sim.contracts import AudioBlock
from gesture_sim.errors import GestureSimError


class ListeningPipeline:
    """A :class:`~gesture_sim.pipeline.GesturePipeline` made with ``listener=True``, fed the
    partner's speech by :meth:`push_audio` (the avatar itself stays silent)."""

    def __init__(self, pipeline: Any) -> None:
        if getattr(pipeline, "listener", None) is None:
            raise GestureSimError("live --listen needs a pipeline made with listener=True")
        self.pipeline = pipeline

    def push_audio(self, block: AudioBlock) -> None:
        """The partner's block, then the same span of the avatar's own (silent) voice."""
        self.pipeline.push_partner_audio(block)
        self.pipeline.push_audio(AudioBlock(np.zeros(len(block.samples), np.float32),
                                            block.t_start))

    def __getattr__(self, name: str) -> Any:          # advance, status, data, model_mj, ...
        return getattr(self.pipeline, name)
