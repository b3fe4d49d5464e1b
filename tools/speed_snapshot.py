"""Save (or compare) what the pipeline computes on one take, for speed work that must not change it.

    .venv/bin/python tools/speed_snapshot.py save before.npz [AUDIO]
    .venv/bin/python tools/speed_snapshot.py compare before.npz [AUDIO]
    .venv/bin/python tools/speed_snapshot.py save-conv before_conv.npz      # the two-person scene
    GESTURE_SIM_DEFER=0 .venv/bin/python tools/speed_snapshot.py save ref.npz  # feed's physics
                                                                # deferral off (DEFER_PHYSICS_S)

Saved: every array of the physics :class:`~gesture_sim.sim.trace.SimTrace`, the prosody frames
(times, F0, intensity, silent, voice), the syllables (start, end, emission, F0, intensity) and the
control steps' targets. ``compare`` runs again and reports every array that is not equal
(NaN equal to NaN), exiting 1 if any.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

DEFAULT = Path(__file__).resolve().parents[1] / "tests" / "data" / "pipeline" / \
    "beat2_scott_0_2_2.wav"


def _trace_arrays(prefix: str, trace) -> dict[str, np.ndarray]:
    out = {}
    for k, v in vars(trace).items():
        if isinstance(v, np.ndarray):
            out[f"{prefix}trace.{k}"] = v
    return out


def _speech_arrays(prefix: str, pipe) -> dict[str, np.ndarray]:
    fr = pipe.tracker.frames()
    syl = pipe.log.syllables
    out = {f"{prefix}frames.times": fr.times, f"{prefix}frames.f0": fr.f0_hz,
           f"{prefix}frames.intensity": fr.intensity_db, f"{prefix}frames.silent": fr.silent,
           f"{prefix}frames.voice": np.asarray(fr.voice),
           f"{prefix}syllables": np.array(
               [(s.t_start, s.t_end, s.t_emitted, np.nan if s.f0_hz is None else s.f0_hz,
                 s.intensity_db) for s in syl]).reshape(-1, 5)}
    targets = getattr(pipe.log, "targets", None)
    if targets is not None and len(targets):
        out[f"{prefix}targets"] = np.asarray(targets)
    return out


def snapshot(audio: Path) -> dict[str, np.ndarray]:
    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method="controller", physics=True)
    run_file(pipe, audio)
    return {**_trace_arrays("", pipe.trace()), **_speech_arrays("", pipe)}


def snapshot_conversation() -> dict[str, np.ndarray]:
    from gesture_sim.conversation import Conversation, conversation_channels, run_conversation
    from gesture_sim.loading import load_stack
    from gesture_sim.testing.dialogue import make_dialogue

    voices, turns = conversation_channels(channels=make_dialogue(seed=0).channels)
    stack = load_stack(None, None, policy=True)
    conv = Conversation(stack.library, stack.model, stack.policy, physics=True,
                        control_library=stack.control_library)
    run_conversation(conv, voices, turns)
    out: dict[str, np.ndarray] = {}
    for k, pipe in enumerate(conv.people):
        out.update(_speech_arrays(f"p{k}.", pipe))
    for k, trace in enumerate(conv.traces()):
        out.update(_trace_arrays(f"p{k}.", trace))
    return out


def main(argv: list[str]) -> int:
    import os

    if "GESTURE_SIM_DEFER" in os.environ:
        import gesture_sim.feed

        gesture_sim.feed.DEFER_PHYSICS_S = float(os.environ["GESTURE_SIM_DEFER"])
    mode, path = argv[0], Path(argv[1])
    conv = mode.endswith("-conv")
    arrays = snapshot_conversation() if conv else snapshot(Path(argv[2]) if len(argv) > 2
                                                             else DEFAULT)
    if mode.startswith("save"):
        np.savez_compressed(path, **arrays)
        print(f"saved {len(arrays)} arrays to {path}")
        return 0
    ref = np.load(path)
    bad = [k for k in sorted(set(ref.files) | set(arrays))
           if k not in ref.files or k not in arrays
           or not np.array_equal(ref[k], arrays[k], equal_nan=ref[k].dtype.kind == "f")]
    for k in bad:
        print(f"DIFFERENT: {k}")
    print(f"{len(arrays) - len(bad)} of {len(arrays)} arrays equal")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
