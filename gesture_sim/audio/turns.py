"""Who speaks when: the turns of a two-person conversation (:class:`~gesture_sim.contracts.Turn`).

Three sources give the roles:

* a **stereo file**, one channel per person (headset or lapel microphones):
  :func:`load_channels` reads every channel (16 kHz float32), :func:`turns_from_channels` finds
  each person's speech with a per-channel voice activity detector that ignores the partner's
  voice leaking into a microphone;
* a **mono file plus a diarization** in RTTM (the format pyannote and other diarization tools
  write): :func:`read_rttm` / :func:`write_rttm`, and :func:`voice_of` to cut one person's voice
  out of the mix with :func:`speaking_mask`;
* **live**: the microphone is the partner (the caller builds the turns as the stream goes).

:func:`role_at` says whether a person is ``"speaking"`` or ``"listening"`` at a time and
:func:`check_turns` refuses turns that do not fit the audio they go with.

Times are seconds on the audio's clock, levels dB (dBFS for absolute ones, where full scale
is 1.0); arrays are float32 at :data:`~gesture_sim.contracts.SAMPLE_RATE` (16 kHz). User errors
(a bad RTTM line, an unreadable file) raise a one-line
:class:`~gesture_sim.errors.GestureSimError` that names the file and, where there is one, the line.
"""

from __future__ import annotations

import math
import re
import subprocess
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from gesture_sim.audio.sources import (
    check_audio_file,
    is_wav,
    read_wav_checked,
    resample_to_16k,
    to_float_mono,
)
from gesture_sim.contracts import SAMPLE_RATE, Turn
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_write_text

__all__ = [
    "check_turns", "load_channels", "read_rttm", "role_at", "speaking_mask", "turns_from_channels",
    "voice_of", "write_rttm",
]

# --------------------------------------------------------------------------------------------
# Voice activity thresholds (turns_from_channels)
# --------------------------------------------------------------------------------------------

#: Analysis frame step (s): one level per 10 ms, the resolution of the turn boundaries.
FRAME_STEP_S = 0.01
#: Analysis window (s), centred on its frame step.
FRAME_WINDOW_S = 0.025
#: High-pass corner (Hz) applied before the levels: removes DC and rumble (handling, hum).
HIGHPASS_HZ = 80.0
#: Frame levels are clipped below this (dBFS); a channel whose speech level is not above it
#: is digital silence and has no turns.
SILENCE_DB = -100.0
#: Percentile (%) of a channel's loud frame levels (those at least ON_ABOVE_NOISE_DB above its
#: noise floor) taken as its speech level: the channel's own reference, so every threshold
#: below is relative and a quieter channel gives the same turns. Taken over the loud frames
#: only, it does not depend on how much of the recording the person speaks.
SPEECH_PERCENTILE = 95.0
#: Percentile (%) of a channel's frame levels taken as its noise floor; frames of digital
#: silence (at SILENCE_DB: muted or zero-padded stretches) are left out of it.
NOISE_PERCENTILE = 10.0
#: A channel whose speech level is less than this (dB) above its noise floor holds no speech
#: (stationary noise, a constant tone, or an unplugged microphone's hiss).
MIN_RANGE_DB = 10.0
#: A frame enters speech when it is within this many dB of the channel's speech level ...
ON_BELOW_SPEECH_DB = 35.0
#: ... and at least this many dB above the channel's noise floor.
ON_ABOVE_NOISE_DB = 10.0
#: Hysteresis (dB): once in speech, a frame stays in speech down to the entry threshold minus
#: this ...
HYSTERESIS_DB = 6.0
#: ... but never closer than this (dB) to the noise floor.
OFF_ABOVE_NOISE_DB = 3.0
#: Dominance (dB): a frame is person p's speech only if channel p, relative to its own speech
#: level, is not this much or more below an active other channel (relative to that one's).
CROSSTALK_DB = 15.0
#: Frames of the other channel used to measure the leakage (coupling) of its voice into
#: channel p: those within this many dB of its speech level (its loud frames).
COUPLING_LOUD_DB = 10.0
#: Percentile (%) of (level_p - level_q) over q's loud frames in which q is the louder channel
#: (dB, raw levels) taken as the coupling q -> p (dB): low, so that p's own speech during q's
#: (overlap) does not raise it. Frames where p is louder are p's voice leaking into q, not q's.
COUPLING_PERCENTILE = 10.0
#: A frame of p while q is active is p's own speech only if p is at least this many dB louder
#: than q's leakage alone would make it (coupling + margin); this is what keeps a channel that
#: holds only the partner's leakage from becoming a second speaker.
LEAK_MARGIN_DB = 6.0
#: Fewest loud frames of q (10 ms each) needed to measure a coupling; with fewer, no leak rule.
MIN_COUPLING_FRAMES = 20
#: Speech gaps shorter than this (s) within a person's speech are bridged (pauses between
#: syllables and words belong to the turn).
BRIDGE_S = 0.3
#: Stretches of speech shorter than this (s) after bridging are dropped (clicks, blips).
MIN_TURN_S = 0.1


