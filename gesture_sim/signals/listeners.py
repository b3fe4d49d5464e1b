"""The listener factory: the pause rule (:mod:`gesture_sim.signals.listener`) or the
audio-driven listener (:mod:`gesture_sim.signals.listener_audio`) by name.

It sits beside both so that neither imports the other's subclass (no file-level cycle).
"""

from __future__ import annotations

from gesture_sim.errors import GestureSimError
from gesture_sim.signals.listener import LISTENER_MODELS, ListenerConfig, ListenerSignals
from gesture_sim.signals.listener_audio import AudioListener

__all__ = ["make_listener"]


def make_listener(model: str = "rule", seed: int = 0, interest: float | None = None, *,
                  config: ListenerConfig | None = None, tendencies=None, audio_model=None,
                  audio_motion: str | None = None, graph=None, posture: bool = True):
    """A listener with the :class:`~gesture_sim.signals.listener.ListenerSignals` interface
    (``reset``, ``push_frames``, ``step``, ``backchannels``, ``cues``, ``events``).

    Args:
        model: ``"rule"`` (:class:`~gesture_sim.signals.listener.ListenerSignals`, the
            prosodic rule) or ``"okwechime"``
            (:class:`~gesture_sim.signals.listener_audio.AudioListener`: MFCC classes of the
            partner's voice -> listener motion states; it also needs the partner's samples,
            :meth:`~gesture_sim.signals.listener_audio.AudioListener.push_audio`).
        seed: the listener's seed. interest: None or 0..1 (module docstring).
        config: the rule's settings (both models use its motion settings).
        tendencies: the interest tables (default: Table 5.4 around the base rates).
        audio_model: an :class:`~gesture_sim.signals.listener_audio.AudioListenerModel`
            (``"okwechime"`` only; default: the fallback model on the bundled speech).
        audio_motion: ``"okwechime"``'s motion, ``"graph"`` (real excerpts of the library),
            ``"envelope"`` (the rule's nod and lean envelopes) or None (the graph when it has
            every state; :mod:`~gesture_sim.signals.listener_audio`). graph: its
            :class:`~gesture_sim.signals.listener_graph.ListenerGraph` (default: the shipped
            library's).
        posture: ``"rule"``: the listening posture (head lift, eyes on the partner;
            :class:`~gesture_sim.signals.listener.ListenerSignals`).

    Raises:
        GestureSimError: an unknown model.
    """
    if model == "rule":
        return ListenerSignals(config, seed=seed, interest=interest, tendencies=tendencies,
                               posture=posture)
    if model == "okwechime":
        return AudioListener(audio_model, seed=seed, interest=interest, config=config,
                             tendencies=tendencies, motion=audio_motion, graph=graph)
    raise GestureSimError(f"unknown listener model {model!r} (choose from "
                          f"{', '.join(LISTENER_MODELS)})")
