"""The Levine 2009 synthesis: syllable-timed starts, late termination, α⊙γ sampling, segment
choice, determinism; and an end-to-end run of the shipped model on real speech."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gesture_sim.contracts import Syllable
from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.errors import GestureSimError
from gesture_sim.inference.levine09 import (
    Discretiser,
    Levine09Filter,
    Levine09Model,
    ObservationStream,
)
from gesture_sim.inference.levine09_synthesis import Levine09Synthesis, clusters_by_likelihood

ROOT = Path(__file__).resolve().parents[2]
FPS = 30.0
S = 2
# Hand-made library: 10 segments, clusters 0 0 0 0 1 1 1 1 0 1; segment 8 is tagged (an emblem).
LENGTHS = np.array([12, 15, 10, 20, 9, 14, 18, 11, 12, 16])
CLUSTERS = np.array([0, 0, 0, 0, 1, 1, 1, 1, 0, 1])
START_POSE = np.array([0.0, 0.02, 0.5, 1.0, 0.0, 0.3, 0.31, 0.9, 0.0, 0.0])
END_POSE = np.array([0.2, 0.8, 0.4, 0.1, 0.6, 0.05, 0.7, 0.35, 0.5, 0.0])


def _qpos(i: int) -> np.ndarray:
    """(length, 3): the first column ramps from the start pose to the end pose."""
    ramp = np.linspace(START_POSE[i], END_POSE[i], LENGTHS[i])
    return np.stack([ramp, np.zeros_like(ramp), np.zeros_like(ramp)], axis=1)


def _library() -> ControlLibrary:
    n = len(LENGTHS)
    tags = tuple(("wave",) if i == 8 else () for i in range(n))
    return ControlLibrary(
        lengths=LENGTHS, interrupt_frames=np.full((n, 1), 3), params=np.zeros((n, 6)),
        d_sp=np.zeros((n, n)), d_in=np.zeros((n, 1, n)), tags=tags, fps=FPS,
        fingerprint="test", segment_qpos=_qpos)


def _model(cont_a: float = 3.0, cont_b: float = 4.0, silence_chunk_s: float = 0.5
           ) -> Levine09Model:
    """s_0, s_1, c_0, c_1; loud syllables favour cluster 1, quiet ones cluster 0."""
    trans = np.array([[0.1, 0.2, 0.7, 0.0],     # s_0 -> s_0, s_1, c_0
                      [0.2, 0.1, 0.0, 0.7],     # s_1 -> s_0, s_1, c_1
                      [0.4, 0.6, 0.0, 0.0],     # c_0 ends -> s_0, s_1
                      [0.5, 0.5, 0.0, 0.0]])    # c_1 ends -> s_0, s_1
    emit = np.full((2 * S, 36), 1.0)
    loud = [c for c in range(36) if (c // 3) % 3 == 2]
    emit[1, loud] = emit[3, loud] = 6.0
    emit /= emit.sum(axis=1, keepdims=True)
    logistic = np.array([[cont_a, cont_b], [cont_a, cont_b]])
    stats = {"change": (0.0, 2.0), "intensity": (70.0, 6.0), "length": (0.2, 0.08)}
    return Levine09Model(trans, emit, logistic, np.array([0.5, 0.45]), stats, silence_chunk_s)


def _syllables(rng: np.random.Generator, duration: float, gap: tuple[float, float] = (0.1, 0.5)
               ) -> list[Syllable]:
    out, t = [], 0.3
    while t < duration:
        length = float(rng.uniform(0.12, 0.3))
        out.append(Syllable(t, t + length, t + length + 0.05,
                            float(rng.uniform(100, 250)), float(rng.normal(70, 6)), True))
        t += length + float(rng.uniform(*gap))
    return out


def _drive(synth: Levine09Synthesis, syllables: list[Syllable], duration: float) -> list:
    """Step the synthesis at 30 Hz; returns (t, syllables of the step, StepResult) per step."""
    order = sorted(syllables, key=lambda s: s.t_emitted)
    out, k = [], 0
    for i in range(int(duration * FPS)):
        t = i / FPS
        new = []
        while k < len(order) and order[k].t_emitted <= t + 1e-9:
            new.append(order[k])
            k += 1
        out.append((t, new, synth.step(t, new)))
    return out


def _observation_steps(model: Levine09Model, steps: list) -> set[int]:
    """Steps at which the model's causal observation stream issues a symbol (independently)."""
    stream = ObservationStream(Discretiser(model.stats), model.silence_chunk_s)
    return {i for i, (t, new, _) in enumerate(steps) if stream.advance(t, new)}


