"""Who speaks when (gesture_sim.audio.turns): RTTM reading and writing, turns from one channel
per person (leakage, gain, blips, silence), the channel-keeping loader, roles and masks. Known
answers throughout: hand-written RTTM, synthetic syllable trains placed at known times."""

from __future__ import annotations

import shutil
import subprocess
import wave
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.sources import load_audio
from gesture_sim.audio.turns import (
    check_turns,
    load_channels,
    read_rttm,
    role_at,
    speaking_mask,
    turns_from_channels,
    voice_of,
    write_rttm,
)
from gesture_sim.contracts import Turn
from gesture_sim.errors import GestureSimError

SR = 16_000

# --------------------------------------------------------------------------------------------
# RTTM
# --------------------------------------------------------------------------------------------

HAND_WRITTEN = """\
# diarization of a two-person dialogue (hand-written)
SPKR-INFO meeting 1 <NA> <NA> <NA> unknown bob <NA> <NA>
SPEAKER meeting 1 3.20 1.30 <NA> <NA> alice <NA> <NA>
SPEAKER meeting 1 1.00 2.00 <NA> <NA> bob <NA> <NA>

SPEAKER meeting 1 0.50 1.00 <NA> <NA> alice <NA> <NA> extra fields
SPEAKER meeting 1 1.20 0.60 <NA> <NA> alice <NA> <NA>
SPEAKER meeting 1 4.00 0.50 <NA> <NA> bob
"""


def test_read_rttm_hand_written_file(tmp_path: Path) -> None:
    p = tmp_path / "d.rttm"
    p.write_text(HAND_WRITTEN)
    turns, names = read_rttm(p)
    # alice starts first (0.5 s) -> person 0 though bob's line comes first in the file;
    # alice's 0.5-1.5 and 1.2-1.8 overlap -> merged 0.5-1.8; bob 1.0-3.0 overlaps alice (kept).
    assert names == ("alice", "bob")
    assert [(t.person, t.t_start, t.t_end) for t in turns] == [
        (0, 0.5, pytest.approx(1.8)), (1, 1.0, 3.0), (0, 3.2, pytest.approx(4.5)),
        (1, 4.0, 4.5)]


def test_rttm_round_trip(tmp_path: Path) -> None:
    turns = [Turn(1, 0.25, 1.5), Turn(0, 1.0, 2.125), Turn(1, 2.5, 3.0), Turn(0, 3.1234567, 4.0)]
    p = tmp_path / "out" / "t.rttm"
    write_rttm(p, turns, file_id="take1", names=("left", "right"))
    text = p.read_text()
    assert text.splitlines()[0] == "SPEAKER take1 1 0.250 1.250 <NA> <NA> right <NA> <NA>"
    back, names = read_rttm(p)
    # persons are renumbered by first appearance: 'right' speaks first
    assert names == ("right", "left")
    want = sorted(turns, key=lambda t: t.t_start)
    assert len(back) == len(want)
    for b, w in zip(back, want, strict=True):
        assert names[b.person] == ("left", "right")[w.person]
        assert b.t_start == pytest.approx(w.t_start, abs=1e-6)
        assert b.t_end == pytest.approx(w.t_end, abs=2e-6)
    assert not list(p.parent.glob(".tmp-*"))  # atomic write leaves no temporary


def test_write_rttm_refuses_what_rttm_cannot_hold(tmp_path: Path) -> None:
    with pytest.raises(GestureSimError, match="no speaker name"):
        write_rttm(tmp_path / "a.rttm", [Turn(2, 0.0, 1.0)])
    with pytest.raises(GestureSimError, match="without spaces"):
        write_rttm(tmp_path / "a.rttm", [Turn(0, 0.0, 1.0)], names=("dr who", "B"))
    with pytest.raises(GestureSimError, match="start < end"):
        write_rttm(tmp_path / "a.rttm", [Turn(0, 1.0, 1.0)])
    assert not (tmp_path / "a.rttm").exists()


GOOD = "SPEAKER f 1 0.0 1.0 <NA> <NA> A <NA> <NA>\n"


