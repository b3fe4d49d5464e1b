"""The Levine 2009 body sections: per-section segmentation at that section's speed minima,
clustering, a per-section HMM (trains, filters, stores), the composed three-stream target, and
the one-stream path unchanged for models without sections."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from gesture_sim.contracts import Syllable
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.inference.levine09 import Discretiser, Levine09Model, train_levine09
from gesture_sim.inference.levine09_sections import (
    DEFAULT_SETTINGS,
    SectionLibrary,
    SectionModel,
    load_levine09,
    section_joint_names,
    segment_section,
    train_sections,
)
from gesture_sim.inference.levine09_synthesis import Levine09Synthesis

FPS = 40.0
JOINTS = ("lower_spine_flex", "neck_flex", "neck_bend", "neck_twist", "head_flex", "head_bend",
          "head_twist", "left_shoulder_flex", "left_shoulder_abduct", "left_elbow_flex",
          "right_shoulder_flex", "right_shoulder_abduct", "right_elbow_flex", "left_hip_flex",
          "left_hip_abduct", "left_knee_flex", "right_hip_flex", "right_hip_abduct",
          "right_knee_flex")
HEAD = [JOINTS.index(j) for j in section_joint_names("head", JOINTS)]
ARMS = [JOINTS.index(j) for j in section_joint_names("arms", JOINTS)]
LOWER = [JOINTS.index(j) for j in section_joint_names("lower", JOINTS)]


def _sine_clip(seconds: float, head_hz: float = 2.0, arms_hz: float = 0.5,
               lower_hz: float = 0.25, seed: int | None = None) -> np.ndarray:
    """(T, n) joint angles: head joints at head_hz, arms at arms_hz, legs at lower_hz (sines
    from rest at t = 0; with a seed, amplitudes and frequencies vary slowly per cycle)."""
    t = np.arange(int(seconds * FPS)) / FPS
    q = np.zeros((len(t), len(JOINTS)))
    rng = np.random.default_rng(seed) if seed is not None else None
    for cols, hz, amp in ((HEAD, head_hz, 0.3), (ARMS, arms_hz, 0.5), (LOWER, lower_hz, 0.1)):
        phase = 2 * np.pi * hz * t
        a = amp if rng is None else amp * (1 + 0.6 * np.sin(2 * np.pi * rng.uniform(0.05, 0.2)
                                                            * t + rng.uniform(0, 6)))
        for k, c in enumerate(cols):
            q[:, c] = a * np.sin(phase) * (1.0 + 0.1 * k)
    return q


def test_each_section_is_cut_at_its_own_speed_minima() -> None:
    """Head 2 Hz, arms 0.5 Hz, legs 0.25 Hz: the joint speed |cos| has its minima every
    0.25 s, 1 s and 2 s (at the turning points, t = (2k + 1) / 4f); each section's cuts are
    exactly those, apart from the ones closer to the ends than its minimum length."""
    q = _sine_clip(6.0)
    n = len(q)
    expected = {"head": 2.0, "arms": 0.5, "lower": 0.25}
    cuts = {}
    for section, hz in expected.items():
        segs = segment_section(q, JOINTS, section, FPS)
        assert segs[0, 0] == 0 and segs[-1, 1] == n
        assert np.all(segs[1:, 0] == segs[:-1, 1])               # contiguous cover
        inner = segs[1:, 0]
        min_len = round(DEFAULT_SETTINGS[section].min_length_s * FPS)
        turns = [(2 * k + 1) / (4 * hz) * FPS for k in range(int(2 * hz * 6.0) + 2)]
        turns = [x for x in turns if min_len <= x <= n - min_len]
        assert len(inner) == len(turns), section
        assert np.max(np.abs(inner - np.array(turns))) <= 1.0, section
        cuts[section] = set(inner.tolist())
    assert cuts["head"] != cuts["arms"] != cuts["lower"]
    assert len(cuts["head"]) > 3 * len(cuts["arms"]) > 3 * len(cuts["lower"])


def test_a_still_section_is_split_only_by_its_maximum_length() -> None:
    q = _sine_clip(6.0)
    q[:, HEAD] = 0.1                                             # the head holds still
    segs = segment_section(q, JOINTS, "head", FPS)
    lengths = np.diff(segs, axis=1)[:, 0]
    assert lengths.max() <= DEFAULT_SETTINGS["head"].max_length_s * FPS
    assert len(segs) == int(np.ceil(len(q) / (DEFAULT_SETTINGS["head"].max_length_s * FPS)))


def _syllables(rng: np.random.Generator, duration: float) -> list[Syllable]:
    out, t = [], 0.3
    while t < duration:
        length = float(rng.uniform(0.12, 0.3))
        out.append(Syllable(t, t + length, t + length + 0.05, float(rng.uniform(100, 250)),
                            float(rng.normal(70, 6)), True))
        t += length + float(rng.uniform(0.1, 0.5))
    return out


@dataclass
class _Clip:
    name: str
    qpos: np.ndarray
    tags: tuple = ()
    source: str = "BEAT2 test"


@dataclass
class _MotionLibrary:
    clips: list
    joint_names: tuple = JOINTS
    fps: float = FPS


@pytest.fixture(scope="module")
def trained() -> tuple[np.ndarray, list[Syllable], dict[str, SectionModel], Levine09Model]:
    """A 60-s clip with varying sines, its syllables, the section models and an arms model
    (one-stream baseline over 2-s segments in 2 clusters)."""
    q = _sine_clip(60.0, head_hz=1.5, arms_hz=0.5, lower_hz=0.2, seed=3)
    syl = _syllables(np.random.default_rng(1), 60.0)
    stats = Discretiser.fit_stats(syl)
    segs = np.array([[a, a + 80] for a in range(0, len(q), 80)])
    arms = train_levine09([syl], [segs], [np.arange(len(segs)) % 2], 2, [FPS], 30.0, [60.0],
                          stats=stats)
    sections = train_sections([syl], [q], JOINTS, [FPS], 30.0, [60.0], arms.stats,
                              arms.silence_chunk_s)
    return q, syl, sections, arms


def test_each_section_model_trains_on_the_same_observations_and_filters(trained) -> None:
    q, syl, sections, arms = trained
    assert set(sections) == {"head", "lower"}
    for name, sec in sections.items():
        m = sec.model
        s = m.n_clusters
        assert s == sec.clusters.n_clusters == DEFAULT_SETTINGS[name].n_clusters
        assert m.stats == arms.stats and m.silence_chunk_s == arms.silence_chunk_s
        np.testing.assert_allclose(m.trans.sum(axis=1), 1.0)
        np.testing.assert_allclose(m.emit.sum(axis=1), 1.0)
        assert np.all(m.trans[s:, s:] == 0.0)                   # c_i -> c_i only via f_i
        assert np.all(m.logistic[:, 1] > 0)                     # decreasing continuation
        assert sum(sec.info["cluster_sizes"]) == sec.info["segments"]
        f = m.new_filter()
        order = sorted(syl, key=lambda x: x.t_emitted)
        k, changed = 0, 0
        prev = f.belief.copy()
        for i in range(600):
            t = i / 30.0
            new = []
            while k < len(order) and order[k].t_emitted <= t + 1e-9:
                new.append(order[k])
                k += 1
            b = f.step(t, new)
            assert b.shape == (s,) and abs(b.sum() - 1.0) < 1e-9 and np.all(b >= 0)
            changed += int(not np.allclose(b, prev))
            prev = b.copy()
        assert changed > 20
    # The head is cut more finely than the lower body, as its sines are faster.
    assert sections["head"].info["segments"] > 2 * sections["lower"].info["segments"]


def test_sections_store_under_their_own_prefixes_and_load_back(trained) -> None:
    _, _, sections, arms = trained
    plain_arrays, plain_meta = arms.to_arrays(), arms.meta()
    model = Levine09Model(arms.trans, arms.emit, arms.logistic, arms.mean_length_s, arms.stats,
                          arms.silence_chunk_s, sections=sections)
    arrays, meta = model.to_arrays(), model.meta()
    assert {k: v for k, v in arrays.items() if k in plain_arrays}.keys() == plain_arrays.keys()
    extra = set(arrays) - set(plain_arrays)
    assert extra and all(k.startswith(("l09_head_", "l09_lower_")) for k in extra)
    assert {k: v for k, v in meta.items() if k != "sections"} == plain_meta
    back = load_levine09(arrays, meta)
    for name, sec in sections.items():
        got = back.sections[name]
        for a in ("trans", "emit", "logistic", "mean_length_s"):
            np.testing.assert_array_equal(getattr(got.model, a), getattr(sec.model, a))
        np.testing.assert_array_equal(got.clusters.medoids, sec.clusters.medoids)
        np.testing.assert_array_equal(got.clusters.medoid_still, sec.clusters.medoid_still)
        assert got.clusters.joint_names == sec.clusters.joint_names
        assert got.clusters.settings == sec.clusters.settings


def test_old_model_arrays_and_meta_are_unchanged(trained) -> None:
    """A model without sections writes exactly the four arrays and two keys it always did, and
    loads with ``sections`` None."""
    _, _, _, arms = trained
    assert set(arms.to_arrays()) == {"l09_trans", "l09_emit", "l09_logistic",
                                     "l09_mean_length_s"}
    assert set(arms.meta()) == {"stats", "silence_chunk_s"}
    assert load_levine09(arms.to_arrays(), arms.meta()).sections is None


def _control_library(n_seg: int = 12, length: int = 40) -> ControlLibrary:
    """Arms segments whose qpos rows are ``100 + segment`` on every joint: any value that comes
    from an arms segment is recognisable."""
    def qpos(i: int) -> np.ndarray:
        return np.full((length, len(JOINTS)), 100.0 + i)

    return ControlLibrary(
        lengths=np.full(n_seg, length), interrupt_frames=np.full((n_seg, 1), 3),
        params=np.zeros((n_seg, 6)), d_sp=np.zeros((n_seg, n_seg)),
        d_in=np.zeros((n_seg, 1, n_seg)), tags=((),) * n_seg, fps=FPS, fingerprint="t",
        segment_qpos=qpos, joint_names=JOINTS)


def _drive(synth: Levine09Synthesis, syl: list[Syllable], seconds: float, each=None) -> list:
    """Step at FPS; ``each(result)`` is called right after every step."""
    order = sorted(syl, key=lambda x: x.t_emitted)
    out, k = [], 0
    for i in range(int(seconds * FPS)):
        t = i / FPS
        new = []
        while k < len(order) and order[k].t_emitted <= t + 1e-9:
            new.append(order[k])
            k += 1
        out.append(synth.step(t, new))
        if each is not None:
            each(out[-1])
    return out


def test_the_composed_target_takes_each_section_from_its_own_stream(trained) -> None:
    q, syl, sections, arms = trained
    model = Levine09Model(arms.trans, arms.emit, arms.logistic, arms.mean_length_s, arms.stats,
                          arms.silence_chunk_s, sections=sections)
    lib = _control_library()
    mlib = _MotionLibrary([_Clip("take", q.astype(np.float32))])
    clusters = np.arange(lib.n_segments) % 2
    synth = Levine09Synthesis(model, lib, seed=4, clusters=clusters, motion_library=mlib,
                              section_blend_frames=0)
    assert [s.name for s in synth.sections] == ["head", "lower"]
    head_cols = synth.sections[0].columns
    lower_cols = synth.sections[1].columns
    others = np.setdiff1d(np.arange(len(JOINTS)), np.concatenate([head_cols, lower_cols]))
    clip_q = mlib.clips[0].qpos
    switches = {"head": 0, "lower": 0}
    prev: dict[str, int] = {}

    def check(r) -> None:
        arm_q = lib.segment_qpos(r.segment)[r.frame]
        np.testing.assert_array_equal(r.target[others], arm_q[others])
        for name, cols in (("head", head_cols), ("lower", lower_cols)):
            clip, frame = synth.section_frame(name)
            assert clip == 0
            np.testing.assert_array_equal(r.target[cols], clip_q[frame, cols])
            assert not np.array_equal(r.target[cols], arm_q[cols])
            if name in prev and frame != prev[name] + 1:
                switches[name] += 1
            prev[name] = frame

    _drive(synth, syl, 30.0, check)
    # The streams decide independently: the sections jump elsewhere in the clip on their own.
    assert switches["head"] > 5 and switches["lower"] > 2
    assert len(synth.sections[0].decisions) > 0 and len(synth.sections[1].decisions) > 0


def test_section_switches_are_blended_on_their_joints(trained) -> None:
    q, syl, sections, arms = trained
    model = Levine09Model(arms.trans, arms.emit, arms.logistic, arms.mean_length_s, arms.stats,
                          arms.silence_chunk_s, sections=sections)
    lib = _control_library()
    mlib = _MotionLibrary([_Clip("take", q.astype(np.float32))])
    clusters = np.arange(lib.n_segments) % 2
    jumps = {}
    for blend in (0, 6):
        synth = Levine09Synthesis(model, lib, seed=4, clusters=clusters, motion_library=mlib,
                                  section_blend_frames=blend)
        out = np.array([r.target for r in _drive(synth, syl, 30.0)])
        jumps[blend] = float(np.abs(np.diff(out[:, synth.sections[0].columns], axis=0)).max())
    assert jumps[6] < jumps[0]


def test_the_arms_stream_and_the_old_path_are_unchanged_by_sections(trained) -> None:
    """Same seed: a model without sections, with the library given or not, and the arms stream
    of a model with sections play the same segments, frames and decisions; the one-stream
    targets are bit-identical."""
    q, syl, sections, arms = trained
    lib = _control_library()
    mlib = _MotionLibrary([_Clip("take", q.astype(np.float32))])
    clusters = np.arange(lib.n_segments) % 2
    with_sec = Levine09Model(arms.trans, arms.emit, arms.logistic, arms.mean_length_s,
                             arms.stats, arms.silence_chunk_s, sections=sections)
    runs = {}
    for key, model, ml in (("old", arms, None), ("old+lib", arms, mlib),
                           ("sections", with_sec, mlib)):
        synth = Levine09Synthesis(model, lib, seed=7, clusters=clusters, motion_library=ml)
        runs[key] = (_drive(synth, syl, 20.0), synth)
    assert runs["old"][1].sections == [] and runs["old+lib"][1].sections == []
    for key in ("old+lib", "sections"):
        for a, b in zip(runs["old"][0], runs[key][0], strict=True):
            assert (a.segment, a.frame) == (b.segment, b.frame)
            assert (a.decision is None) == (b.decision is None)
            if a.decision is not None:
                assert a.decision.kind == b.decision.kind
                ca, cb = a.decision.costs, b.decision.costs
                assert ca.keys() == cb.keys()
                assert all(ca[x] == cb[x] or (np.isnan(ca[x]) and np.isnan(cb[x])) for x in ca)
        assert len(runs["old"][1].decisions) == len(runs[key][1].decisions)
    for a, b in zip(runs["old"][0], runs["old+lib"][0], strict=True):
        assert a.target.tobytes() == b.target.tobytes()


def test_section_library_segments_only_the_cospeech_clips(trained) -> None:
    q, _, sections, _ = trained
    mlib = _MotionLibrary([_Clip("wave", q[:200].astype(np.float32), tags=("wave",),
                                 source="other"),
                           _Clip("take", q.astype(np.float32)),
                           _Clip("acted", q[:400].astype(np.float32), source="other")])
    src = SectionLibrary(mlib, sections["head"].clusters)
    assert set(src.clip.tolist()) == {1}
    assert src.starts[0] == 0 and src.ends[-1] == len(q)
    assert np.all(src.lengths >= 2) and src.labels.shape == (src.n_segments,)
    np.testing.assert_array_equal(
        src.features(3), q.astype(np.float32)[src.starts[3]:src.ends[3]][:, HEAD])


def test_training_adds_sections_only_when_the_takes_carry_joint_angles(trained) -> None:
    from types import SimpleNamespace

    from gesture_sim.inference.train import levine09_sections

    q, syl, _, arms = trained
    motion = SimpleNamespace(fps=FPS, qpos=q, joint_names=JOINTS)
    take = SimpleNamespace(syllables=syl, motion=motion)
    prepared = [SimpleNamespace(take=take, y=np.zeros((1800, 6)))]
    got = levine09_sections(prepared, 30.0, arms)
    assert set(got) == {"head", "lower"}
    assert all(s.model.stats == arms.stats for s in got.values())
    plain = SimpleNamespace(syllables=syl, motion=SimpleNamespace(fps=FPS))
    assert levine09_sections([SimpleNamespace(take=plain, y=np.zeros((1800, 6)))], 30.0,
                             arms) is None


def test_the_legs_follow_the_lower_body_stream_of_the_shipped_model() -> None:
    """With the default legs (the clip's lower body over planted feet), levine09's leg targets
    come from its own lower-body stream's clip frames, not from the arms stream's segment."""
    from pathlib import Path

    from gesture_sim.feed import run_file
    from gesture_sim.pipeline import GesturePipeline

    pipe = GesturePipeline.create(method="levine09", physics=False)
    synth = pipe.motion.chooser
    assert "lower" in pipe.model.baseline.sections and pipe.legs == "clip"
    lower = pipe.leg_stage.lower
    seen: list[tuple] = []
    step = lower.step

    def spy(segment, frame, clip_frame=None):
        seen.append((segment, frame, clip_frame, synth.section_frame("lower")))
        return step(segment, frame, clip_frame)

    lower.step = spy
    run_file(pipe, Path(__file__).parents[1] / "data" / "audio" / "jfk.wav")
    assert len(seen) > 300
    assert all(c is not None and c == s for _, _, c, s in seen)
    lib = pipe.library
    # the lower stream's frames are not the arms stream's: the two differ most of the time
    differ = [(lib.segments[g].clip, lib.segments[g].start + f) != c
              for g, f, c, _ in seen if g >= 0]
    assert len(differ) > 300 and np.mean(differ) > 0.5
    # and what the legs target moves with the stream: the pelvis offsets the stage read
    offsets = np.array([lower.clip_target(*c) for _, _, c, _ in seen])
    assert np.ptp(offsets[:, 1]) > 0.0