# --------------------------------------------------------------------------------------------
# RTTM
# --------------------------------------------------------------------------------------------

#: Fields of a SPEAKER line up to the speaker name (type file chan onset dur NA NA name).
_RTTM_MIN_FIELDS = 8


def _read_lines(p: Path) -> list[str]:
    """The text lines of ``p`` (UTF-8, a BOM tolerated); one-line errors naming the file."""
    if p.is_dir():
        raise GestureSimError(f"{p}: is a folder, not an RTTM file")
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise GestureSimError(f"{p}: cannot read RTTM file ({e.strerror or e})") from None
    lines = raw.split(b"\n")
    if lines and not lines[-1]:
        lines.pop()  # the newline that ends the last line starts no line
    out: list[str] = []
    for i, b in enumerate(lines, start=1):
        try:
            text = b.decode("utf-8-sig" if i == 1 else "utf-8")
        except UnicodeDecodeError:
            raise GestureSimError(
                f"{p}:{i}: not an RTTM text file (line {i} is not UTF-8 text)") from None
        if "\x00" in text:
            raise GestureSimError(f"{p}:{i}: not an RTTM text file (binary data on line {i})")
        out.append(text.rstrip("\r"))
    return out


def _short(token: str, limit: int = 24) -> str:
    """A field of the file as a message may quote it: at most ``limit`` characters (a
    300-digit number is shown by its start and its length)."""
    if len(token) <= limit:
        return token
    return f"{token[:limit]}… ({len(token)} characters)"


def _secs(x: float) -> str:
    """Seconds for a message: 3 decimals, or 6 significant digits for huge values."""
    return f"{x:.3f}" if abs(x) < 1e7 else f"{x:.6g}"


