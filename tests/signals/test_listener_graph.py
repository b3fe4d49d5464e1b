"""The listener motion graph of real frames (gesture_sim.signals.listener_graph) and the audio
listener playing it: planted nods, stillness and leans are found with the right times and
kinds, nothing in noise; the listener's joint targets are the excerpts' frames; interest raises
its nods; the envelope motion is unchanged (known answers of the code before the graph)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gesture_sim.errors import GestureSimError
from gesture_sim.signals.listener import LISTENER_JOINTS, ListenerConfig
from gesture_sim.signals.listener_audio import AudioListener, AudioListenerModel
from gesture_sim.signals.listener_graph import (
    ARM_JOINTS,
    GRAPH_JOINTS,
    Excerpt,
    ListenerGraph,
    extract_excerpts,
)

FPS = 30.0
SR = 16_000
DT = 1 / 30
NAMES = GRAPH_JOINTS + ARM_JOINTS
J = {n: i for i, n in enumerate(NAMES)}
GIDX = np.array([LISTENER_JOINTS.index(n) for n in GRAPH_JOINTS])


def _planted(n: int = 300) -> np.ndarray:
    """10 s at 30 fps: still, a nod of 8 degrees down and up over 0.6 s from 2.0 s (neck 0.4,
    head 0.6), still, a 4 degree forward lean of the lower spine over 1.5 s from 4.0 s, still;
    the arms still throughout."""
    t = np.arange(n) / FPS
    q = np.zeros((n, len(NAMES)))
    x = np.clip((t - 2.0) / 0.6, 0.0, 1.0)
    nod = math.radians(8.0) * 0.5 * (1.0 - np.cos(2.0 * np.pi * x))
    q[:, J["neck_flex"]] = 0.4 * nod
    q[:, J["head_flex"]] = 0.6 * nod
    y = np.clip((t - 4.0) / 1.5, 0.0, 1.0)
    q[:, J["lower_spine_flex"]] = math.radians(4.0) * 0.5 * (1.0 - np.cos(np.pi * y))
    q[:, J["left_elbow_flex"]] = 0.3                      # a bent arm, held
    return q


def _in(a: int, b: int, spans) -> bool:
    return any(lo <= a and b <= hi for lo, hi in spans)


def test_planted_nod_stillness_and_lean_are_found() -> None:
    ex = extract_excerpts(_planted(), NAMES, FPS, "planted")
    nods = [e for e in ex if e.kind == "nod"]
    shifts = [e for e in ex if e.kind == "posture"]
    rests = [e for e in ex if e.kind == "rest"]
    assert len(nods) == 1 and len(shifts) == 1
    nod = nods[0]
    assert abs(nod.start - 60) <= 2 and abs(nod.end - 78) <= 2       # 2.0 .. 2.6 s
    assert abs(nod.start + nod.peak - 69) <= 1                        # the lowest head, 2.3 s
    p = np.degrees(nod.frames[:, 0] + nod.frames[:, 3])
    assert p.max() - p[0] == pytest.approx(8.0, abs=0.3) and abs(p[-1] - p[0]) < 0.5
    sh = shifts[0]
    assert 120 <= sh.start <= 135 and 150 <= sh.end <= 165            # within 4.0 .. 5.5 s
    net = np.degrees(sh.frames[-1] - sh.frames[0])
    assert 3.0 <= net[GRAPH_JOINTS.index("lower_spine_flex")] <= 4.0   # forward, most of it
    assert np.abs(np.delete(net, GRAPH_JOINTS.index("lower_spine_flex"))).max() < 1e-9
    # rests: 0.5 s pieces, only where everything is still, chained end to start
    assert len(rests) >= 10
    assert all(e.n_frames == 16 for e in rests)
    assert all(_in(e.start, e.end, [(0, 60), (78, 135), (150, 300)]) for e in rests)
    assert not any(_in(e.start, e.end, [(60, 78)]) for e in rests)
    chained = [(a, b) for a, b in zip(rests[:-1], rests[1:], strict=True) if a.end == b.start]
    assert chained and all(np.array_equal(a.frames[-1], b.frames[0]) for a, b in chained)
    # excerpts are relative to the clip's median pose: the neck is at 0 at rest
    assert np.allclose(rests[0].frames[:, 0], 0.0)


def test_nothing_is_found_in_noise_and_moving_arms_are_no_rest() -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        noise = np.radians(rng.standard_normal((600, len(NAMES))))     # 1 degree, white
        assert extract_excerpts(noise, NAMES, FPS) == []
    q = _planted()
    q[:, J["right_shoulder_flex"]] = 0.3 * np.sin(2 * np.pi * np.arange(len(q)) / FPS)
    kinds = [e.kind for e in extract_excerpts(q, NAMES, FPS)]
    assert "rest" not in kinds and kinds.count("nod") == 1           # a gesturing arm
    # a bow (the spine flexes with the head) is no nod
    q = _planted()
    q[:, J["lower_spine_flex"]] += 2.0 * q[:, J["head_flex"]]
    assert "nod" not in [e.kind for e in extract_excerpts(q, NAMES, FPS)]


def _graph() -> ListenerGraph:
    return ListenerGraph(FPS, extract_excerpts(_planted(), NAMES, FPS, "planted"))


def test_cut_points_choice_and_round_trip(tmp_path) -> None:
    g = _graph()
    assert g.complete and g.counts()["nod"] == 1
    n = len(g.excerpts)
    assert g.cut_dist.shape == (n, n)
    # consecutive still pieces share their cut frame, and still ends are cut points
    a = next(i for i, e in enumerate(g.excerpts) if e.kind == "rest")
    assert g.cut_dist[a, a + 1] < 1e-9 and g.edges()[a, a + 1]
    # the distance is pose + velocity: the nod's start (moving down) is far from a still end
    nod = int(g.of_kind("nod")[0])
    f = g.excerpts[nod].frames
    v = (f[1] - f[0]) * FPS * g.settings.vel_weight_s
    assert g.cut_dist[a, nod] == pytest.approx(
        math.sqrt(np.sum((f[0] - g.excerpts[a].frames[-1]) ** 2) + np.sum(v ** 2)))
    # choice: the excerpt whose start fits the current pose
    far = Excerpt("rest", "x", 0, 15, np.full((16, len(GRAPH_JOINTS)), math.radians(10.0)), 7)
    g2 = ListenerGraph(FPS, [*g.excerpts, far])
    rng = np.random.default_rng(0)
    picks = [g2.choose("rest", far.frames[0], None, rng) for _ in range(50)]
    assert all(p == n for p in picks)
    picks = [g2.choose("rest", np.zeros(len(GRAPH_JOINTS)), None, rng) for _ in range(50)]
    assert n not in picks and len(set(picks)) > 3                    # seeded roulette
    with pytest.raises(GestureSimError, match="no nod"):
        ListenerGraph(FPS, [far]).choose("nod", far.frames[0], None, rng)
    p = tmp_path / "lg.npz"
    g.save(p)
    back = ListenerGraph.load(p)
    assert [(e.kind, e.start, e.end, e.peak) for e in back.excerpts] == \
        [(e.kind, e.start, e.end, e.peak) for e in g.excerpts]
    assert np.allclose(back.cut_dist, g.cut_dist, atol=1e-6)
    p.write_bytes(b"nope")
    with pytest.raises(GestureSimError, match="cannot read listener graph"):
        ListenerGraph.load(p)


@pytest.fixture(scope="module")
def speech() -> np.ndarray:
    """The shipped 11 s recording with 1 s of digital silence before and after (as in
    test_listener_audio)."""
    from gesture_sim import EXAMPLE_SPEECH
    from gesture_sim.audio.sources import load_audio

    x, _ = load_audio(EXAMPLE_SPEECH)
    return np.concatenate([np.zeros(SR), x.astype(float), np.zeros(SR)])


@pytest.fixture(scope="module")
def model(speech) -> AudioListenerModel:
    return AudioListenerModel.train([speech])


def _listen(lis, x: np.ndarray, dur: float, own=lambda t: False):
    lis.push_audio(x)
    out, events = [], []
    for k in range(int(dur / DT)):
        off, ev = lis.step(k * DT, own(k * DT))
        out.append(off)
        events += ev
    return np.array(out), events


def test_graph_motion_plays_the_excerpts_frames(model, speech) -> None:
    g = _graph()
    cfg = ListenerConfig(attend_tilt_rad=0.0, attend_lean_rad=0.0, p_brow=0.0,
                         attend_on_s=1e-6)
    lis = AudioListener(model, seed=2, config=cfg, interest=1.0, graph=g, settle_s=1e-9)
    assert lis.motion == "graph"
    dur = len(speech) / SR
    off, events = _listen(lis, speech, dur)
    assert {STATE for _, STATE in lis.states} >= {"rest", "nod"}
    times = np.arange(len(off)) * DT
    checked = 0
    for j, (t0, k, fps, _) in enumerate(lis.plays):
        frames = g.excerpts[k].frames
        t1 = lis.plays[j + 1][0] if j + 1 < len(lis.plays) else dur
        for i in np.flatnonzero((times > t0 + 1e-6) & (times < t1 - 1e-6)):
            u = int(round((times[i] - t0) * fps))
            assert np.allclose(off[i, GIDX], frames[min(u, len(frames) - 1)], atol=1e-9)
            checked += 1
    assert checked > 0.8 * len(off)
    other = np.setdiff1d(np.arange(len(LISTENER_JOINTS)), GIDX)
    assert np.all(off[:, other] == 0.0)                 # no brows, no attention: nothing else
    nods = [e for e in events if e[1].startswith("backchannel")]
    assert len(nods) == len(lis.backchannels) >= 1
    for b in lis.backchannels:                          # stamped at the excerpt's lowest head
        t0, k, fps, _ = next(p for p in lis.plays if p[0] == round(b.t_emitted, 4))
        assert g.excerpts[k].kind == "nod"
        assert b.t_peak == pytest.approx(t0 + g.excerpts[k].peak / fps)


def test_graph_motion_is_continuous_quiet_when_speaking_and_seeded(model, speech) -> None:
    dur = len(speech) / SR
    a = AudioListener(model, seed=4, interest=1.0, graph=_graph())
    off, ev = _listen(a, speech, dur)
    assert np.all(off[0] == 0.0)
    assert np.abs(np.diff(off, axis=0)).max() <= math.radians(2.0)
    b = AudioListener(model, seed=4, interest=1.0, graph=_graph())
    off_b, ev_b = _listen(b, speech, dur)
    assert ev == ev_b and np.array_equal(off, off_b)
    own = AudioListener(model, seed=4, graph=_graph())
    off_own, _ = _listen(own, speech, dur, own=lambda t: True)
    assert own.backchannels == [] and np.allclose(off_own, 0.0)


def test_interest_raises_the_graph_listeners_nods(model, speech) -> None:
    g = _graph()
    dur = len(speech) / SR
    counts = {}
    for interest in (0.0, 1.0):
        counts[interest] = 0
        for seed in range(10):
            lis = AudioListener(model, seed=seed, interest=interest, graph=g)
            _listen(lis, speech, dur)
            counts[interest] += sum(1 for _, s in lis.states if s == "nod")
    assert counts[1.0] > 1.2 * counts[0.0], counts


def test_the_motion_switch(model) -> None:
    shipped = AudioListener(model)                      # the shipped library has all states
    assert shipped.motion == "graph" and shipped.graph.complete
    no_shift = ListenerGraph(FPS, [e for e in _graph().excerpts if e.kind != "posture"])
    assert AudioListener(model, graph=no_shift).motion == "envelope"
    with pytest.raises(GestureSimError, match="at least one excerpt of each state"):
        AudioListener(model, graph=no_shift, motion="graph")
    with pytest.raises(GestureSimError, match="unknown listener motion"):
        AudioListener(model, motion="mimic")
    assert AudioListener(model, motion="envelope").graph is None


#: The envelope listener before the graph existed (same code path, recorded on this input):
#: (seed, interest) -> (sum |offsets|, sum offsets^2, number of events, first events, cuts).
ENVELOPE = {
    (3, None): (31.08943404523266, 0.9323200167623902, 2,
                [(3.3, "backchannel nod+brow"), (8.9, "backchannel nod")], 26),
    (5, 0.0): (31.609482641904123, 0.9547643213611339, 3,
               [(4.8, "backchannel nod"), (8.9, "backchannel nod"), (12.0, "backchannel nod")],
               26),
    (5, 1.0): (31.6236352934323, 0.9555919185441082, 3,
               [(4.8, "backchannel nod"), (8.4, "backchannel nod"), (12.0, "backchannel nod")],
               26),
}


def test_the_envelope_motion_is_unchanged(model, speech) -> None:
    dur = len(speech) / SR
    for (seed, interest), (s1, s2, n, first, cuts) in ENVELOPE.items():
        lis = AudioListener(model, seed=seed, interest=interest, motion="envelope")
        off, ev = _listen(lis, speech, dur)
        assert float(np.abs(off).sum()) == pytest.approx(s1, rel=1e-9)
        assert float((off ** 2).sum()) == pytest.approx(s2, rel=1e-9)
        assert len(ev) == n and ev[:len(first)] == first and len(lis.states) == cuts


def test_the_stored_graph_is_read_when_it_names_the_library(tmp_path) -> None:
    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.motion.library import MotionLibrary
    from gesture_sim.signals import listener_graph as lgm

    g = _graph()
    g.library = "abc123"
    (tmp_path / "manifest.json").write_text('{"fingerprint": "abc123"}')
    g.save(tmp_path / lgm.CACHE_FILE)
    got = lgm.default_listener_graph(tmp_path)
    assert got.counts() == g.counts() and got is lgm.default_listener_graph(tmp_path)
    other = tmp_path / "other"
    other.mkdir()
    (other / "manifest.json").write_text('{"fingerprint": "another"}')
    g.save(other / lgm.CACHE_FILE)                 # names another library: not used
    with pytest.raises(GestureSimError):
        lgm.default_listener_graph(other)          # so the library itself is read (none here)
    # the shipped graph is the extraction from the shipped library
    shipped = lgm.default_listener_graph()
    fresh = ListenerGraph.from_library(MotionLibrary.load(DEFAULT_LIBRARY_DIR))
    assert [(e.kind, e.clip, e.start, e.end) for e in shipped.excerpts] == \
        [(e.kind, e.clip, e.start, e.end) for e in fresh.excerpts]
    assert all(np.allclose(a.frames, b.frames, atol=1e-6)
               for a, b in zip(shipped.excerpts, fresh.excerpts, strict=True))


def test_a_pipelines_listener_plays_its_own_librarys_frames(model) -> None:
    """``listener_graph_for``: the shipped library's stored graph for the shipped library, an
    extraction for another library; the pipeline's audio listener gets the graph of its
    library, or the envelopes when asked."""
    from dataclasses import dataclass

    from gesture_sim.pipeline import GesturePipeline
    from gesture_sim.signals import listener_graph as lgm
    from gesture_sim.stages import ListenerLayer

    @dataclass
    class _Clip:
        name: str
        qpos: np.ndarray

    @dataclass
    class _Lib:
        clips: list
        joint_names: tuple = NAMES
        fps: float = FPS
        fingerprint: str = "planted-library"

    shipped = lgm.default_listener_graph()
    pipe = GesturePipeline.create(physics=False, listener=True, listener_model="okwechime")
    assert lgm.listener_graph_for(pipe.library) is shipped
    own = lgm.listener_graph_for(_Lib([_Clip("planted", _planted())]))
    assert own.library == "planted-library" and own.counts() == _graph().counts()
    listener = next(la for la in pipe.layers if isinstance(la, ListenerLayer)).listener
    assert listener.motion == "graph" and listener.graph is shipped
    env = GesturePipeline.create(physics=False, listener=True, listener_model="okwechime",
                                 listener_motion="envelope")
    listener = next(la for la in env.layers if isinstance(la, ListenerLayer)).listener
    assert listener.motion == "envelope" and listener.graph is None
