"""BVH reader: any channel layout and rotation order, End Sites, unit detection, vectorised FK.

Handles position channels on every joint (as in the Bandai Namco dataset: a joint's position
channels replace its OFFSET), any Euler order (intrinsic, in the order the channels are listed,
as the BVH convention has it), any frame rate, and lengths in metres, centimetres, millimetres or
inches (detected from the size of the rest skeleton). Malformed files raise a one-line
:class:`~gesture_sim.errors.GestureSimError`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.skeleton import SkeletonMotion, forward_kinematics

#: Candidate length units (metres per file unit) for detection from the skeleton's size.
#: 0.0254/0.45 is the "CMU unit" of the ASF/AMC-derived BVH conversions.
UNIT_CANDIDATES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.0254 / 0.45}
#: Expected size (m) of a human rest skeleton's largest extent, used for unit detection.
HUMAN_EXTENT_M = 1.7

_VALID_CHANNELS = {
    "Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation",
}


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str] = field(default_factory=list)
    channel_start: int = 0


class _Tokens:
    """A cursor over whitespace-separated tokens of the HIERARCHY section, with line numbers."""

    def __init__(self, lines: list[str], path: str) -> None:
        self.items: list[tuple[str, int]] = []
        for number, line in enumerate(lines, start=1):
            for tok in line.split():
                self.items.append((tok, number))
        self.pos = 0
        self.path = path

    def error(self, message: str) -> GestureSimError:
        line = self.items[min(self.pos, len(self.items) - 1)][1] if self.items else 0
        return GestureSimError(f"malformed BVH {self.path} (line {line}): {message}")

    def next(self, what: str) -> str:
        if self.pos >= len(self.items):
            raise self.error(f"unexpected end of HIERARCHY, expected {what}")
        tok = self.items[self.pos][0]
        self.pos += 1
        return tok

    def expect(self, value: str) -> None:
        tok = self.next(repr(value))
        if tok != value:
            self.pos -= 1
            raise self.error(f"expected {value!r}, found {tok!r}")

    def number(self, what: str) -> float:
        tok = self.next(what)
        try:
            return float(tok)
        except ValueError:
            self.pos -= 1
            raise self.error(f"expected a number for {what}, found {tok!r}") from None

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None


def _parse_hierarchy(tokens: _Tokens) -> list[_Joint]:
    """The joints in file order (each parent before its children), End Sites included.

    Iterative (a stack of the open joints), so a chain of any depth parses: no recursion limit.
    """
    joints: list[_Joint] = []
    n_channels = 0
    open_joints: list[tuple[int, str]] = []  # (index, name) of the joints whose '}' is pending
    lines: dict[str, int] = {}               # joint name -> the line that names it

    def finite(offset: np.ndarray, name: str) -> np.ndarray:
        if not np.all(np.isfinite(offset)):
            raise tokens.error(f"joint {name!r} has the OFFSET "
                               f"{' '.join(f'{x:g}' for x in offset)}; offsets must be finite")
        return offset

    def open_joint(parent: int) -> None:
        nonlocal n_channels
        name = tokens.next("a joint name")
        line = tokens.items[tokens.pos - 1][1]
        if name in lines:
            tokens.pos -= 1
            raise tokens.error(f"two joints are named {name!r} (lines {lines[name]} and "
                               f"{line}); every joint needs its own name (the motion is "
                               "mapped by name)")
        lines[name] = line
        tokens.expect("{")
        tokens.expect("OFFSET")
        offset = finite(np.array([tokens.number("OFFSET") for _ in range(3)]), name)
        tokens.expect("CHANNELS")
        count_tok = tokens.next("a channel count")
        try:
            count = int(count_tok)
        except ValueError:
            tokens.pos -= 1
            raise tokens.error(f"expected a channel count, found {count_tok!r}") from None
        channels = [tokens.next("a channel name") for _ in range(count)]
        for ch in channels:
            if ch not in _VALID_CHANNELS:
                raise tokens.error(f"unknown channel {ch!r} on joint {name!r}")
        open_joints.append((len(joints), name))
        joints.append(_Joint(name, parent, offset, channels, n_channels))
        n_channels += count

    tokens.expect("HIERARCHY")
    tokens.expect("ROOT")
    open_joint(-1)
    while open_joints:
        index, name = open_joints[-1]
        tok = tokens.peek()
        if tok == "JOINT":
            tokens.next("JOINT")
            open_joint(index)
        elif tok == "End":
            tokens.next("End")
            tokens.expect("Site")
            tokens.expect("{")
            tokens.expect("OFFSET")
            end_offset = finite(np.array([tokens.number("OFFSET") for _ in range(3)]),
                                f"{name}_End")
            tokens.expect("}")
            joints.append(_Joint(f"{name}_End", index, end_offset, [], n_channels))
        elif tok == "}":
            tokens.next("}")
            open_joints.pop()
        elif tok is None:
            raise tokens.error(f"unexpected end of HIERARCHY: joint {name!r} lacks its '}}'")
        else:
            raise tokens.error(f"expected JOINT, End Site or '}}', found {tok!r}")
    if tokens.peek() is not None:
        raise tokens.error(f"unexpected {tokens.peek()!r} after the ROOT joint (one root only)")
    return joints


def detect_unit_scale(rest_positions: np.ndarray) -> float:
    """Metres per file unit, chosen so that the rest skeleton's largest extent is human-sized.

    Args:
        rest_positions: (J, 3) rest-pose joint positions in file units.
    """
    extent = float(np.max(np.ptp(rest_positions, axis=0)))
    if not math.isfinite(extent) or extent <= 0:
        raise GestureSimError("cannot detect BVH units: the rest skeleton has zero size")
    return min(UNIT_CANDIDATES.values(),
               key=lambda s: abs(math.log(s * extent / HUMAN_EXTENT_M)))


def read_bvh(path: str | os.PathLike[str], unit_scale: float | None = None) -> SkeletonMotion:
    """Read a BVH file and compute global joint positions/rotations.

    Args:
        path: the .bvh file.
        unit_scale: metres per file unit; detected from the skeleton's size when ``None``.

    Returns:
        A :class:`SkeletonMotion` in the file's axes, lengths in metres.

    Raises:
        GestureSimError: the file is missing or malformed (one-line message).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise GestureSimError(f"cannot read BVH file {path}: {exc.strerror}") from exc
    lines = text.splitlines()
    motion_line = next((i for i, ln in enumerate(lines) if ln.strip() == "MOTION"), None)
    if not any(ln.strip() == "HIERARCHY" for ln in lines[: motion_line or len(lines)]):
        raise GestureSimError(f"malformed BVH {path}: no HIERARCHY section")
    if motion_line is None:
        raise GestureSimError(f"malformed BVH {path}: no MOTION section")
    joints = _parse_hierarchy(_Tokens(lines[:motion_line], str(path)))
    n_channels = sum(len(j.channels) for j in joints)

    header = {}
    cursor = motion_line + 1
    for key in ("Frames:", "Frame Time:"):
        while cursor < len(lines) and not lines[cursor].strip():
            cursor += 1
        if cursor >= len(lines) or not lines[cursor].strip().startswith(key):
            raise GestureSimError(f"malformed BVH {path} (line {cursor + 1}): expected {key!r}")
        value = lines[cursor].strip()[len(key):].strip()
        try:
            header[key] = float(value)
        except ValueError:
            raise GestureSimError(
                f"malformed BVH {path} (line {cursor + 1}): {key} {value!r} is not a number"
            ) from None
        cursor += 1
    n_frames = int(header["Frames:"])
    frame_time = header["Frame Time:"]
    if n_frames != header["Frames:"] or n_frames < 1:
        raise GestureSimError(f"malformed BVH {path}: Frames: must be a positive integer")
    if not frame_time > 0:
        raise GestureSimError(f"malformed BVH {path}: Frame Time must be positive")

    data_lines = [(i + 1, ln) for i, ln in enumerate(lines[cursor:], start=cursor) if ln.strip()]
    if len(data_lines) != n_frames:
        kind = "truncated motion" if len(data_lines) < n_frames else "frame count mismatch"
        raise GestureSimError(
            f"malformed BVH {path}: {kind}: header says {n_frames} frames, found {len(data_lines)}")
    rows = [ln.split() for _, ln in data_lines]
    for (number, _), row in zip(data_lines, rows, strict=True):
        if len(row) != n_channels:
            raise GestureSimError(
                f"malformed BVH {path} (line {number}): {len(row)} values, expected {n_channels} "
                "(wrong channel count)")
    try:
        values = np.array(rows, dtype=float)
    except ValueError:
        for (number, _), row in zip(data_lines, rows, strict=True):
            for tok in row:
                try:
                    float(tok)
                except ValueError:
                    raise GestureSimError(
                        f"malformed BVH {path} (line {number}): {tok!r} is not a number") from None
        raise
    if not np.all(np.isfinite(values)):
        raise GestureSimError(f"malformed BVH {path}: motion contains NaN or infinite values")
    fps = 1.0 / frame_time
    if abs(fps - round(fps)) < 1e-3 * fps:  # "0.0333333" means 30 fps
        fps = float(round(fps))
    return _build_motion(joints, values, fps, str(path), unit_scale)


