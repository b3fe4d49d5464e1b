"""The audio-driven listener (gesture_sim.signals.listener_audio): the MFCC front end against
hand computations, the 25-class codebook, the projection mapping (Eq. 4.5) and the causal
listener with the rule listener's interface."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.signals import listener_audio as la
from gesture_sim.signals.listener import LISTENER_JOINTS, ListenerSignals
from gesture_sim.signals.listener_audio import (
    STATES,
    AudioCodebook,
    AudioListener,
    AudioListenerModel,
    MfccStream,
    ProjectionMapping,
    cepstra,
    mel_filterbank,
    mfcc,
)
from gesture_sim.signals.listeners import make_listener
from gesture_sim.signals.sdm import SignalTable

SR = 16_000
DT = 1 / 30


def _htk_mel_points(n: int = 26, fmax: float = 8000.0) -> np.ndarray:
    """By hand: n + 2 points equally spaced on 2595 log10(1 + f / 700) from 0 to fmax, Hz."""
    top = 2595.0 * math.log10(1.0 + fmax / 700.0)
    return np.array([700.0 * (10 ** (top * i / (n + 1) / 2595.0) - 1.0) for i in range(n + 2)])


def test_the_filterbank_is_htk_triangles() -> None:
    fb = mel_filterbank()
    assert fb.shape == (26, 257)
    pts = _htk_mel_points()
    freqs = np.arange(257) * SR / 512
    for i in range(26):
        k = int(np.argmax(fb[i]))
        assert abs(freqs[k] - pts[i + 1]) <= SR / 512          # peak at its centre (1 bin)
        assert np.all(fb[i][(freqs <= pts[i]) | (freqs >= pts[i + 2])] == 0.0)
    assert pts[1] == pytest.approx(68.5, abs=0.1)              # the first centre, by hand


def test_a_pure_tone_lands_in_its_mel_band() -> None:
    """A tone at band 9's centre frequency (by hand, 1080 Hz): band 9 holds the most energy,
    its neighbours (whose edges lie at that frequency) far less."""
    f = _htk_mel_points()[10]
    assert 1000.0 < f < 1100.0
    x = 0.5 * np.sin(2 * np.pi * f * np.arange(SR // 2) / SR)
    pre = x - 0.97 * np.concatenate([[0.0], x[:-1]])
    frame = pre[1600:1920] * np.hamming(320)
    power = np.abs(np.fft.rfft(frame, 512)) ** 2
    bands = power @ mel_filterbank().T
    assert int(np.argmax(bands)) == 9
    assert bands[9] > 8 * max(bands[8], bands[10])       # the window's main lobe leaks


def test_energy_and_cepstra_by_hand() -> None:
    x = np.full(SR // 10, 0.5)
    times, feats = mfcc(x)
    assert len(times) == 1 + (1600 - 320) // 160 == 9
    assert times[0] == pytest.approx(0.01) and np.allclose(np.diff(times), 0.01)
    assert feats.shape == (9, 13)
    assert np.allclose(feats[:, 12], math.log(320 * 0.25))     # ln sum x^2 of the raw frame
    # a flat log-mel spectrum has no cepstrum; a cosine over the bands only its coefficient
    assert np.allclose(cepstra(np.full(26, 3.0)), 0.0)
    m = np.arange(26)
    c = cepstra(np.cos(np.pi * 4 * (m + 0.5) / 26))
    expect = np.zeros(12)
    expect[3] = math.sqrt(26 / 2) * (1 + 11 * math.sin(math.pi * 4 / 22))
    assert np.allclose(c, expect, atol=1e-9)
    # silence: the energy floor, finite features
    _, sil = mfcc(np.zeros(800))
    assert np.all(np.isfinite(sil)) and np.allclose(sil[:, 12], math.log(1e-10))
    assert mfcc(np.zeros(100))[1].shape == (0, 13)


def test_streaming_equals_batch() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(SR) * 0.1
    t_all, f_all = mfcc(x)
    st = MfccStream()
    parts = [st.push(x[a:a + n]) for a, n in ((0, 100), (100, 457), (557, 3000), (3557, 12443))]
    t_s = np.concatenate([p[0] for p in parts])
    f_s = np.concatenate([p[1] for p in parts])
    assert np.array_equal(t_all, t_s)
    assert np.allclose(f_all, f_s, atol=1e-9)


@pytest.fixture(scope="module")
def speech() -> np.ndarray:
    """Real speech (the shipped 11 s recording) with 1 s of digital silence before and after."""
    from gesture_sim import EXAMPLE_SPEECH
    from gesture_sim.audio.sources import load_audio

    x, _ = load_audio(EXAMPLE_SPEECH)
    return np.concatenate([np.zeros(SR), x.astype(float), np.zeros(SR)])


@pytest.fixture(scope="module")
def model(speech) -> AudioListenerModel:
    return AudioListenerModel.train([speech])


def test_the_codebook_has_25_classes_and_separates_silence(model, speech) -> None:
    book = model.codebook
    assert book.n_classes == 25 and book.centres.shape == (25, 13)
    _, f = mfcc(speech)
    cls = book.predict(f)
    assert len(np.unique(cls)) == 25                            # every class is used
    z = (f - book.mean) / book.std
    d = ((z[:, None] - book.centres[None]) ** 2).sum(axis=2)
    assert np.array_equal(cls, np.argmin(d, axis=1))
    silent = cls[:90]                                           # the leading second
    assert len(np.unique(silent)) == 1 and not model.mapping.speech[silent[0]]
    assert model.mapping.p[silent[0]].tolist() == [1.0, 0.0, 0.0]
    with pytest.raises(GestureSimError, match="at least"):
        AudioCodebook.fit(f[:10])


def test_the_projection_mapping_is_eq_4_5() -> None:
    classes = np.array([0, 0, 0, 0, 1, 1, 2, 2, 2, 2])
    states = np.array([0, 1, 1, 1, 2, 0, 0, 0, 0, 1])
    mp = ProjectionMapping.fit(classes, states, n_classes=4)
    assert np.allclose(mp.p[0], [0.25, 0.75, 0.0])              # |C_q ∩ E_r| / N_r
    assert np.allclose(mp.p[1], [0.5, 0.0, 0.5])
    assert np.allclose(mp.p[2], [0.75, 0.25, 0.0])
    assert np.allclose(mp.p[3], [0.5, 0.4, 0.1])                # unseen class: the prior
    assert np.allclose(mp.p.sum(axis=1), 1.0)
    with pytest.raises(GestureSimError):
        ProjectionMapping.fit(classes, states[:-1])


def _listen(lis, x: np.ndarray, dur: float, own=lambda t: False, stream: bool = False):
    """Step at 30 Hz; audio pushed up front or in 30 Hz blocks. Returns (offsets, events)."""
    if not stream:
        lis.push_audio(x)
    sent, out, events = 0, [], []
    for k in range(int(dur / DT)):
        t = k * DT
        if stream:
            n = min(int(t * SR), len(x))
            if n > sent:
                lis.push_audio(x[sent:n])
                sent = n
        off, ev = lis.step(t, own(t))
        out.append(off)
        events += ev
    return np.array(out), events


def test_a_learned_mapping_drives_the_listener(speech) -> None:
    """Paired data: the listener nodded whenever the speaker was loud. The learned listener
    nods during loud speech and rests in silence."""
    _, f = mfcc(speech)
    loud = f[:, 12] > np.percentile(f[:, 12], 60)
    states = np.where(loud, 1, 0)
    mdl = AudioListenerModel.train([speech], [states])
    assert mdl.mapping.source == "paired"
    lis = AudioListener(mdl, seed=1)
    off, events = _listen(lis, speech, len(speech) / SR)
    bcs = lis.backchannels
    assert len(bcs) >= 3
    assert all(1.0 <= b.t_emitted <= len(speech) / SR - 1.0 + 0.4 for b in bcs)
    assert np.diff([b.t_emitted for b in bcs]).min() >= lis.cfg.refractory_s - 1e-9
    assert off.shape[1] == len(LISTENER_JOINTS)
    # paired training with a frame count that does not match is refused
    with pytest.raises(GestureSimError, match="one listener state per MFCC frame"):
        AudioListenerModel.train([speech], [states[:-5]])


def test_the_fallback_listener_is_causal_quiet_in_silence_and_at_own_speech(model, speech
                                                                           ) -> None:
    dur = len(speech) / SR
    a, b = AudioListener(model, seed=3), AudioListener(model, seed=3)
    off_a, ev_a = _listen(a, speech, dur)
    off_b, ev_b = _listen(b, speech, dur, stream=True)
    assert ev_a == ev_b and np.allclose(off_a, off_b)           # causal streaming = batch
    assert a.backchannels, "the fallback nods at speech"
    assert all(1.0 <= bc.t_emitted <= dur - 1.0 + 0.4 for bc in a.backchannels)
    assert np.all(off_a[0] == 0.0)
    step = np.abs(np.diff(off_a, axis=0))
    assert step.max() <= math.radians(2.0)                      # smooth
    own = AudioListener(model, seed=3)
    off_own, _ = _listen(own, speech, dur, own=lambda t: True)
    assert own.backchannels == [] and np.allclose(off_own, 0.0)
    a.reset()
    off_r, ev_r = _listen(a, speech, dur)
    assert ev_r == ev_a


def test_interest_raises_the_audio_listeners_nods(model, speech) -> None:
    dur = len(speech) / SR
    counts = {}
    for interest in (0.0, 1.0):
        n = 0
        for seed in range(24):
            lis = AudioListener(model, seed=seed, interest=interest)
            _listen(lis, speech, dur)
            n += len(lis.backchannels)
        counts[interest] = n
    assert counts[1.0] > 1.2 * counts[0.0]
    w = AudioListener(model, interest=0.5)
    w.push_audio(speech[: 3 * SR])
    w.step(2.5, False)
    w_none = AudioListener(model)
    w_none.push_audio(speech[: 3 * SR])
    w_none.step(2.5, False)
    assert np.allclose(w.weights(), w_none.weights())           # 0.5 = no scaling


def test_model_round_trip_and_make_listener(model, tmp_path) -> None:
    p = tmp_path / "al.json"
    model.save(p)
    back = AudioListenerModel.load(p)
    assert np.allclose(back.codebook.centres, model.codebook.centres)
    assert np.allclose(back.mapping.p, model.mapping.p)
    p.write_text("[]")
    with pytest.raises(GestureSimError, match="cannot read audio listener"):
        AudioListenerModel.load(p)
    assert isinstance(make_listener("rule", seed=2), ListenerSignals)
    lis = make_listener("okwechime", seed=2, audio_model=model, interest=0.8)
    assert isinstance(lis, AudioListener) and lis.interest == 0.8
    lis.push_frames(np.zeros(1), np.zeros(1), np.ones(1, bool), np.zeros(1))   # accepted
    with pytest.raises(GestureSimError, match="unknown listener model"):
        make_listener("nope")


def test_states_from_an_sdm_table() -> None:
    table = SignalTable.from_intervals([("B", "nod", 0.0, 0.2), ("B", "activity", 0.1, 0.4)],
                                       fps=25.0)
    st = la.states_from_table(table, "B", np.array([0.05, 0.15, 0.3, 0.5]))
    assert [STATES[i] for i in st] == ["nod", "nod", "posture", "rest"]
