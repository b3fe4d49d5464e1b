"""G.711 A-law and µ-law WAV files (telephony: format tags 6 and 7, 8 bits a sample), decoded
in numpy.

scipy's WAV reader takes PCM and IEEE float only; a valid A-law or µ-law recording (what a
telephone system or ``sox -e a-law`` writes) was refused as a "broken header". The decoders
are the ITU-T G.711 expansions to 16-bit linear PCM (A-law: ±32256, µ-law: ±32124 at full
scale), returned as float32 divided by 32768, the scale :func:`~gesture_sim.audio.sources.
to_float_mono` gives 16-bit PCM, so that a G.711 file and its 16-bit PCM decoding (``sox
in.wav -e signed -b 16 out.wav``) give the same samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: WAVE format tags (``fmt `` chunk, or the first two bytes of an extensible format's GUID).
WAVE_FORMAT_ALAW = 6
WAVE_FORMAT_MULAW = 7
WAVE_FORMAT_EXTENSIBLE = 0xFFFE


def _alaw_table() -> np.ndarray:
    """(256,) int16: the linear value of each A-law byte (G.711, even bits inverted)."""
    a = np.arange(256, dtype=np.int32) ^ 0x55
    exponent, mantissa = (a >> 4) & 7, a & 0x0F
    mag = np.where(exponent == 0, (mantissa << 4) + 8,
                   ((mantissa << 4) + 0x108) << np.maximum(exponent - 1, 0))
    return np.where(a & 0x80, mag, -mag).astype(np.int16)


def _ulaw_table() -> np.ndarray:
    """(256,) int16: the linear value of each µ-law byte (G.711, all bits inverted)."""
    u = ~np.arange(256, dtype=np.int32) & 0xFF
    exponent, mantissa = (u >> 4) & 7, u & 0x0F
    mag = (((mantissa << 3) + 0x84) << exponent) - 0x84
    return np.where(u & 0x80, -mag, mag).astype(np.int16)


ALAW_TO_LINEAR = _alaw_table()
ULAW_TO_LINEAR = _ulaw_table()


def decode(raw: bytes | np.ndarray, tag: int) -> np.ndarray:
    """G.711 bytes (n,) to float32 (n,) in [-1, 1] (linear 16-bit value / 32768); ``tag``:
    :data:`WAVE_FORMAT_ALAW` or :data:`WAVE_FORMAT_MULAW`."""
    table = ALAW_TO_LINEAR if tag == WAVE_FORMAT_ALAW else ULAW_TO_LINEAR
    codes = np.frombuffer(raw, dtype=np.uint8) if isinstance(raw, bytes | bytearray) else \
        np.asarray(raw, dtype=np.uint8)
    return table[codes].astype(np.float32) / np.float32(32768.0)


def _chunks(raw: bytes) -> dict[bytes, bytes]:
    """The first chunk of each id in a RIFF/WAVE file (a truncated ``data`` chunk is cut at the
    file's end)."""
    out: dict[bytes, bytes] = {}
    pos = 12
    while pos + 8 <= len(raw):
        cid, size = raw[pos:pos + 4], int.from_bytes(raw[pos + 4:pos + 8], "little")
        out.setdefault(cid, raw[pos + 8:pos + 8 + size])
        pos += 8 + size + (size & 1)
    return out


def format_tag(raw: bytes) -> int | None:
    """The WAVE format tag of a RIFF/WAVE file's bytes (the subformat's, for an extensible
    one), or None without a readable ``fmt `` chunk."""
    if raw[:4] != b"RIFF" or raw[8:12] != b"WAVE":
        return None
    fmt = _chunks(raw).get(b"fmt ")
    if fmt is None or len(fmt) < 16:
        return None
    tag = int.from_bytes(fmt[0:2], "little")
    if tag == WAVE_FORMAT_EXTENSIBLE and len(fmt) >= 26:
        tag = int.from_bytes(fmt[24:26], "little")
    return tag


def read_g711_wav(path: str | Path) -> tuple[np.ndarray, int, str] | None:
    """A G.711 WAV file's samples as float32 ((n,) or (n, C) in [-1, 1]), its rate (Hz) and
    ``"alaw"``/``"mulaw"``; None when the file is not an A-law or µ-law WAV (or its header is
    damaged: the PCM readers and their messages take it from there)."""
    with Path(path).open("rb") as f:
        head = f.read(1 << 16)            # the header: a PCM file is not read twice
    tag = format_tag(head)
    if tag not in (WAVE_FORMAT_ALAW, WAVE_FORMAT_MULAW):
        return None
    raw = Path(path).read_bytes()
    chunks = _chunks(raw)
    fmt, data = chunks[b"fmt "], chunks.get(b"data")
    channels = int.from_bytes(fmt[2:4], "little")
    rate = int.from_bytes(fmt[4:8], "little")
    bits = int.from_bytes(fmt[14:16], "little")
    if data is None or channels == 0 or bits != 8:
        return None
    n = len(data) // channels
    x = decode(data[:n * channels], tag)
    x = x.reshape(n, channels) if channels > 1 else x
    return x, rate, "alaw" if tag == WAVE_FORMAT_ALAW else "mulaw"