def _build_motion(
    joints: list[_Joint], values: np.ndarray, fps: float, source: str, unit_scale: float | None,
) -> SkeletonMotion:
    n_frames, n_joints = values.shape[0], len(joints)
    parents = np.array([j.parent for j in joints], dtype=int)
    offsets = np.stack([j.offset for j in joints])
    translations = np.broadcast_to(offsets, (n_frames, n_joints, 3)).copy()
    local = np.broadcast_to(np.eye(3), (n_frames, n_joints, 3, 3)).copy()
    for j, joint in enumerate(joints):
        rot_axes = ""
        rot_cols = []
        for k, ch in enumerate(joint.channels):
            col = joint.channel_start + k
            if ch.endswith("position"):
                translations[:, j, "XYZ".index(ch[0])] = values[:, col]
            else:
                rot_axes += ch[0]
                rot_cols.append(col)
        if rot_axes:
            if len(set(rot_axes)) != len(rot_axes):
                raise GestureSimError(f"malformed BVH {source}: repeated rotation channel on "
                                      f"joint {joint.name!r}")
            local[:, j] = Rotation.from_euler(
                rot_axes.upper(), values[:, rot_cols], degrees=True).as_matrix()
    if unit_scale is None:
        rest, _ = forward_kinematics(parents, offsets[None], np.eye(3)[None, None].repeat(
            n_joints, axis=1))
        unit_scale = detect_unit_scale(rest[0])
    translations *= unit_scale
    positions, rotations = forward_kinematics(parents, translations, local)
    return SkeletonMotion(
        names=tuple(j.name for j in joints), parents=parents, offsets=offsets * unit_scale,
        local_rotations=local, positions=positions, rotations=rotations, fps=float(fps),
        source=source, unit_scale=float(unit_scale),
    )
