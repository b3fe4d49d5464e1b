"""A scripted two-voice dialogue with known answers (espeak-ng speech, sox, numpy).

:func:`make_dialogue` speaks a fixed script in two clearly different espeak-ng voices
(person 0: ``en-us``, pitch 40, a low voice near 100 Hz; person 1: ``en-us+f3``, pitch 70, a
high voice near 250 Hz), resamples each utterance to 16 kHz with sox and composes them with
numpy: 1 s of silence, then alternating turns of two or three utterances separated by pauses
of 0.8-1.0 s within a turn and gaps of 1.1-1.3 s between turns (seeded), then 1 s of silence.
Statements end in "." (espeak's falling, low phrase end: a pause after one *invites* a
backchannel); two utterances are yes/no questions ending in "?" (a rising end: the pause after
one does not). The known answers come from the composition itself: every utterance's exact
start and end (s), the pauses after statements and after questions within a turn, and the gaps
between turns. Times are seconds from the start of the audio; samples float32 at 16 kHz.
"""

from __future__ import annotations

import shutil
import subprocess
import wave
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, Turn
from gesture_sim.errors import GestureSimError

__all__ = ["SCRIPT", "VOICES", "Dialogue", "make_dialogue", "say"]

#: (espeak-ng voice, pitch 0-99) of person 0 and person 1.
VOICES: tuple[tuple[str, int], ...] = (("en-us", 40), ("en-us+f3", 70))
#: espeak-ng speaking rate (words per minute).
SPEED_WPM = 178
#: Peak level (of full scale 1.0) of each person's utterances.
PEAKS: tuple[float, float] = (0.5, 0.4)
#: The script: turns of (person, utterances).
SCRIPT: tuple[tuple[int, tuple[str, ...]], ...] = (
    (0, ("I went to the market this morning.", "The vegetables were very good.",
         "So I bought some tomatoes.")),
    (1, ("That sounds really lovely.", "Did you see the new bakery?",
         "My sister works there now.")),
    (0, ("I have not seen it yet.", "Is it near the old station?",
         "I will look for it tomorrow.")),
    (1, ("Yes, right by the station.",)),
)
LEAD_S = 1.0
TAIL_S = 1.0
PAUSE_S = (0.8, 1.0)
GAP_S = (1.1, 1.3)
_TRIM = 0.005  # |x| above this (full scale) is speech when trimming espeak's silences

_CACHE: dict[tuple[str, str, int, int], np.ndarray] = {}


def _tools() -> None:
    missing = [t for t in ("espeak-ng", "sox") if shutil.which(t) is None]
    if missing:
        raise GestureSimError(f"the test dialogue needs {' and '.join(missing)} "
                              "(install espeak-ng and sox)")