@pytest.fixture(scope="module")
def lib() -> ControlLibrary:
    return _library()


def _synth(lib: ControlLibrary, seed: int = 0, **kw) -> Levine09Synthesis:
    return Levine09Synthesis(kw.pop("model", _model()), lib, seed=seed, clusters=CLUSTERS, **kw)


def test_segments_start_only_at_observations_or_late_terminations(lib) -> None:
    model = _model()
    synth = _synth(lib, 1, model=model)
    steps = _drive(synth, _syllables(np.random.default_rng(0), 30.0), 30.0)
    obs = _observation_steps(model, steps)
    by_step: dict[int, list[str]] = {}
    for d in synth.decisions:
        by_step.setdefault(round(d.t * FPS), []).append(d.kind)
    kinds = [k for ks in by_step.values() for k in ks]
    assert kinds.count("early") >= 5 and kinds.count("late") >= 3
    assert kinds.count("continue") >= 10 and kinds.count("start") == 1
    for i, (_, _, r) in enumerate(steps):
        if i == 0:
            assert r.frame == 0 and by_step[0][0] == "start"
            continue
        prev = steps[i - 1][2]
        new_segment = r.frame == 0
        if not new_segment:                     # one frame per step, same segment
            assert r.segment == prev.segment and r.frame == prev.frame + 1
            assert "late" not in by_step.get(i, [])
            continue
        assert r.decision is not None and not r.decision.costs["continue"]
        if r.decision.kind in ("early", "end"):
            assert i in obs                     # a start state sampled at an observation
        else:
            assert r.decision.kind == "late"    # the playing segment had shown its last frame
            assert prev.frame == lib.lengths[prev.segment] - 1
    # Every observation step took a decision; no decision away from observations but "late".
    for i in obs:
        assert set(by_step[i]) & {"continue", "early", "end"}
    for i, ks in by_step.items():
        if i not in obs:
            assert set(ks) <= {"late", "start"}


def test_late_termination_redoes_the_last_observation_with_continuation_forbidden(lib) -> None:
    """Observations 1.5 s apart, segments under 0.7 s: every segment runs out between them. The
    redo must start from α_{t-1}, τ̄_{t-1} (not update twice) with → c_i forbidden."""
    model = _model(cont_a=6.0, cont_b=1.0, silence_chunk_s=1.5)
    synth = _synth(lib, 3, model=model)
    replica = Levine09Filter(model)
    replica_stream = ObservationStream(Discretiser(model.stats), model.silence_chunk_s)
    snap = replica.snapshot()
    last_obs: tuple[float, int] | None = None
    displayed_before_obs = -1
    n_late = 0
    for i in range(int(8.0 * FPS)):
        t = i / FPS
        state_before = synth.state
        codes = replica_stream.advance(t, [])
        for code in codes:
            snap = replica.snapshot()
            replica.observe(t, code)
            last_obs, displayed_before_obs = (t, code), state_before
        r = synth.step(t, [])
        if r.decision is not None and r.decision.kind == "late" and last_obs is not None:
            n_late += 1
            i_prev = displayed_before_obs % S
            expected = Levine09Filter(model)
            expected.restore(snap)
            expected.observe(*last_obs, forbid=(i_prev,))
            np.testing.assert_allclose(synth.filter.alpha, expected.alpha, atol=1e-12)
            np.testing.assert_allclose(synth.filter.tau, expected.tau, atol=1e-12)
            assert synth.filter.alpha[S + i_prev] == 0.0
            assert r.decision.costs["state"] < S            # a start state was sampled
            assert r.frame == 0 and r.decision.costs["p_gamma"] > 0
            replica.restore(snap)                            # keep the replica in step
            replica.observe(*last_obs, forbid=(i_prev,))
    assert n_late >= 4


def test_step_transitions_forbid_renormalises_rows() -> None:
    model = _model()
    p = model.step_transitions(np.array([0.3, 0.6]))
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    q = model.step_transitions(np.array([0.3, 0.6]), forbid=(0,))
    np.testing.assert_allclose(q.sum(axis=1), 1.0)
    assert np.all(q[:, S + 0] == 0.0) and q[1, S + 1] == p[1, S + 1]
    np.testing.assert_allclose(q[S + 0, :S], model.trans[S + 0, :S])   # c_0 row -> T_c0


