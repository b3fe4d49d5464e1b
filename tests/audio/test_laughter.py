"""The laugh detector (gesture_sim.audio.laughter) on espeak-ng / sox audio with known answers:
synthetic laughter found where it is, speech and silence not; streaming equals whole-file; and
the listeners smile at a partner's laugh and change nothing without one."""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.audio.laughter import LaughterDetector, detect_laughter
from gesture_sim.audio.sources import load_audio
from gesture_sim.signals.listener import LISTENER_JOINTS, ListenerConfig, ListenerSignals

DATA = Path(__file__).resolve().parents[1] / "data" / "audio"
SR = 16000
LEAD = 0.8          # s of silence before each synthetic sound
J = {n: i for i, n in enumerate(LISTENER_JOINTS)}
LIPS = [J["left_lip_corner_up"], J["right_lip_corner_up"]]

pytestmark = pytest.mark.skipif(not (shutil.which("espeak-ng") and shutil.which("sox")),
                                reason="needs espeak-ng and sox")


def _run(cmd: list[str]) -> None:
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _espeak(d: Path, name: str, text: str, voice: str, speed: int) -> np.ndarray:
    raw, out = d / f"{name}.raw.wav", d / f"{name}.wav"
    _run(["espeak-ng", "-v", voice, "-s", str(speed), "-w", str(raw), text])
    _run(["sox", str(raw), "-r", str(SR), "-c", "1", str(out), "pad", str(LEAD), "0.5"])
    return load_audio(out)[0]


@pytest.fixture(scope="module")
def sounds(tmp_path_factory) -> dict[str, np.ndarray]:
    """Every test sound, made once: laughter (``laugh_*``) and not (``speech_*``)."""
    d = tmp_path_factory.mktemp("laughter")
    out = {
        "laugh_espeak_f3": _espeak(d, "a", "ha ha ha ha", "en+f3", 175),
        "laugh_espeak_m3": _espeak(d, "b", "ho ho ho ho", "en+m3", 200),
        "speech_hello": _espeak(d, "c", "hello how are you", "en", 175),
        "speech_count": _espeak(d, "d", "one two three four", "en+f3", 175),
        "speech_ha": _espeak(d, "e", "ha", "en", 175),
        "speech_sentence": _espeak(d, "f", "I think that is a very good idea, don't you?",
                                   "en+m3", 175),
    }
    trem = d / "trem.wav"
    _run(["sox", "-n", "-r", str(SR), "-c", "1", str(trem), "synth", "1.2", "sawtooth", "220",
          "lowpass", "1500", "tremolo", "5", "95", "gain", "-n", "-6", "pad", str(LEAD),
          "0.5"])
    out["laugh_tremolo"] = load_audio(trem)[0]
    burst = d / "burst.wav"
    _run(["sox", "-n", "-r", str(SR), "-c", "1", str(burst), "synth", "0.11", "pinknoise",
          "highpass", "500", "fade", "q", "0.02", "0.11", "0.05", "gain", "-n", "-8"])
    bursts = d / "bursts.wav"
    _run(["sox", str(burst), str(bursts), "pad", "0", "0.09", "repeat", "3", "pad", str(LEAD),
          "0.5"])
    out["laugh_breathy"] = load_audio(bursts)[0]
    return out


def _sound_span(x: np.ndarray) -> tuple[float, float]:
    idx = np.flatnonzero(np.abs(x) > 0.02 * np.abs(x).max())
    return idx[0] / SR, idx[-1] / SR


@pytest.mark.parametrize("name", ["laugh_espeak_f3", "laugh_espeak_m3", "laugh_tremolo",
                                  "laugh_breathy"])
def test_synthetic_laughter_is_found_where_it_is(sounds, name: str) -> None:
    x = sounds[name]
    a, b = _sound_span(x)
    times, flags, laughs = detect_laughter(x)
    assert len(laughs) == 1, laughs
    lg = laughs[0]
    assert abs(lg.start - a) < 0.15 and abs(lg.end - b) < 0.35, (lg, a, b)
    assert lg.n_calls >= 3 and 3.0 < lg.rate_hz < 8.5
    assert lg.start < lg.t_detected < lg.end + 0.4            # decided once heard, soon after
    marked = times[flags]
    assert marked.min() >= a - 0.15 and marked.max() <= b + 0.35
    assert flags.mean() > 0.3 * (b - a) / (len(x) / SR)        # the span is marked, not a frame


@pytest.mark.parametrize("name", ["speech_hello", "speech_count", "speech_ha",
                                  "speech_sentence"])
def test_synthetic_speech_is_no_laugh(sounds, name: str) -> None:
    _, flags, laughs = detect_laughter(sounds[name])
    assert laughs == [] and not flags.any()


@pytest.mark.parametrize("path", sorted(DATA.glob("*.wav")), ids=lambda p: p.stem)
def test_real_speech_is_no_laugh(path: Path) -> None:
    """The repository's real speech (27 s: JFK, CMU Arctic, BEAT2) has no laughter, and the
    detector finds none (tools/laughter_eval.py measures longer sets)."""
    _, flags, laughs = detect_laughter(load_audio(path)[0])
    assert laughs == [] and not flags.any()