def say(text: str, voice: str = "en-us", pitch: int = 50, speed: int = SPEED_WPM) -> np.ndarray:
    """espeak-ng speech resampled by sox to 16 kHz mono float32 (n,), peak 1.0, leading and
    trailing silence trimmed exactly (the first and last sample are speech). Cached per
    process (the same arguments give the same array; do not modify it).

    Raises:
        GestureSimError: espeak-ng or sox is missing or fails.
    """
    key = (text, voice, int(pitch), int(speed))
    if key in _CACHE:
        return _CACHE[key]
    _tools()
    try:
        raw = subprocess.run(["espeak-ng", "-v", voice, "-p", str(pitch), "-s", str(speed),
                              "--stdout", text], capture_output=True, check=True).stdout
        # -R: repeatable (sox dithers its 16-bit output with a random seed otherwise, and a
        # recogniser's borderline decision would change from run to run)
        pcm = subprocess.run(["sox", "-R", "-t", "wav", "-", "-r", str(SAMPLE_RATE), "-c", "1",
                              "-b", "16", "-e", "signed-integer", "-t", "raw", "-"],
                             input=raw, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        raise GestureSimError(f"espeak-ng/sox failed on {text!r}: {exc}") from None
    x = np.frombuffer(pcm, dtype="<i2").astype(np.float32) / 32768.0
    peak = float(np.max(np.abs(x))) if len(x) else 0.0
    if peak <= 0:
        raise GestureSimError(f"espeak-ng produced no sound for {text!r}")
    x = x / peak
    loud = np.nonzero(np.abs(x) > _TRIM)[0]
    x = np.ascontiguousarray(x[loud[0]: loud[-1] + 1])
    x.setflags(write=False)
    _CACHE[key] = x
    return x


@dataclass
class Dialogue:
    """A composed dialogue and its known answers.

    Attributes:
        channels: (n, 2) float32, channel p holds person p's voice only (16 kHz).
        mono: (n,) float32, the sum of the channels (the voices never overlap).
        turns: one :class:`~gesture_sim.contracts.Turn` per utterance (exact, s).
        texts: the text of each utterance, in the order of ``turns``.
        inviting_pauses: (speaking person, pause start s, pause end s) of the pauses within a
            turn that follow a statement.
        other_pauses: the same for pauses within a turn that follow a question.
        turn_gaps: (person who spoke before, gap start s, gap end s) between turns.
    """

    channels: np.ndarray
    mono: np.ndarray
    turns: list[Turn]
    texts: list[str] = field(default_factory=list)
    inviting_pauses: list[tuple[int, float, float]] = field(default_factory=list)
    other_pauses: list[tuple[int, float, float]] = field(default_factory=list)
    turn_gaps: list[tuple[int, float, float]] = field(default_factory=list)

    @property
    def duration(self) -> float:
        """Length of the audio (s)."""
        return len(self.mono) / SAMPLE_RATE

    def speech_s(self, person: int) -> float:
        """Total speech of ``person`` (s)."""
        return sum(t.duration for t in self.turns if t.person == person)

    def write(self, folder: str | Path) -> dict[str, Path]:
        """Write ``dialogue_stereo.wav`` (16-bit, 2 channels), ``dialogue_mono.wav`` (16-bit)
        and ``dialogue.rttm`` (persons named A and B) into ``folder`` (created).

        Returns:
            ``{"stereo": path, "mono": path, "rttm": path}``.
        """
        d = Path(folder)
        d.mkdir(parents=True, exist_ok=True)
        out = {"stereo": d / "dialogue_stereo.wav", "mono": d / "dialogue_mono.wav",
               "rttm": d / "dialogue.rttm"}
        _write_wav(out["stereo"], self.channels)
        _write_wav(out["mono"], self.mono[:, None])
        try:
            from gesture_sim.audio.turns import write_rttm
        except ImportError:  # the roles module is not there: the standard lines by hand
            lines = [f"SPEAKER dialogue 1 {t.t_start:.3f} {t.duration:.3f} <NA> <NA> "
                     f"{'AB'[t.person]} <NA> <NA>\n" for t in self.turns]
            out["rttm"].write_text("".join(lines), encoding="utf-8")
        else:
            write_rttm(out["rttm"], self.turns, file_id="dialogue", names=("A", "B"))
        return out


def _write_wav(path: Path, x: np.ndarray) -> None:
    """16-bit PCM WAV of (n, channels) float samples (clipped to [-1, 1])."""
    pcm = np.clip(np.round(np.asarray(x, float) * 32767.0), -32768, 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(pcm.shape[1])
        w.setsampwidth(2)
        w.setframerate(SAMPLE_RATE)
        w.writeframes(np.ascontiguousarray(pcm).tobytes())


def make_dialogue(seed: int = 0) -> Dialogue:
    """The scripted dialogue (about 25 s); ``seed`` draws the pause and gap lengths.

    Raises:
        GestureSimError: espeak-ng or sox is missing or fails.
    """
    _tools()
    rng = np.random.default_rng(seed)
    pieces: list[tuple[int, int, np.ndarray]] = []  # (person, start sample, samples)
    turns: list[Turn] = []
    texts: list[str] = []
    inviting: list[tuple[int, float, float]] = []
    other: list[tuple[int, float, float]] = []
    gaps: list[tuple[int, float, float]] = []
    pos = int(round(LEAD_S * SAMPLE_RATE))
    for k, (person, utterances) in enumerate(SCRIPT):
        voice, pitch = VOICES[person]
        for j, text in enumerate(utterances):
            x = say(text, voice, pitch) * PEAKS[person]
            t0, t1 = pos / SAMPLE_RATE, (pos + len(x)) / SAMPLE_RATE
            pieces.append((person, pos, x))
            turns.append(Turn(person, t0, t1))
            texts.append(text)
            pos += len(x)
            if j < len(utterances) - 1:
                n = int(round(rng.uniform(*PAUSE_S) * SAMPLE_RATE))
                pause = (person, t1, (pos + n) / SAMPLE_RATE)
                (other if text.rstrip().endswith("?") else inviting).append(pause)
                pos += n
            elif k < len(SCRIPT) - 1:
                n = int(round(rng.uniform(*GAP_S) * SAMPLE_RATE))
                gaps.append((person, t1, (pos + n) / SAMPLE_RATE))
                pos += n
    pos += int(round(TAIL_S * SAMPLE_RATE))
    channels = np.zeros((pos, 2), dtype=np.float32)
    for person, start, x in pieces:
        channels[start: start + len(x), person] += x
    mono = channels.sum(axis=1).astype(np.float32)
    return Dialogue(channels, mono, turns, texts, inviting, other, gaps)
