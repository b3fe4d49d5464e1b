"""Overlays and key map of the live viewer: pure functions, testable without a display.

The live viewer (:mod:`gesture_sim.app.live`) shows, over the 3-D view, text boxes drawn by
MuJoCo's ``Handle.set_texts`` (MuJoCo ≥ 3.3): the input level as a bar, the current hidden state
and its probability, the playing segment, the style dial, a pending semantic label, the pause
indicator, loop timing, and the key map. This module builds those texts and decodes GLFW key
codes into :class:`KeyAction` s; it imports MuJoCo only for the grid-position constants.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

#: Level-bar range (dB): the bar is empty at or below the floor and full at or above the top.
LEVEL_FLOOR_DB = -60.0
LEVEL_TOP_DB = 0.0
#: Characters in the level and belief bars (the viewer's font is ASCII only).
BAR_WIDTH = 24
#: Style-dial step per key press.
STYLE_STEP = 0.1
#: Listener-interest step per key press (0 bored … 1 interested; Okwechime 2011's dial).
INTEREST_STEP = 0.1

# GLFW key codes (glfw3.h); the passive viewer's key_callback receives these.
KEY_SPACE = 32
KEY_MINUS = 45
KEY_LEFT_BRACKET = 91
KEY_RIGHT_BRACKET = 93
KEY_EQUAL = 61
KEY_0 = 48
KEY_H = 72
KEY_R = 82
KEY_BACKSPACE = 259
KEY_RIGHT = 262
KEY_LEFT = 263
KEY_DOWN = 264
KEY_UP = 265
KEY_KP_1 = 321
KEY_KP_SUBTRACT = 333
KEY_KP_ADD = 334
#: Semantic gestures are bound to the number keys 1 … 9 (and the keypad's).
MAX_LABEL_KEYS = 9


@dataclass(frozen=True)
class KeyAction:
    """What a key press asks the live loop to do.

    Attributes:
        kind: ``"style"`` (change the dial by ``value``), ``"interest"`` (change the
            listener's interest by ``value``), ``"pause"`` (toggle), ``"reset"``, ``"label"``
            (trigger the semantic gesture ``label``) or ``"help"`` (toggle the key map
            overlay).
        value: style or interest change (dial units, 0 … 1 scale).
        label: the semantic label for ``"label"``.
        deferred: the viewer itself also acts on this key at its next ``sync()`` (MuJoCo's
            simulate resets ``MjData`` on Backspace), so the loop must act *after* that sync.
    """

    kind: str
    value: float = 0.0
    label: str | None = None
    deferred: bool = False


def decode_key(key: int, labels: tuple[str, ...] | list[str],
               listening: bool = False) -> KeyAction | None:
    """Map a GLFW key code to a :class:`KeyAction` (``None`` for keys the loop ignores).

    ``+``/``=``/Up/Right raise the style dial, ``-``/Down/Left lower it, Space pauses,
    ``R`` or Backspace resets, ``H`` toggles the key map, and the number keys 1 … 9 trigger
    ``labels[0]`` … ``labels[8]``; with ``listening`` (an avatar that listens), ``]`` and
    ``[`` make the listener more and less interested.
    """
    if listening and key in (KEY_RIGHT_BRACKET, KEY_LEFT_BRACKET):
        return KeyAction("interest", INTEREST_STEP if key == KEY_RIGHT_BRACKET
                         else -INTEREST_STEP)
    if key in (KEY_EQUAL, KEY_UP, KEY_RIGHT, KEY_KP_ADD):
        return KeyAction("style", STYLE_STEP)
    if key in (KEY_MINUS, KEY_DOWN, KEY_LEFT, KEY_KP_SUBTRACT):
        return KeyAction("style", -STYLE_STEP)
    if key == KEY_SPACE:
        return KeyAction("pause")
    if key == KEY_R:
        return KeyAction("reset")
    if key == KEY_BACKSPACE:
        return KeyAction("reset", deferred=True)
    if key == KEY_H:
        return KeyAction("help")
    for base in (KEY_0, KEY_KP_1 - 1):
        i = key - base - 1
        if 0 <= i < min(len(labels), MAX_LABEL_KEYS):
            return KeyAction("label", label=labels[i])
    return None


#: The keys that do not depend on the library, and the last line of the key map.
GENERAL_KEYS = (
    "+ / Up     style: more energetic",
    "- / Down   style: calmer",
    "Space      pause / resume",
    "R / Bksp   reset the body and controller",
    "H          show / hide this key map",
)
QUIT_LINE = "close window or Ctrl-C to quit"
#: The key-map line of the listener's interest (shown when the avatar listens).
INTEREST_LINE = "] / [      listener: more / less interested"


def key_map_lines(labels: tuple[str, ...] | list[str], listening: bool = False) -> list[str]:
    """The key map, one line per binding (printed at start and shown in the viewer)."""
    lines = [*GENERAL_KEYS, *([INTEREST_LINE] if listening else [])]
    for i, lab in enumerate(list(labels)[:MAX_LABEL_KEYS]):
        lines.append(f"{i + 1:<10} gesture: {lab}")
    lines.append(QUIT_LINE)
    return lines


def bar(fraction: float, width: int = BAR_WIDTH) -> str:
    """An ASCII bar ``[#####.....]`` filled to ``fraction`` (clipped to 0 … 1)."""
    f = 0.0 if not np.isfinite(fraction) else min(max(float(fraction), 0.0), 1.0)
    n = int(round(f * width))
    return "[" + "#" * n + "." * (width - n) + "]"


def level_fraction(level_db: float | None) -> float:
    """Bar fill for an input level (dB re full scale): 0 at :data:`LEVEL_FLOOR_DB`, 1 at
    :data:`LEVEL_TOP_DB`, linear in dB between; 0 for ``None`` / non-finite."""
    if level_db is None or not np.isfinite(level_db):
        return 0.0
    return min(max((level_db - LEVEL_FLOOR_DB) / (LEVEL_TOP_DB - LEVEL_FLOOR_DB), 0.0), 1.0)


@dataclass
class OverlayState:
    """Everything the overlay shows for one frame.

    Attributes:
        t: stream time of the physics (s).
        level_db: input level of the latest audio (dB re full scale), or ``None``.
        state: argmax hidden state, or ``None`` before the first belief.
        belief: shape (S,), the belief over hidden states, or ``None``.
        segment: name or id of the playing segment, or ``None``.
        style: the style dial, 0 (calm) … 1 (energetic).
        label: a pending semantic label, or ``None``.
        paused: whether the loop is paused.
        steps_per_frame: physics steps taken in the last frame.
        realtime: simulated / wall time over the last second (1.0 = real time).
        source: a short description of the audio source.
        interest: the listener's interest (0 … 1) when the avatar listens with a dial, else
            ``None`` (no row).
    """

    t: float = 0.0
    level_db: float | None = None
    state: int | None = None
    belief: np.ndarray | None = None
    segment: Any = None
    style: float = 0.5
    label: str | None = None
    paused: bool = False
    steps_per_frame: int = 0
    realtime: float = 1.0
    source: str = ""
    interest: float | None = None


def status_lines(s: OverlayState) -> tuple[str, str]:
    """The main overlay box as (left column, right column), lines joined by newlines."""
    level = "-inf" if s.level_db is None or not np.isfinite(s.level_db) else f"{s.level_db:.0f}"
    left = ["input", "state", "segment", "style", "gesture", "time"]
    right = [
        f"{bar(level_fraction(s.level_db))} {level} dB",
        _state_text(s.state, s.belief),
        "-" if s.segment is None else str(s.segment),
        f"{bar(s.style)} {s.style:.2f}",
        s.label or "-",
        f"{s.t:7.2f} s  {s.steps_per_frame:3d} steps/frame  {100 * s.realtime:4.0f}% real time",
    ]
    if s.interest is not None:
        left.insert(4, "interest")
        right.insert(4, f"{bar(s.interest)} {s.interest:.2f}")
    if s.paused:
        left.insert(0, "PAUSED")
        right.insert(0, "press Space to resume")
    if s.source:
        left.append("source")
        right.append(s.source)
    return "\n".join(left), "\n".join(right)


def _state_text(state: int | None, belief: np.ndarray | None) -> str:
    if state is None:
        return "-"
    if belief is None or len(belief) == 0:
        return str(state)
    p = float(belief[state]) if 0 <= state < len(belief) else float("nan")
    return f"{state:<3d}{bar(p, 12)} p={p:.2f}"


def viewer_texts(s: OverlayState, labels: tuple[str, ...] | list[str],
                 show_keys: bool = True, listening: bool = False,
                 ) -> list[tuple[Any, Any, str, str]]:
    """The ``Handle.set_texts`` argument: status box top-left; with ``show_keys`` the keys
    bottom-left and the numbered semantic gestures bottom-right."""
    left, right = status_lines(s)
    texts: list[tuple[Any, Any, str, str]] = [
        (mujoco.mjtFontScale.mjFONTSCALE_150, mujoco.mjtGridPos.mjGRID_TOPLEFT, left, right),
    ]
    if show_keys:
        n_lab = min(len(labels), MAX_LABEL_KEYS)
        cols = [_key_col(ln) for ln in (*GENERAL_KEYS,
                                         *([INTEREST_LINE] if listening else []), QUIT_LINE)]
        texts.append((mujoco.mjtFontScale.mjFONTSCALE_100, mujoco.mjtGridPos.mjGRID_BOTTOMLEFT,
                      "\n".join(k for k, _ in cols), "\n".join(v for _, v in cols)))
        if n_lab:
            texts.append((mujoco.mjtFontScale.mjFONTSCALE_100,
                          mujoco.mjtGridPos.mjGRID_BOTTOMRIGHT,
                          "\n".join(str(i + 1) for i in range(n_lab)),
                          "\n".join(labels[:n_lab])))
    else:
        texts.append((mujoco.mjtFontScale.mjFONTSCALE_100, mujoco.mjtGridPos.mjGRID_BOTTOMLEFT,
                      "H", "key map"))
    return texts


def _key_col(line: str) -> tuple[str, str]:
    """Split a key-map line into (keys, meaning) at the first run of two spaces."""
    i = line.find("  ")
    if i < 0:
        return "", line
    return line[:i].strip(), line[i:].strip()