def read_rttm(path: str | Path, n_persons: int = 2) -> tuple[list[Turn], tuple[str, ...]]:
    """Read a diarization in RTTM: the turns (s) and the speaker names.

    SPEAKER lines are ``SPEAKER <file> <chan> <onset> <dur> <NA> <NA> <name> <NA> <NA>``
    (onset and duration in s; fields after the name are optional and extra ones tolerated).
    Blank lines and ``#`` comments are skipped, other record types (``SPKR-INFO``, ``LEXEME``,
    ...) ignored. Persons are numbered 0, 1, ... by first appearance in time (segments sorted by
    onset, ties in file order) and ``names[person]`` is the speaker's name in the file.
    Overlapping or touching segments of one speaker are merged; overlap between persons is
    kept (people talk over each other).

    Returns:
        (turns sorted by ``t_start`` then person, names) with ``len(names) <= n_persons``.

    Raises:
        GestureSimError: unreadable file; a SPEAKER line with too few fields, an onset or
            duration that is not a finite number, a negative onset or a duration that is not
            positive; more than ``n_persons`` speakers; SPEAKER lines of more than one file id;
            no SPEAKER line at all. The message names the file and the line.
    """
    p = Path(path)
    lines = _read_lines(p)
    segments: list[tuple[float, float, int, str]] = []  # (onset, end, line number, name)
    file_id: tuple[str, int] | None = None
    for i, line in enumerate(lines, start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#") or fields[0].upper() != "SPEAKER":
            continue
        where = f"{p}:{i}"
        if len(fields) < _RTTM_MIN_FIELDS:
            raise GestureSimError(
                f"{where}: SPEAKER line has {len(fields)} fields, needs at least "
                f"{_RTTM_MIN_FIELDS} (SPEAKER file channel onset duration <NA> <NA> name)")
        fid, name = fields[1], fields[7]
        values = []
        for what, tok in (("onset", fields[3]), ("duration", fields[4])):
            try:
                v = float(tok)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise GestureSimError(
                    f"{where}: SPEAKER {what} {_short(tok)!r} is not a finite number of "
                    "seconds")
            values.append(v)
        onset, dur = values
        if onset < 0:
            raise GestureSimError(f"{where}: SPEAKER onset {_short(fields[3])} s is negative")
        if dur <= 0:
            raise GestureSimError(
                f"{where}: SPEAKER duration {_short(fields[4])} s is not positive")
        if file_id is None:
            file_id = (fid, i)
        elif fid != file_id[0]:
            raise GestureSimError(
                f"{where}: SPEAKER line of file id {_short(fid)!r}, but line {file_id[1]} is "
                f"of {_short(file_id[0])!r}; one RTTM file per recording")
        segments.append((onset, onset + dur, i, name))
    if not segments:
        raise GestureSimError(f"{p}: no SPEAKER line in {len(lines)} lines (not an RTTM "
                              "diarization?)")
    segments.sort(key=lambda s: (s[0], s[2]))
    names: list[str] = []
    for onset, _, i, name in segments:
        if name not in names:
            names.append(name)
            if len(names) > n_persons:
                raise GestureSimError(
                    f"{p}:{i}: speaker {_short(name)!r} (at {onset:g} s) is speaker "
                    f"{len(names)}, more than the {n_persons} persons of the scene "
                    f"({', '.join(_short(n) for n in names)})")
    turns: list[Turn] = []
    for person, name in enumerate(names):
        spans = sorted((s[0], s[1]) for s in segments if s[3] == name)
        merged: list[list[float]] = []
        for a, b in spans:
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        turns.extend(Turn(person, a, b) for a, b in merged)
    turns.sort(key=lambda t: (t.t_start, t.person))
    return turns, tuple(names)


def rttm_file_id(path: str | Path) -> str | None:
    """The file id (the recording) of an RTTM's first SPEAKER line (read_rttm holds every line
    to one), or None without one."""
    for line in _read_lines(Path(path)):
        fields = line.split()
        if len(fields) >= 2 and fields[0].upper() == "SPEAKER":
            return fields[1]
    return None


def _fmt_time(x: float) -> str:
    """Seconds with at least 3 and at most 6 decimals (``1.500``, ``1.2345``)."""
    s = f"{x:.6f}"
    head, frac = s.split(".")
    return f"{head}.{frac.rstrip('0').ljust(3, '0')}"


def write_rttm(path: str | Path, turns: Iterable[Turn], file_id: str = "dialogue",
               names: Sequence[str] = ("A", "B")) -> None:
    """Write ``turns`` as RTTM SPEAKER lines (sorted by onset), atomically.

    Times are written with 3 to 6 decimals (µs resolution), so :func:`read_rttm` gives the
    turns back to within 1 µs; person ``k`` is written as ``names[k]``, channel as ``1``.

    Raises:
        GestureSimError: a person without a name, a name or file id that is empty or holds
            white space (RTTM fields are separated by spaces), or a turn whose times are not
            finite with ``0 <= t_start < t_end``.
    """
    for label, value in [("file id", file_id)] + [("speaker name", n) for n in names]:
        if not value or re.search(r"\s", value):
            raise GestureSimError(f"RTTM {label} {value!r} must be non-empty without spaces")
    lines = []
    for t in sorted(turns, key=lambda t: (t.t_start, t.person)):
        if not 0 <= t.person < len(names):
            raise GestureSimError(
                f"turn of person {t.person} has no speaker name (names: {', '.join(names)})")
        if not (math.isfinite(t.t_start) and math.isfinite(t.t_end)
                and 0 <= t.t_start < t.t_end):
            raise GestureSimError(
                f"turn of person {t.person} from {t.t_start} s to {t.t_end} s is not a stretch "
                "of time (need 0 <= start < end)")
        dur = max(t.t_end - t.t_start, 1e-6)
        lines.append(f"SPEAKER {file_id} 1 {_fmt_time(t.t_start)} {_fmt_time(dur)} <NA> <NA> "
                     f"{names[t.person]} <NA> <NA>\n")
    atomic_write_text(path, "".join(lines))


# --------------------------------------------------------------------------------------------
# Channels
# --------------------------------------------------------------------------------------------


def _ffmpeg_channels(p: Path) -> np.ndarray:
    """Decode a non-WAV file with ffmpeg to (n, C) float32 at 16 kHz, channels kept."""
    try:
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as exc:
        raise GestureSimError(f"{p}: not a WAV file and no ffmpeg to decode it") from exc
    cmd = [exe, "-hide_banner", "-nostdin", "-i", str(p), "-vn", "-f", "f32le",
           "-ar", str(SAMPLE_RATE), "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    err = proc.stderr.decode("utf-8", "replace")
    # The last "Audio:" line is the output stream (pcm_f32le, 16000 Hz, <layout>).
    found = re.findall(r"Audio: \w+[^,]*, \d+ Hz, ([^,\n]+)", err)
    if proc.returncode != 0 or not found:
        raise GestureSimError(f"{p}: not an audio file (ffmpeg could not decode it)")
    layout = found[-1].strip()
    m = re.match(r"(\d+) channels", layout)
    layouts = {"mono": 1, "stereo": 2, "2.1": 3, "3.0": 3, "quad": 4, "4.0": 4, "5.0": 5,
               "5.1": 6, "5.0(side)": 5, "5.1(side)": 6, "6.1": 7, "7.1": 8}
    channels = int(m.group(1)) if m else layouts.get(layout, 0)
    x = np.frombuffer(proc.stdout, dtype="<f4")
    if channels <= 0 or len(x) % channels:
        raise GestureSimError(f"{p}: cannot tell the channel layout {layout!r} ffmpeg decoded")
    return x.reshape(-1, channels).astype(np.float32)


def load_channels(path: str | Path) -> np.ndarray:
    """Read an audio file keeping every channel: float32 (n, C) at 16 kHz, C = 1 for mono.

    The same conversions as :func:`~gesture_sim.audio.sources.load_audio` (any WAV width, any
    rate resampled with the same anti-aliasing filter, other formats through ffmpeg) and the
    same checks, but the channels are not mixed down: column ``c`` is channel ``c`` of the file
    (person ``c`` of a conversation recorded one microphone per person).

    Raises:
        GestureSimError: no such file, a folder, empty file, not audio / broken header, no
            samples, a sample rate too low for speech, broken float samples.
    """
    p, head = check_audio_file(path)
    if is_wav(head):
        data, rate, _ = read_wav_checked(p)
        data = data.reshape(len(data), -1)
        cols = [resample_to_16k(to_float_mono(data[:, c]), rate) for c in range(data.shape[1])]
        x = np.stack(cols, axis=1).astype(np.float32, copy=False)
    elif head[:4] == b"RIFF":
        raise GestureSimError(f"{p}: RIFF file that is not WAVE audio")
    else:
        x = _ffmpeg_channels(p)
    if x.shape[0] == 0:
        raise GestureSimError(f"{p}: audio file contains no samples")
    return np.ascontiguousarray(x)


# --------------------------------------------------------------------------------------------
# Turns from one channel per person
# --------------------------------------------------------------------------------------------


def _frame_levels(x: np.ndarray) -> np.ndarray:
    """Frame levels (dBFS, clipped at :data:`SILENCE_DB`) of float (n,) samples at 16 kHz.

    Frame ``i`` stands for the samples ``[i*step, (i+1)*step)`` (step 10 ms); its window of
    :data:`FRAME_WINDOW_S` is centred on them. Shape (ceil(n / step),).
    """
    from scipy.signal import butter, sosfilt

    step = int(round(FRAME_STEP_S * SAMPLE_RATE))
    win = int(round(FRAME_WINDOW_S * SAMPLE_RATE))
    n_frames = -(-len(x) // step)
    sos = butter(2, HIGHPASS_HZ, btype="highpass", fs=SAMPLE_RATE, output="sos")
    y = sosfilt(sos, x.astype(np.float64))
    pad_l = (win - step) // 2
    padded = np.zeros(n_frames * step + win, dtype=np.float64)
    padded[pad_l:pad_l + len(y)] = y
    c = np.concatenate([[0.0], np.cumsum(padded * padded)])
    starts = np.arange(n_frames) * step
    power = (c[starts + win] - c[starts]) / win
    return np.maximum(10.0 * np.log10(np.maximum(power, 1e-30)), SILENCE_DB)


def _hysteresis(level: np.ndarray, on: float, off: float) -> np.ndarray:
    """Boolean (n,): True from a frame above ``on`` until the level falls below ``off``."""
    above_on, above_off = level >= on, level >= off
    active = np.zeros(len(level), dtype=bool)
    # Runs of above_off frames that contain at least one above_on frame.
    edges = np.diff(np.concatenate([[0], above_off.astype(np.int8), [0]]))
    for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True):
        if above_on[a:b].any():
            active[a:b] = True
    return active


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) frame index pairs of the True runs of a boolean (n,) array."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist(),
                    strict=True))