def test_sampled_state_follows_alpha_times_gamma(lib) -> None:
    """Many seeds, one observation each: the counts of each sampled state must match the sum
    of the exact normalize(α ⊙ γ) probabilities, computed independently (Poisson-binomial)."""
    model = _model()
    syl = Syllable(0.05, 0.2, 0.2, 180.0, 80.0, True)         # loud: favours cluster 1
    quiet = Syllable(0.25, 0.4, 0.4, 120.0, 62.0, True)
    synth = _synth(lib, 0, model=model)
    n = 1500
    expected = np.zeros(2 * S)
    var = np.zeros(2 * S)
    counts = np.zeros(2 * S)
    checked = 0
    for seed in range(n):
        synth.seed = seed
        synth.reset()
        for i in range(6):
            synth.step(i / FPS, [])
        start = synth.decisions[0]
        t = 6 / FPS
        synth.step(t, [syl])
        d = synth.decisions[-1]
        k = int(start.costs["state"])                          # displayed s_k
        disc = Discretiser(model.stats)
        code = disc.observe(syl)
        filt = Levine09Filter(model)
        filt.observe(t, code)
        tau = np.zeros(S)
        tau[k] = 6 / lib.lengths[start.segment_id]
        gamma = model.step_transitions(tau)[k] * model.emit[:, code]
        p = filt.alpha * gamma
        p /= p.sum()
        expected += p
        var += p * (1 - p)
        counts[int(d.costs["state"])] += 1
        assert d.costs["p"] == pytest.approx(p[int(d.costs["state"])], rel=1e-9)
        if seed % 10:
            continue
        # A second observation 6 frames later: γ from the displayed state with its true τ'.
        for i in range(7, 12):
            synth.step(i / FPS, [])
        t2 = 12 / FPS
        synth.step(t2, [quiet])
        d2 = synth.decisions[-1]
        if synth.decisions[-2] is not d:                       # a late termination came between
            continue
        checked += 1
        prev = int(d.costs["state"])
        if prev >= S:                                          # c_k: the first segment goes on
            nxt, length = 12, lib.lengths[start.segment_id]
        else:                                                  # s_j started at step 6
            nxt, length = 6, lib.lengths[d.segment_id]
        forbid = (prev % S,) if nxt > length - 1 else ()
        code2 = disc.observe(quiet)
        filt.observe(t2, code2, forbid)
        tau = np.zeros(S)
        tau[prev % S] = nxt / length
        gamma = model.step_transitions(tau, forbid)[prev] * model.emit[:, code2]
        p2 = filt.alpha * gamma
        p2 /= p2.sum()
        assert d2.costs["p"] == pytest.approx(p2[int(d2.costs["state"])], rel=1e-9)
        assert d2.costs["tau"] == pytest.approx(nxt / length)
    assert checked >= 50
    assert np.all(np.abs(counts - expected) <= 4 * np.sqrt(var) + 1)
    assert np.count_nonzero(counts >= 0.05 * n) >= 3          # sampled, not an argmax


def test_segment_choice_respects_pose_tolerance_and_allowed(lib) -> None:
    model = _model()
    allowed = np.ones(len(LENGTHS), dtype=bool)
    allowed[[8, 9]] = False          # 8: the tagged one (also excluded by default); 9: by hand
    for tol, seeds in ((0.0, range(4)), (0.05, range(4)), (10.0, range(2))):
        chosen: dict[int, set[int]] = {0: set(), 1: set()}
        for seed in seeds:
            synth = _synth(lib, seed, model=model, allowed=allowed, pose_tolerance=tol)
            steps = _drive(synth, _syllables(np.random.default_rng(seed), 20.0), 20.0)
            for i, (_, _, r) in enumerate(steps):
                assert allowed[r.segment]
                if i == 0 or r.frame != 0:
                    continue
                ref = steps[i - 1][2].target                 # the frame shown last
                j = CLUSTERS[r.segment]
                members = np.flatnonzero(allowed & (CLUSTERS == j))
                d = {m: float(np.linalg.norm(_qpos(m)[0] - ref)) for m in members}
                assert d[r.segment] <= min(d.values()) + tol + 1e-12
                assert r.decision.costs["pose_diff"] == pytest.approx(d[r.segment])
                chosen[j].add(int(r.segment))
        if tol >= 10.0:                   # uniform over the whole cluster
            assert chosen[0] == {0, 1, 2, 3} and chosen[1] == {4, 5, 6, 7}
    default = _synth(lib, 0, model=model)
    assert not default.allowed[8] and default.allowed[9]


