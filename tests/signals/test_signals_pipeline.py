"""Face and head signals through the whole pipeline and the physics, with known answers:
espeak-ng speech with two emphasised words (louder, higher) and a 2 s silence."""

from __future__ import annotations

import numpy as np
import pytest

from gesture_sim.feed import run_file
from gesture_sim.metrics.face import head_speed, speed_peaks, trace_figures
from gesture_sim.metrics.physics import physics_metrics
from gesture_sim.pipeline import GesturePipeline
from gesture_sim.signals.ruth import SIGNAL_JOINTS
from tests.pipeline.stimuli import HAVE_TOOLS, concat, say, silence, write

pytestmark = [pytest.mark.skipif(not HAVE_TOOLS, reason="espeak-ng and sox are needed"),
              pytest.mark.xdist_group("signals-pipeline")]       # one run of the module fixture
LOUD = {"pitch": 75, "amplitude": 126}


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    parts = [silence(0.3), say("this is a plain sentence that we say at first, then we go on"),
             silence(0.6), say("we went to the"), say("market", **LOUD),
             say("in the morning and"), silence(2.0), say("then we walked to the"),
             say("river", **LOUD), say("by the old house"), silence(0.5)]
    x, starts = concat(parts)
    wav = write(tmp_path_factory.mktemp("signals") / "emph.wav", x)
    pipe = GesturePipeline.create(seed=0)
    res = run_file(pipe, wav)
    trace = pipe.trace()
    m = pipe.sim.model
    jid = np.array([m.joint(n).id for n in SIGNAL_JOINTS])
    # the emphasised syllable: the loudest 10 ms frame of the word's first 0.3 s
    fr = pipe.tracker.frames()
    emph = []
    for i in (4, 8):
        w = (fr.times >= starts[i]) & (fr.times <= starts[i] + 0.3)
        emph.append(float(fr.times[w][np.nanargmax(fr.intensity_db[w])]))
    return {"pipe": pipe, "res": res, "trace": trace, "t": trace.time - trace.time[0],
            "q": trace.qpos[:, m.jnt_qposadr[jid]], "qd": trace.qvel[:, m.jnt_dofadr[jid]],
            "emph": emph, "silence": (starts[6], starts[7]), "frames": fr, "x": x}


def test_emphasised_syllables_get_head_speed_peaks_and_brow_raises(run: dict) -> None:
    t, q = run["t"], run["q"]
    spd = head_speed(run["qd"])
    peaks = speed_peaks(t, spd, 0.3)
    for te in run["emph"]:
        assert np.any(np.abs(peaks - te) <= 0.2), (te, peaks[np.abs(peaks - te) < 1])
        near = (t >= te - 0.2) & (t <= te + 0.2)
        brow = q[:, 7]
        k = np.argmax(np.where(near, brow, -1))
        assert brow[k] >= 0.005, f"no brow raise near {te:.2f} s"     # >= 5 of 12 mm
        assert t[k] < te + 0.2
    # brows and nods are for strong accents (RUTH: batons on the accents it marks, not on
    # every accent): most plain accents get neither, the emphasised words get a nod
    ev = run["pipe"].log.signals
    n_brow = sum(1 for _, e in ev if e.startswith("brow"))
    nods = np.array([tt for tt, e in ev if e.startswith("nod")])
    n_acc = sum(1 for _, e in ev if e.startswith("accent "))
    assert 2 <= n_brow <= 4 and n_acc >= 10
    assert 2 <= len(nods) <= n_acc / 2, (len(nods), n_acc)
    assert all(np.any(np.abs(nods - te) <= 0.3) for te in run["emph"]), (nods, run["emph"])


def test_silence_has_no_nods_or_brows_and_the_face_is_calm(run: dict) -> None:
    s0, s1 = run["silence"]
    ev = run["pipe"].log.signals
    assert not [e for e in ev if s0 + 0.3 < e[0] < s1 and e[1].startswith(("nod", "brow"))]
    assert any(e[1] == "calm" and s0 < e[0] < s0 + 0.8 for e in ev)
    t, q = run["t"], run["q"]
    mid = (t > s0 + 0.9) & (t < s1)
    assert q[mid, 7:9].max() < 0.001                         # brows down
    assert np.degrees(q[mid, 6].max()) < 1.0                 # jaw closed
    assert head_speed(run["qd"])[mid].max() < 0.3            # no nods


def test_blinks_are_realised_and_continue_without_speech() -> None:
    from gesture_sim.signals.ruth import RuthSignals

    sig = RuthSignals(seed=0)
    for k in range(int(60 / (1 / 30))):
        sig.step(k / 30, (), (), False, 10.0)
    assert 3 <= sum(1 for _, e in sig.events if e.startswith("blink")) <= 20


def test_eyelids_close_on_blinks(run: dict) -> None:
    t, q = run["t"], run["q"]
    blinks = [x for x, e in run["pipe"].log.signals if e.startswith("blink")]
    assert blinks
    for b in blinks:
        w = (t >= b - 0.05) & (t <= b + 0.1)
        assert q[w, 9].max() > 0.010 and q[w, 10].max() > 0.010


def test_jaw_follows_the_speech_envelope_and_closes_in_silence(run: dict) -> None:
    fr, t, q = run["frames"], run["t"], run["q"]
    env = np.where(fr.silent | ~np.isfinite(fr.intensity_db), np.nan, fr.intensity_db)
    floor = np.nanpercentile(env, 5)
    env = np.nan_to_num(env, nan=floor).clip(floor)
    jaw = np.interp(fr.times, t, q[:, 6])
    # the jaw is causal: it follows the frames as they become known (about 60 ms) through the
    # face's PD tracker (about 10 ms more); judged at the best lag up to 150 ms
    rs = [np.corrcoef(jaw[k:], env[:len(env) - k])[0, 1] for k in range(16)]
    assert max(rs) >= 0.6, rs
    assert np.corrcoef(jaw, env)[0, 1] > 0.4
    s0, s1 = run["silence"]
    assert np.degrees(jaw[(fr.times > s0 + 0.5) & (fr.times < s1)].max()) < 0.5


def test_face_in_range_within_torque_no_fall_no_assist(run: dict) -> None:
    pipe, trace = run["pipe"], run["trace"]
    fig = trace_figures(trace, pipe.sim.model, pipe.log.signals,
                        [a.t for a in pipe.log.accents], run["res"].duration)
    assert max(fig["range_excess_max"].values()) < np.radians(0.5)
    assert fig["force_saturation_share"] < 0.01
    assert fig["head_tracking_rms_deg"] < 3.0
    assert fig["counts"]["blink"] >= 2
    phys = physics_metrics(trace).to_dict()
    assert not phys["fell"]
    assert phys["assist_impulse_per_s"] == 0


def test_signals_off_keeps_the_clip_face(run: dict) -> None:
    pipe = GesturePipeline.create(seed=0, physics=False, signals=False)
    import tempfile
    from pathlib import Path

    from scipy.io import wavfile  # noqa: F401 (the same stimulus, from memory)

    from tests.pipeline.stimuli import write as w

    with tempfile.TemporaryDirectory() as tmp:
        run_file(pipe, w(Path(tmp) / "x.wav", run["x"]))
    assert pipe.signals is None and pipe.log.signals == []
    face = np.array(pipe.log.targets)[:, 12:17]
    assert np.all(face == 0)
    on = np.array(run["pipe"].log.targets)
    assert np.abs(on[:, 12:17]).max() > 0