def test_silence_and_faint_noise_give_none() -> None:
    rng = np.random.default_rng(0)
    for x in (np.zeros(3 * SR), 10 ** (-70 / 20) * rng.standard_normal(3 * SR)):
        times, flags, laughs = detect_laughter(x)
        assert len(times) == 1 + (len(x) - 400) // 160 and not flags.any() and laughs == []


def test_streaming_in_any_blocks_equals_the_whole_file(sounds) -> None:
    x = np.concatenate([load_audio(DATA / "jfk.wav")[0], sounds["laugh_espeak_f3"],
                        sounds["speech_count"], sounds["laugh_tremolo"]])
    t_all, f_all, l_all = detect_laughter(x)
    assert len(l_all) == 2
    rng = np.random.default_rng(3)
    det = LaughterDetector()
    ts, fs, i = [], [], 0
    while i < len(x):
        n = int(rng.integers(1, 4000))
        t, f = det.push(x[i:i + n])
        i += n
        if len(t):        # a decision is final delay_s after the frame (causal, fixed latency)
            assert t[-1] <= i / SR - det.cfg.delay_s + 1e-9
        ts.append(t)
        fs.append(f)
    t, f = det.flush()
    ts.append(t)
    fs.append(f)
    assert np.array_equal(np.concatenate(ts), t_all)
    assert np.array_equal(np.concatenate(fs), f_all)
    assert det.laughs == l_all


def test_a_laugh_is_known_only_once_its_calls_are_heard(sounds) -> None:
    x = sounds["laugh_espeak_f3"]
    lg = detect_laughter(x)[2][0]
    before = LaughterDetector()
    before.push(x[: int((lg.t_detected - 0.01) * SR)])
    assert before.laughs == []
    at = LaughterDetector()
    at.push(x[: int(round(lg.t_detected * SR))])
    assert len(at.laughs) == 1 and at.laughs[0].t_detected == lg.t_detected


# ------------------------------------------------------------------ the listener's response

def _listen(listener, x: np.ndarray, block: int = 480) -> tuple[np.ndarray, list]:
    """Feed ``x`` as the partner's samples (30 ms blocks) and step at 100 Hz; returns the
    offsets (n, joints) and the events."""
    out = []
    for i in range(0, len(x) + 2 * SR, block):
        if i < len(x):
            listener.push_audio(x[i:i + block])
        for k in range(i // 160, (i + block) // 160):
            off, _ = listener.step(k * 0.01, own_speaking=False)
            out.append(off)
    return np.array(out), list(listener.events)


def test_the_listener_smiles_after_a_partner_laugh_and_not_without(sounds) -> None:
    laugh = sounds["laugh_espeak_f3"]
    lg = detect_laughter(laugh)[2][0]
    off, ev = _listen(ListenerSignals(seed=1), laugh)
    smiles = [t for t, e in ev if e == "laugh smile"]
    assert len(smiles) == 1 and lg.t_detected < smiles[0] < lg.t_detected + 1.0
    k = int(round(smiles[0] / 0.01))
    assert off[k, LIPS].min() > 0.0 and np.all(off[: int(lg.t_detected / 0.01), LIPS] == 0.0)
    # speech only: no laugh response, and the offsets are exactly those of a listener that
    # never heard the samples (the laugh path adds nothing without a laugh)
    speech = sounds["speech_sentence"]
    off_s, ev_s = _listen(ListenerSignals(seed=1), speech)
    assert not any(e.startswith("laugh") for _, e in ev_s)
    deaf = ListenerSignals(seed=1)
    off_d = np.array([deaf.step(k * 0.01, own_speaking=False)[0] for k in range(len(off_s))])
    assert np.array_equal(off_s, off_d)


def test_the_listener_laughs_back_and_not_while_it_speaks(sounds) -> None:
    laugh = sounds["laugh_tremolo"]
    cfg = replace(ListenerConfig(), p_laugh_back=1.0)
    off, ev = _listen(ListenerSignals(cfg, seed=0), laugh)
    kinds = [e for _, e in ev]
    assert "laugh back" in kinds and "laugh smile" in kinds
    assert np.abs(off[:, J["head_flex"]]).max() > 0.01          # the head bobs
    busy = ListenerSignals(cfg, seed=0)
    for i in range(0, len(laugh), 480):
        busy.push_audio(laugh[i:i + 480])
        for k in range(i // 160, (i + 480) // 160):
            busy.step(k * 0.01, own_speaking=True)
    assert not any(e.startswith("laugh") for _, e in busy.events)
    assert busy.laugh_responses and busy.laugh_responses[0][1] == "blocked own speech"


def test_the_audio_listener_smiles_at_a_laugh_too(sounds) -> None:
    from gesture_sim.signals.listener_audio import AudioListener

    lis = AudioListener(seed=0, motion="envelope")
    _, ev = _listen(lis, sounds["laugh_espeak_m3"])
    assert [e for _, e in ev].count("laugh smile") == 1