@pytest.mark.parametrize("bad, line, words", [
    ("SPEAKER f 1 0.5 1.0 <NA> <NA>\n", 2, "7 fields"),
    ("SPEAKER f 1 abc 1.0 <NA> <NA> A <NA> <NA>\n", 2, "onset 'abc'"),
    ("SPEAKER f 1 nan 1.0 <NA> <NA> A <NA> <NA>\n", 2, "not a finite"),
    ("SPEAKER f 1 1.0 inf <NA> <NA> A <NA> <NA>\n", 2, "duration 'inf'"),
    ("SPEAKER f 1 -0.5 1.0 <NA> <NA> A <NA> <NA>\n", 2, "negative"),
    ("SPEAKER f 1 1.0 0 <NA> <NA> A <NA> <NA>\n", 2, "not positive"),
    ("SPEAKER f 1 1.0 -2 <NA> <NA> A <NA> <NA>\n", 2, "not positive"),
    ("SPEAKER g 1 1.0 1.0 <NA> <NA> A <NA> <NA>\n", 2, "file id 'g'.*line 1.*'f'"),
    ("SPEAKER f 1 2.0 1.0 <NA> <NA> B <NA> <NA>\n"
     "SPEAKER f 1 3.0 1.0 <NA> <NA> C <NA> <NA>\n", 3, "'C'.*more than the 2 persons"),
    (b"SPEAKER f 1 2.0 1.0 <NA> <NA> \xff\xfe <NA> <NA>\n", 2, "not UTF-8"),
])
def test_read_rttm_errors_name_file_and_line(tmp_path: Path, bad: str | bytes, line: int,
                                             words: str) -> None:
    p = tmp_path / "bad.rttm"
    p.write_bytes(GOOD.encode() + (bad if isinstance(bad, bytes) else bad.encode()))
    with pytest.raises(GestureSimError, match=rf"bad\.rttm:{line}: .*{words}") as e:
        read_rttm(p)
    assert "\n" not in str(e.value)


def test_read_rttm_three_speakers_allowed_when_asked(tmp_path: Path) -> None:
    p = tmp_path / "three.rttm"
    p.write_text(GOOD + GOOD.replace("0.0", "2.0").replace(" A ", " B ")
                 + GOOD.replace("0.0", "4.0").replace(" A ", " C "))
    turns, names = read_rttm(p, n_persons=3)
    assert names == ("A", "B", "C") and [t.person for t in turns] == [0, 1, 2]


def test_read_rttm_file_level_errors(tmp_path: Path) -> None:
    with pytest.raises(GestureSimError, match=r"missing\.rttm: cannot read"):
        read_rttm(tmp_path / "missing.rttm")
    with pytest.raises(GestureSimError, match="is a folder"):
        read_rttm(tmp_path)
    p = tmp_path / "empty.rttm"
    p.write_text("# nothing here\nSPKR-INFO f 1 <NA> <NA> <NA> unknown A <NA> <NA>\n")
    with pytest.raises(GestureSimError, match=r"empty\.rttm: no SPEAKER line"):
        read_rttm(p)


# --------------------------------------------------------------------------------------------
# Turns from one channel per person
# --------------------------------------------------------------------------------------------


def _syllables(t0: float, t1: float, rng: np.random.Generator, f0: float) -> np.ndarray:
    """Speech-like sound from t0 to t1 (s): harmonic syllables of 0.12-0.25 s (10 harmonics
    of ~f0 Hz, sin^2 envelope, peak ~0.3) with 30-80 ms gaps between them."""
    n = int(round((t1 - t0) * SR))
    out = np.zeros(n)
    i = 0
    while i < n:
        length = min(int(rng.uniform(0.12, 0.25) * SR), n - i)
        t = np.arange(length) / SR
        f = f0 * rng.uniform(0.85, 1.15)
        tone = sum(np.sin(2 * np.pi * k * f * t + rng.uniform(0, 6)) / k for k in range(1, 11))
        out[i:i + length] = 0.1 * tone * np.sin(np.pi * np.arange(length) / length) ** 2
        i += length + int(rng.uniform(0.03, 0.08) * SR)
    return out