def test_same_seed_same_run_and_seeds_differ(lib) -> None:
    syl = _syllables(np.random.default_rng(5), 15.0)
    a, b, c = (_drive(_synth(lib, s), syl, 15.0) for s in (7, 7, 8))
    frames = [[(r.segment, r.frame) for *_, r in x] for x in (a, b, c)]
    assert frames[0] == frames[1] and frames[0] != frames[2]
    synth = _synth(lib, 7)
    _drive(synth, syl, 15.0)
    first = [(d.t, d.kind, d.segment_id, d.costs["state"]) for d in synth.decisions]
    synth.reset()
    _drive(synth, syl, 15.0)
    assert first == [(d.t, d.kind, d.segment_id, d.costs["state"]) for d in synth.decisions]


def test_clusters_from_gaussians_and_errors(lib) -> None:
    means = np.stack([np.zeros(6), np.full(6, 3.0)])
    covs = np.stack([np.eye(6), np.eye(6)])
    params = np.array([[0.1] * 6, [2.9] * 6, [1.4] * 6])
    np.testing.assert_array_equal(clusters_by_likelihood(params, means, covs), [0, 1, 0])

    class Hmm:
        pass

    hmm = Hmm()
    hmm.means, hmm.covars = means, covs
    synth = Levine09Synthesis(_model(), lib, state_model=hmm)
    np.testing.assert_array_equal(synth.clusters, 0)          # all params are 0
    with pytest.raises(GestureSimError, match="Gaussians"):
        Levine09Synthesis(_model(), lib)
    with pytest.raises(GestureSimError, match="allowed"):
        Levine09Synthesis(_model(), lib, clusters=CLUSTERS, allowed=np.zeros(3, dtype=bool))
    assert synth.request_label("wave", 0.0) is False
    synth.set_style(0.7)


def test_shipped_model_on_real_speech() -> None:
    """motion_library/default with its model, fed the tracker's syllables of jfk.wav: runs,
    starts segments at syllable emissions, and plays only co-speech segments."""
    from gesture_sim.audio.prosody import analyze_file
    from gesture_sim.inference.levine09_synthesis import cospeech_mask
    from gesture_sim.inference.model import GestureModel
    from gesture_sim.motion.library import MotionLibrary

    lib_dir = ROOT / "motion_library" / "default"
    if not (lib_dir / "model" / "model.json").is_file():
        pytest.skip("default model not built")
    library = MotionLibrary.load(lib_dir)
    gm = GestureModel.load(lib_dir / "model")
    assert gm.baseline is not None
    control = ControlLibrary.from_motion_library(library)
    allowed = cospeech_mask(library)
    assert 0 < allowed.sum() < control.n_segments
    assert not any(control.tags[i] for i in np.flatnonzero(allowed))
    synth = Levine09Synthesis(gm.baseline, control, seed=0, allowed=allowed, state_model=gm)
    syllables = analyze_file(ROOT / "tests" / "data" / "audio" / "jfk.wav").syllables
    duration = max(s.t_emitted for s in syllables) + 0.5
    steps = _drive(synth, list(syllables), duration)
    emitted = {i for i, (_, new, _) in enumerate(steps) if new}
    obs = _observation_steps(gm.baseline, steps)
    starts = [(i, r) for i, (_, _, r) in enumerate(steps) if i > 0 and r.frame == 0]
    assert len(starts) >= 5
    for _, _, r in steps:
        assert allowed[r.segment]
        assert r.target is not None and r.target.shape == (len(control.joint_names),)
        assert np.all(np.isfinite(r.target))
    at_obs = [i for i, r in starts if r.decision.kind in ("early", "end")]
    assert all(i in obs for i in at_obs)
    assert all(r.decision.kind in ("early", "end", "late") for _, r in starts)
    assert sum(i in emitted for i in at_obs) >= 3            # strokes start at syllables
    assert len({r.segment for _, r in starts}) >= 4
    assert synth.mean_step_us > 0