def turns_from_channels(
    channels: np.ndarray, *, min_turn_s: float = MIN_TURN_S, bridge_s: float = BRIDGE_S,
    crosstalk_db: float = CROSSTALK_DB, leak_margin_db: float = LEAK_MARGIN_DB,
    on_below_speech_db: float = ON_BELOW_SPEECH_DB, on_above_noise_db: float = ON_ABOVE_NOISE_DB,
    hysteresis_db: float = HYSTERESIS_DB, min_range_db: float = MIN_RANGE_DB,
) -> list[Turn]:
    """The turns of each person from one channel per person (person ``c`` = channel ``c``).

    Per channel, 10 ms frame levels (dBFS, after an 80 Hz high-pass) are compared with the
    channel's OWN noise floor (10th-percentile frame level) and speech level (95th percentile
    of the frames at least ``on_above_noise_db`` above that floor), so that a channel recorded
    12 dB quieter gives the same turns:

    1. a channel that is digital silence, has fewer than ``min_turn_s`` (s) of frames
       ``on_above_noise_db`` above its floor, or whose speech level is not ``min_range_db``
       (dB) above its floor, has no speech at all;
    2. hysteresis: a frame enters speech within ``on_below_speech_db`` (dB) of the speech level
       and at least ``on_above_noise_db`` (dB) above the noise floor, and stays in it down to
       ``hysteresis_db`` (dB) lower (never closer than :data:`OFF_ABOVE_NOISE_DB` to the floor);
    3. crosstalk, against every other channel q active in the frame: channel p's frame is p's
       speech only if (a) relative to its own speech level, p is not ``crosstalk_db`` (dB) or
       more below q relative to q's (the louder person in their own microphone speaks), and
       (b) p is at least ``leak_margin_db`` (dB) louder than q's voice leaking into p's
       microphone would make it, the leakage (dB, level_p - level_q) being measured as the
       10th percentile over q's loud frames in which q is the louder channel (a voice reaches
       the partner's microphone weaker than its own: mic gains must differ by less than the
       acoustic separation, ~25 dB for headsets). Rule (b) keeps a channel that holds only the
       partner's leakage from becoming a second speaker; both rules are gain-invariant;
    4. gaps shorter than ``bridge_s`` (s) within a person's speech are bridged, then stretches
       shorter than ``min_turn_s`` (s) are dropped.

    The references (floor, speech level, leakage) are measured over the whole recording, not
    a running window: a level that drifts by tens of dB within one file is not followed.

    Args:
        channels: float (n, C) at 16 kHz (a (n,) array is one channel).

    Returns:
        Turns sorted by ``t_start`` then person; boundaries on the 10 ms frame grid, ending no
        later than the audio. Overlap between persons is kept.
    """
    x = np.asarray(channels, dtype=np.float32)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise GestureSimError(f"channels must be an (n, C) array, got shape {x.shape}")
    n, n_ch = x.shape
    if n == 0 or n_ch == 0:
        return []
    x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=-1.0)
    levels = np.stack([_frame_levels(x[:, c]) for c in range(n_ch)])  # (C, frames), dBFS
    noise = np.full(n_ch, SILENCE_DB)  # (C,) dBFS
    speech = np.full(n_ch, SILENCE_DB)  # (C,) dBFS
    active = np.zeros(levels.shape, dtype=bool)
    for c in range(n_ch):
        sounding = levels[c][levels[c] > SILENCE_DB]  # digital silence is no microphone's floor
        if len(sounding) * FRAME_STEP_S < min_turn_s:
            continue
        noise[c] = np.percentile(sounding, NOISE_PERCENTILE)
        loud = levels[c][levels[c] >= noise[c] + on_above_noise_db]
        if len(loud) * FRAME_STEP_S < min_turn_s:
            continue  # never clearly above its floor: no speech (speech[c] stays silence)
        speech[c] = np.percentile(loud, SPEECH_PERCENTILE)
        if speech[c] <= SILENCE_DB or speech[c] - noise[c] < min_range_db:
            continue
        on = max(speech[c] - on_below_speech_db, noise[c] + on_above_noise_db)
        off = max(on - hysteresis_db, noise[c] + OFF_ABOVE_NOISE_DB)
        active[c] = _hysteresis(levels[c], on, off)
    rel = levels - speech[:, None]  # dB re each channel's own speech level
    own = active.copy()
    for p in range(n_ch):
        for q in range(n_ch):
            if q == p or not active[q].any():
                continue
            both = active[p] & active[q]
            own[p] &= ~(both & (rel[p] <= rel[q] - crosstalk_db))
            diff = levels[p] - levels[q]
            # q's loud frames where q is louder than p: there q may be the source and p hear it.
            loud_q = active[q] & (rel[q] >= -COUPLING_LOUD_DB) & (diff < 0)
            if loud_q.sum() >= MIN_COUPLING_FRAMES:
                coupling = float(np.percentile(diff[loud_q], COUPLING_PERCENTILE))
                own[p] &= ~(both & (diff < coupling + leak_margin_db))
    step = FRAME_STEP_S
    bridge_frames, min_frames = bridge_s / step, min_turn_s / step
    duration = n / SAMPLE_RATE
    turns: list[Turn] = []
    for p in range(n_ch):
        runs = _runs(own[p])
        merged: list[list[int]] = []
        for a, b in runs:
            if merged and a - merged[-1][1] < bridge_frames - 1e-9:
                merged[-1][1] = b
            else:
                merged.append([a, b])
        for a, b in merged:
            if b - a >= min_frames - 1e-9:
                turns.append(Turn(p, round(a * step, 6), round(min(b * step, duration), 6)))
    turns.sort(key=lambda t: (t.t_start, t.person))
    return turns