def _voice(total_s: float, spans: list[tuple[float, float]], f0: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.zeros(int(total_s * SR))
    for a, b in spans:
        x[int(a * SR):int(b * SR)] += _syllables(a, b, rng, f0)
    return x


TOTAL = 8.0
#: Person 0 speaks 0.5-2.3 s (with a 0.2 s pause at 1.3-1.5 s, bridged) and 4.0-5.2 s; person 1
#: 2.6-3.7 s and 5.0-6.5 s (overlapping person 0 at 5.0-5.2 s).
SPANS_0 = [(0.5, 1.3), (1.5, 2.3), (4.0, 5.2)]
SPANS_1 = [(2.6, 3.7), (5.0, 6.5)]
WANT_0 = [(0.5, 2.3), (4.0, 5.2)]
WANT_1 = [(2.6, 3.7), (5.0, 6.5)]
LEAK = 10 ** (-25 / 20)  # channel 0 leaks into channel 1 at -25 dB
QUIET = 10 ** (-12 / 20)


@pytest.fixture(scope="module")
def voices() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    s0 = _voice(TOTAL, SPANS_0, 120.0, seed=1)
    s1 = _voice(TOTAL, SPANS_1, 210.0, seed=2)
    rng = np.random.default_rng(3)
    s0[int(7.0 * SR):int(7.05 * SR)] += 0.3 * rng.standard_normal(int(0.05 * SR))  # 50 ms blip
    n0, n1 = (0.001 * rng.standard_normal(len(s0)) for _ in range(2))  # -60 dBFS background
    return s0, s1, n0, n1


def _spans(turns: list[Turn], person: int) -> list[tuple[float, float]]:
    return [(t.t_start, t.t_end) for t in turns if t.person == person]


def _assert_spans(got: list[tuple[float, float]], want: list[tuple[float, float]]) -> None:
    assert len(got) == len(want), (got, want)
    for (a, b), (wa, wb) in zip(got, want, strict=True):
        assert abs(a - wa) <= 0.1 and abs(b - wb) <= 0.1, (got, want)


def test_turns_from_stereo_with_leakage(voices) -> None:
    s0, s1, n0, n1 = voices
    ch = np.stack([s0 + n0, s1 + LEAK * s0 + n1], axis=1).astype(np.float32)
    turns = turns_from_channels(ch)
    _assert_spans(_spans(turns, 0), WANT_0)  # the pause is bridged, the blip dropped
    _assert_spans(_spans(turns, 1), WANT_1)  # nothing from channel 0's leakage
    assert turns == sorted(turns, key=lambda t: t.t_start)
    assert all(t.t_end > t.t_start for t in turns)
    # overlap between persons is kept
    assert role_at(turns, 0, 5.1) == role_at(turns, 1, 5.1) == "speaking"


@pytest.mark.parametrize("gains", [(1.0, QUIET), (QUIET, 1.0), (QUIET, QUIET)])
def test_turns_do_not_depend_on_channel_gain(voices, gains) -> None:
    s0, s1, n0, n1 = voices
    ch = np.stack([s0 + n0, s1 + LEAK * s0 + n1], axis=1)
    ref = turns_from_channels(ch)
    quiet = turns_from_channels(ch * np.asarray(gains))
    assert len(quiet) == len(ref)
    for q, r in zip(quiet, ref, strict=True):
        assert q.person == r.person
        assert q.t_start == pytest.approx(r.t_start, abs=0.011)
        assert q.t_end == pytest.approx(r.t_end, abs=0.011)


def test_a_channel_of_only_leakage_is_no_speaker(voices) -> None:
    s0, _, n0, n1 = voices
    for leak_db in (-25, -18):
        turns = turns_from_channels(np.stack([s0 + n0, 10 ** (leak_db / 20) * s0 + n1], axis=1))
        assert _spans(turns, 1) == [], leak_db
        _assert_spans(_spans(turns, 0), WANT_0)


def test_silent_and_noise_only_channels_give_no_turns(voices) -> None:
    s0, _, n0, n1 = voices
    turns = turns_from_channels(np.stack([s0 + n0, np.zeros_like(s0)], axis=1))
    assert _spans(turns, 1) == []
    _assert_spans(_spans(turns, 0), WANT_0)
    assert turns_from_channels(np.stack([n0, n1], axis=1)) == []
    assert turns_from_channels(np.zeros((SR, 2), dtype=np.float32)) == []
    assert turns_from_channels(np.zeros((0, 2), dtype=np.float32)) == []
    # one (n,) channel is a mono recording of person 0
    _assert_spans(_spans(turns_from_channels(s0 + n0), 0), WANT_0)


def test_bridge_and_min_turn_are_in_seconds(voices) -> None:
    s0, _, n0, _ = voices
    unbridged = _spans(turns_from_channels(s0 + n0, bridge_s=0.1), 0)
    assert any(abs(b - 1.3) <= 0.1 for _, b in unbridged)  # the 0.2 s pause now splits a turn
    with_blip = _spans(turns_from_channels(s0 + n0, min_turn_s=0.02), 0)
    assert any(abs(a - 7.0) <= 0.05 for a, _ in with_blip)  # the 50 ms blip is kept


@pytest.mark.skipif(shutil.which("espeak-ng") is None or shutil.which("sox") is None,
                    reason="needs espeak-ng and sox")
def test_turns_from_espeak_dialogue() -> None:
    import importlib.util

    # tests/ is not a package: load the shared espeak-ng stimuli by path
    spec = importlib.util.spec_from_file_location(
        "_turns_stimuli", Path(__file__).resolve().parents[1] / "pipeline" / "stimuli.py")
    assert spec is not None and spec.loader is not None
    stimuli = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stimuli)
    say = stimuli.say

    a = say("the weather was lovely this morning")
    b = say("we should walk down to the river", pitch=80)
    i0, i1 = SR, SR + len(a) + int(0.6 * SR)
    n = i1 + len(b) + SR
    s0, s1 = np.zeros(n), np.zeros(n)
    s0[i0:i0 + len(a)], s1[i1:i1 + len(b)] = a, b
    rng = np.random.default_rng(5)
    ch = np.stack([s0 + 5e-4 * rng.standard_normal(n),
                   QUIET * (s1 + LEAK * s0) + 5e-4 * rng.standard_normal(n)], axis=1)
    turns = turns_from_channels(ch)
    _assert_spans(_spans(turns, 0), [(i0 / SR, (i0 + len(a)) / SR)])
    _assert_spans(_spans(turns, 1), [(i1 / SR, (i1 + len(b)) / SR)])


# --------------------------------------------------------------------------------------------
# load_channels
# --------------------------------------------------------------------------------------------


def _write_wav(path: Path, x: np.ndarray, rate: int) -> Path:
    """16-bit PCM WAV of float (n, ch) in [-1, 1], with the stdlib ``wave`` module."""
    pcm = np.clip(np.round(x * 32767.0), -32768, 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(pcm.shape[1])
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(pcm.tobytes())
    return path


def _peak_hz(x: np.ndarray) -> float:
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    return float(np.fft.rfftfreq(len(x), 1 / SR)[np.argmax(spec)])


@pytest.fixture(scope="module")
def stereo_wav(tmp_path_factory) -> Path:
    rate = 44_100
    t = np.arange(int(1.5 * rate)) / rate
    x = np.stack([0.5 * np.sin(2 * np.pi * 440 * t), 0.1 * np.sin(2 * np.pi * 1000 * t)], 1)
    return _write_wav(tmp_path_factory.mktemp("ch") / "stereo.wav", x, rate)


def test_load_channels_keeps_stereo_channels(stereo_wav: Path) -> None:
    x = load_channels(stereo_wav)
    assert x.dtype == np.float32 and x.ndim == 2 and x.shape[1] == 2
    assert abs(x.shape[0] - int(1.5 * SR)) <= 1
    mid = x[SR // 4: -SR // 4]
    assert _peak_hz(mid[:, 0]) == pytest.approx(440, abs=2)
    assert _peak_hz(mid[:, 1]) == pytest.approx(1000, abs=2)
    rms = np.sqrt(np.mean(mid.astype(np.float64) ** 2, axis=0))
    assert rms == pytest.approx([0.5 / np.sqrt(2), 0.1 / np.sqrt(2)], rel=0.01)
    # load_audio's mono mix is the mean of the kept channels (same resampler)
    mono, info = load_audio(stereo_wav)
    assert info.channels == 2
    np.testing.assert_allclose(x.mean(axis=1), mono, atol=1e-5)


def test_load_channels_mono_file(tmp_path: Path) -> None:
    t = np.arange(SR) / SR
    p = _write_wav(tmp_path / "mono.wav", 0.3 * np.sin(2 * np.pi * 300 * t)[:, None], SR)
    x = load_channels(p)
    assert x.shape == (SR, 1) and x.dtype == np.float32
    np.testing.assert_allclose(x[:, 0], load_audio(p)[0], atol=1e-7)


@pytest.mark.skipif(shutil.which("sox") is None, reason="needs sox")
def test_load_channels_decodes_other_formats_keeping_channels(stereo_wav: Path,
                                                              tmp_path: Path) -> None:
    flac = tmp_path / "stereo.flac"
    subprocess.run(["sox", str(stereo_wav), str(flac)], check=True, capture_output=True)
    x = load_channels(flac)
    assert x.shape[1] == 2 and abs(x.shape[0] - int(1.5 * SR)) <= 40
    mid = x[SR // 4: -SR // 4]
    assert _peak_hz(mid[:, 0]) == pytest.approx(440, abs=2)
    assert _peak_hz(mid[:, 1]) == pytest.approx(1000, abs=2)


def test_load_channels_errors(tmp_path: Path) -> None:
    with pytest.raises(GestureSimError, match="no such file"):
        load_channels(tmp_path / "nope.wav")
    (tmp_path / "empty.wav").write_bytes(b"")
    with pytest.raises(GestureSimError, match="empty file"):
        load_channels(tmp_path / "empty.wav")


# --------------------------------------------------------------------------------------------
# Roles, masks, checks
# --------------------------------------------------------------------------------------------

SMALL = [Turn(0, 0.1, 0.3), Turn(1, 0.25, 0.5), Turn(0, 0.6, 0.7)]


def test_role_at() -> None:
    assert role_at(SMALL, 0, 0.2) == "speaking"
    assert role_at(SMALL, 1, 0.2) == "listening"
    assert role_at(SMALL, 0, 0.28) == role_at(SMALL, 1, 0.28) == "speaking"  # overlap
    assert role_at(SMALL, 0, 0.3) == "listening"  # t_end is outside the turn
    assert role_at(SMALL, 0, 0.1) == "speaking"
    assert role_at(SMALL, 0, 0.65) == "speaking" and role_at(SMALL, 1, 0.65) == "listening"
    assert role_at([], 0, 0.0) == "listening"


def test_speaking_mask_is_one_inside_zero_outside_smooth_edges() -> None:
    n = int(0.8 * SR)
    m = speaking_mask(SMALL, 0, n, fade_s=0.01)
    assert m.shape == (n,) and m.dtype == np.float32
    assert m.min() >= 0.0 and m.max() <= 1.0
    t = np.arange(n) / SR
    inside = ((t >= 0.1) & (t <= 0.3)) | ((t >= 0.6) & (t <= 0.7))
    assert np.all(m[inside] == 1.0)
    far = (t < 0.09) | ((t > 0.31) & (t < 0.59)) | (t > 0.71)
    assert np.all(m[far] == 0.0)
    # raised-cosine fade: half way at 5 ms outside the edge, monotonic, steps far below a jump
    assert m[int(round(0.095 * SR))] == pytest.approx(0.5, abs=0.01)
    rise = m[int(0.09 * SR):int(0.1 * SR) + 1]
    assert np.all(np.diff(rise) >= 0) and np.max(np.abs(np.diff(m))) < 0.01
    hard = speaking_mask(SMALL, 0, n, fade_s=0.0)
    assert set(np.unique(hard)) == {0.0, 1.0}
    assert hard[int(0.2 * SR)] == 1.0 and hard[int(0.09 * SR)] == 0.0
    assert np.all(speaking_mask(SMALL, 2, n) == 0.0)


def test_voice_of_keeps_only_the_persons_turns() -> None:
    n = int(0.8 * SR)
    mono = np.ones(n, dtype=np.float32)
    v1 = voice_of(mono, SMALL, 1)
    assert v1.dtype == np.float32 and v1.shape == (n,)
    assert v1[int(0.4 * SR)] == 1.0 and v1[int(0.2 * SR)] == 0.0 and v1[int(0.65 * SR)] == 0.0
    both = voice_of(mono, SMALL, 0) + v1
    assert both[int(0.28 * SR)] == 2.0  # overlap: each person has the mix


def test_check_turns() -> None:
    check_turns(SMALL, 0.65, "d.rttm")  # the last turn may run past the end (by 0.5 s)
    with pytest.raises(GestureSimError, match=r"^d\.rttm: turn of person 0 at 0\.6 s \(to 0\.7 s\) "
                       r"lies after the audio ends \(0\.550 s"):
        check_turns(SMALL, 0.55, "d.rttm")
    long = [Turn(0, 1.0, 98.0)]           # one that runs 94 s past a 4 s audio (issue 49)
    check_turns(long, 97.5, "d.rttm")
    with pytest.raises(GestureSimError, match=r"to 98 s\) lies after the audio ends \(4\.000 s; "
                       r"a side file may run past the end by 0\.5 s at most\); the RTTM's turns "
                       r"are of recording 'other'"):
        check_turns(long, 4.0, "d.rttm", recording="other")