# --------------------------------------------------------------------------------------------
# Roles and masks
# --------------------------------------------------------------------------------------------


def role_at(turns: Iterable[Turn], person: int, t: float) -> str:
    """``"speaking"`` if a turn of ``person`` covers time ``t`` (s; ``t_start <= t < t_end``),
    else ``"listening"``."""
    for turn in turns:
        if turn.person == person and turn.t_start <= t < turn.t_end:
            return "speaking"
    return "listening"


def speaking_mask(turns: Iterable[Turn], person: int, n_samples: int,
                  fade_s: float = 0.01) -> np.ndarray:
    """Float32 (n_samples,) in [0, 1] at 16 kHz: 1 inside the person's turns, 0 elsewhere.

    Sample ``i`` is at ``i / 16000`` s. Each turn edge fades with a raised cosine over
    ``fade_s`` (s) OUTSIDE the turn (so the whole turn keeps full gain and the mask reaches 0
    ``fade_s`` before the start and after the end); overlapping fades take the larger value.
    ``fade_s = 0`` gives a hard 0/1 mask.
    """
    n = max(int(n_samples), 0)
    mask = np.zeros(n, dtype=np.float64)
    fade = max(float(fade_s), 0.0) * SAMPLE_RATE  # samples
    idx = np.arange(n, dtype=np.float64)
    for turn in turns:
        if turn.person != person:
            continue
        s, e = turn.t_start * SAMPLE_RATE, turn.t_end * SAMPLE_RATE
        lo = max(int(math.floor(s - fade)), 0)
        hi = min(int(math.ceil(e + fade)) + 1, n)
        if hi <= lo:
            continue
        i = idx[lo:hi]
        d = np.maximum(np.maximum(s - i, i - e), 0.0)  # samples outside the turn
        if fade > 0:
            v = np.where(d < fade, 0.5 * (1.0 + np.cos(np.pi * np.minimum(d / fade, 1.0))), 0.0)
        else:
            v = (d == 0).astype(np.float64)
        mask[lo:hi] = np.maximum(mask[lo:hi], v)
    return mask.astype(np.float32)


def voice_of(mono: np.ndarray, turns: Iterable[Turn], person: int) -> np.ndarray:
    """The person's own voice from a diarized mono mix: float32 (n,) ``mono * speaking_mask``."""
    x = np.asarray(mono, dtype=np.float32)
    return (x * speaking_mask(turns, person, len(x))).astype(np.float32)


def check_turns(turns: Iterable[Turn], duration_s: float, where: str,
                recording: str | None = None) -> None:
    """GestureSimError (one line naming ``where``) if a turn lies outside the audio
    (``duration_s``, s) it goes with: starts at or after its end, or runs past it by more than
    :data:`~gesture_sim.validation.SIDE_FILE_OVERRUN_S` (the one rule of every side file,
    :func:`gesture_sim.validation.side_file_times`): the turns belong to another recording
    (``recording``: the RTTM's file id, named in the message when given)."""
    from gesture_sim.validation import side_file_times

    hint = "are the turns for this recording?" if recording is None else \
        f"the RTTM's turns are of recording {_short(recording)!r}; are they for this one?"
    side_file_times("", where, sorted(((t.t_start, t.t_end, f"turn of person {t.person}")
                                       for t in turns), key=lambda it: -it[1]),
                    duration_s, hint=hint)
