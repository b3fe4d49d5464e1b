"""MIMiC (Okwechime 2011): graph building on hand-made motions with known cut points, clusters
and transitions; the density model; the roulette wheel; the chooser behind the real timing
layer."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest

from gesture_sim.control.inputs import ControlLibrary
from gesture_sim.control.mimic import (
    FORMAT_VERSION,
    KernelDensity,
    MimicChooser,
    MotionGraph,
    build_graph,
    cv_alpha,
    fit_pca,
    kmedoids,
    markov_matrix,
    projection_mapping,
    speed_minima,
)
from gesture_sim.control.synchrony import SpeechCue, SyncPlayer
from gesture_sim.errors import GestureSimError

KEYS = {"A": (0.0, 0.0, 0.0), "B": (1.0, 0.0, 0.0), "C": (0.0, 1.0, 0.0)}
ROUTE = "ABACABACA"          # legs A→B, B→A, A→C, C→A, twice
LEG = 10                     # frames per leg


def handmade_motion() -> np.ndarray:
    """(81, 3) poses moving between key poses A, B, C with ease-in-out (speed 0 at the keys)."""
    out = []
    for p, q in zip(ROUTE[:-1], ROUTE[1:], strict=True):
        a, b = np.array(KEYS[p]), np.array(KEYS[q])
        s = np.arange(LEG) / LEG
        w = s * s * (3 - 2 * s)
        out.append(a + w[:, None] * (b - a))
    out.append(np.array(KEYS[ROUTE[-1]])[None])
    return np.concatenate(out)


def library_from_motion(y: np.ndarray, cuts: np.ndarray, tags=None) -> ControlLibrary:
    """A ControlLibrary whose segments are the motion cut at ``cuts`` (the last segment keeps
    the final frame)."""
    bounds = list(cuts[:-1]) + [len(y)]
    segs = [y[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    n = len(segs)
    lengths = np.array([len(s) for s in segs])
    inter = np.array([[max(1, round(ln * j / 4)) for j in (1, 2, 3)] for ln in lengths])
    speed = [np.r_[np.linalg.norm(np.diff(s, axis=0), axis=1), 0.0] * 30 for s in segs]
    params = np.stack([[np.log(ln), np.linalg.norm(s[-1] - s[0]), v.mean(), 0, 0, 0]
                       for ln, s, v in zip(lengths, segs, speed, strict=True)])
    return ControlLibrary(
        lengths=lengths, interrupt_frames=inter, params=params, d_sp=np.zeros((n, n)),
        d_in=np.zeros((n, 3, n)), tags=tags or ((),) * n, fps=30.0, fingerprint="handmade",
        starts=np.array(bounds[:-1]), segment_qpos=lambda i: segs[i],
        frame_features=lambda i: segs[i], hand_speed=lambda i: speed[i],
        successors=np.r_[np.arange(1, n), -1])


@pytest.fixture(scope="module")
def handmade():
    y = handmade_motion()
    cuts = speed_minima(y)
    lib = library_from_motion(y, cuts)
    graph = build_graph(lib, n_clusters=3, smoothing=0.1, alpha=0.5, min_cluster=1)
    return y, cuts, lib, graph


# ---------------------------------------------------------------------------- building
def test_cut_points_are_the_key_poses(handmade):
    y, cuts, _, _ = handmade
    assert cuts.tolist() == list(range(0, len(y), LEG))


def test_clusters_are_the_key_poses(handmade):
    _, _, lib, g = handmade
    assert g.n_clusters == 3
    # the start cluster of each segment is its key pose
    key_of = {}
    for i, k in enumerate(ROUTE[:-1]):
        key_of.setdefault(k, int(g.start_cluster[i]))
        assert g.start_cluster[i] == key_of[k]
    assert len(set(key_of.values())) == 3
    # medoids are real cut points at the key poses
    pca = g.pca()
    for k, c in key_of.items():
        assert np.allclose(g.medoids[c], pca.project(np.array([KEYS[k]]))[0], atol=1e-9)
    # the end point of a segment is the next key pose
    for i, k in enumerate(ROUTE[1:]):
        assert g.end_cluster[i] == key_of[k]


def test_markov_matrix_is_the_smoothed_route_counts(handmade):
    _, _, _, g = handmade
    a, b, c = (int(g.start_cluster[i]) for i in (0, 1, 3))
    expected = np.zeros((3, 3))
    for p, q in zip(ROUTE[:-1], ROUTE[1:], strict=True):
        expected[{"A": a, "B": b, "C": c}[p], {"A": a, "B": b, "C": c}[q]] += 1
    assert np.array_equal(g.counts, expected)
    assert g.counts[a, b] == 2 and g.counts[a, c] == 2 and g.counts[b, a] == 2
    sm = expected + 0.1
    assert np.allclose(g.markov, sm / sm.sum(axis=1, keepdims=True))
    assert np.allclose(g.markov[a, b], 2.1 / 4.3) and np.allclose(g.markov[b, c], 0.1 / 2.3)


def test_markov_matrix_rows_and_counts():
    counts, m = markov_matrix(np.array([0, 0, 1]), np.array([1, 1, 0]), 3, 0.5)
    assert counts[0, 1] == 2 and counts[1, 0] == 1 and counts.sum() == 3
    assert np.allclose(m.sum(axis=1), 1.0)
    assert np.allclose(m[2], 1 / 3)            # an unseen row: uniform after smoothing


def test_kmedoids_separated_blobs_deterministic():
    rng = np.random.default_rng(0)
    centres = np.array([[0, 0], [5, 0], [0, 5], [5, 5]], float)
    x = np.concatenate([c + 0.3 * rng.standard_normal((15, 2)) for c in centres])
    med, lab = kmedoids(x, 4, seed=1)
    assert len(med) == 4
    truth = np.repeat(np.arange(4), 15)
    # each true blob maps onto exactly one cluster
    assert all(len(set(lab[truth == t])) == 1 for t in range(4))
    assert len(set(lab)) == 4
    med2, lab2 = kmedoids(x, 4, seed=1)
    assert np.array_equal(med, med2) and np.array_equal(lab, lab2)


def test_pca_keeps_the_energy():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((400, 3)) * np.array([10.0, 3.0, 0.1])
    pca, kept = fit_pca(x, 0.95)
    assert pca.components.shape == (2, 3) and kept >= 0.95
    pca1, kept1 = fit_pca(x, 0.5)
    assert pca1.components.shape == (1, 3) and kept1 >= 0.5


def test_graph_settings_errors(handmade):
    _, _, lib, _ = handmade
    with pytest.raises(GestureSimError):
        build_graph(lib, n_clusters=3, alpha=-1.0)


# ---------------------------------------------------------------------------- density
def test_kde_matches_brute_force_with_all_neighbours():
    rng = np.random.default_rng(2)
    c = rng.standard_normal((50, 3))
    w = np.array([0.5, 0.3, 0.8])
    kde = KernelDensity(c, w, n_neighbours=50)
    x = rng.standard_normal((7, 3))
    u = ((x[:, None, :] - c[None]) / w) ** 2
    brute = np.exp(-0.5 * u.sum(-1)).mean(axis=1)
    assert np.allclose(kde.density(x), brute, rtol=1e-10)
    norm = np.exp(-np.log(w).sum() - 1.5 * np.log(2 * np.pi))
    assert np.allclose(np.exp(kde.log_pdf(x)), brute * norm, rtol=1e-10)
    # denser near the kernels than far away
    assert kde.density(c[:1])[0] > kde.density(c[:1] + 10.0)[0]


def test_cv_picks_an_interior_width_for_gaussian_data():
    x = np.random.default_rng(3).standard_normal((600, 1))
    cv = cv_alpha(x, np.ones(1))
    best = max(cv, key=cv.get)
    assert min(cv) < best < max(cv)            # not a grid edge
    assert 0.1 <= best <= 0.8                  # Silverman's rule gives ~0.29 here


# ---------------------------------------------------------------------------- storage
def test_save_load_roundtrip_and_refusals(handmade, tmp_path):
    _, _, lib, g = handmade
    path = tmp_path / "g.npz"
    g.save(path)
    g2 = MotionGraph.load(path, lib.fingerprint)
    assert np.array_equal(g2.markov, g.markov) and g2.meta["graph_fingerprint"] == \
        g.meta["graph_fingerprint"]
    with pytest.raises(GestureSimError, match="built for library"):
        MotionGraph.load(path, "another")
    bad = dataclasses.replace(g, meta=dict(g.meta))
    bad.save(tmp_path / "b.npz")
    z = dict(np.load(tmp_path / "b.npz"))
    import json
    meta = json.loads(str(z.pop("meta")))
    meta["format_version"] = FORMAT_VERSION + 1
    np.savez(tmp_path / "b.npz", meta=np.array(json.dumps(meta)), **z)
    with pytest.raises(GestureSimError, match="format"):
        MotionGraph.load(tmp_path / "b.npz")
    (tmp_path / "c.npz").write_bytes(b"not a zip")
    with pytest.raises(GestureSimError, match="damaged"):
        MotionGraph.load(tmp_path / "c.npz")
    with pytest.raises(GestureSimError):
        MimicChooser(g, dataclasses.replace(lib, fingerprint="x"))


# ---------------------------------------------------------------------------- roulette
def test_roulette_frequencies_match_the_weights(handmade):
    _, _, lib, g = handmade
    ch = MimicChooser(g, lib, seed=5)
    logw = np.log(np.array([0.1, 0.2, 0.7]))
    n = 6000
    hits = Counter(ch._roulette(logw)[0] for _ in range(n))
    for j, p in enumerate((0.1, 0.2, 0.7)):
        sd = np.sqrt(p * (1 - p) / n)
        assert abs(hits[j] / n - p) < 4 * sd


def test_decision_frequencies_match_reported_probabilities(handmade):
    """At the end of A→B (cluster B) the candidates are the two B→A segments; the draw
    frequencies match the chooser's own φ-normalised probabilities."""
    _, _, lib, g = handmade
    ch = MimicChooser(g, lib, seed=7, lookahead=1)
    n = 3000
    draws = [ch.decide_at(np.ones(1), 0, lib.n_interrupts, 0.0) for _ in range(n)]
    segs = Counter(d.segment_id for d in draws)
    assert set(segs) == {1, 5}                  # the segments that start at B
    p1 = next(d.costs["p"] for d in draws if d.segment_id == 1)
    assert abs(segs[1] / n - p1) < 4 * np.sqrt(p1 * (1 - p1) / n)


def test_deterministic_per_seed(small_lib, small_model, random_beliefs):
    g = build_graph(small_lib, alpha=0.5)
    beliefs = random_beliefs(np.random.default_rng(0), 600, small_model.n_states)

    def run(seed):
        ch = MimicChooser(g, small_lib, seed=seed, model=small_model)
        return _drive(small_lib, ch, beliefs)[0]

    a, b, c = run(1), run(1), run(2)
    assert a == b
    assert a != c


# ---------------------------------------------------------------------------- with the timing layer
def _drive(lib, chooser, beliefs, labels=None):
    """Run the real SyncPlayer: speech with an accent every 0.4 s, a pause now and then."""
    player = SyncPlayer(lib, chooser)
    chooser.reset()
    shown = []
    labels = labels or {}
    for i, b in enumerate(beliefs):
        t = i / lib.fps
        speaking = (i // 120) % 4 != 3
        if i in labels:
            assert chooser.request_label(labels[i], t)
        cue = SpeechCue(speaking, 0.0 if speaking else (i % 120) / lib.fps,
                        [t] if speaking and i % 12 == 0 else [], 0.0)
        s = player.step(t, b, cue)
        shown.append((s.segment, s.frame))
    return [(d.segment_id, d.frame, d.kind) for d in chooser.decisions], shown


def test_interface_contract_with_sync_player(small_lib, small_model, random_beliefs):
    n = small_lib.n_segments
    mask = np.zeros(n, bool)
    mask[: n // 2] = True
    tag_seg = int(small_lib.segments_with_tag("wave")[0])
    mask[tag_seg] = False
    lib = dataclasses.replace(small_lib, cospeech=mask)
    g = build_graph(lib, alpha=0.5)
    ch = MimicChooser(g, lib, seed=0, model=small_model)
    # decision points: interruption frames 0..K-1 and the last frame K
    for a in range(n):
        for k, f in enumerate(lib.interrupt_frames[a]):
            if 0 < f < lib.lengths[a] - 1:
                assert ch.decision_point(a, int(f)) == k
        assert ch.decision_point(a, int(lib.lengths[a] - 1)) == lib.n_interrupts
        assert ch.decision_point(a, 0) == -1
    b = np.full(small_model.n_states, 1.0 / small_model.n_states)
    # continue at an interruption frame without a reason to switch
    d = ch.decide_at(b, 0, 0, 1.0)
    assert d.costs["continue"] == 1.0 and d.segment_id == 0
    # switch when the timing layer prefers one, and at the end: co-speech, frame 0
    for k, pref in ((0, True), (lib.n_interrupts, False)):
        d = ch.decide_at(b, 0, k, 1.0, prefer_switch=pref)
        assert d.costs["continue"] == 0.0 and mask[d.segment_id]
        assert d.frame == lib.starts[d.segment_id]
        assert d.kind == ("interrupt" if pref else "end")
    d = ch.decide_start(b, 2.0)
    assert d.kind == "start" and mask[d.segment_id] and d.frame == lib.starts[d.segment_id]
    # a label: the next decision enters a tagged segment and clears it
    assert not ch.request_label("nonexistent")
    assert ch.request_label("wave", 3.0) and ch.label
    d = ch.decide_at(b, 0, 0, 3.5)
    assert d.kind == "label" and "wave" in lib.tags[d.segment_id] and ch.label == 0
    assert d.costs["label_delay"] == pytest.approx(0.5)
    with pytest.raises(GestureSimError):
        ch.decide_at(np.ones(3), 0, lib.n_interrupts, 0.0)
    # the whole stream through the real SyncPlayer
    beliefs = random_beliefs(np.random.default_rng(1), 1500, small_model.n_states)
    decisions, shown = _drive(lib, ch, beliefs, labels={700: "wave"})
    assert len(decisions) > 20
    labelled = [dd for dd in decisions if dd[2] == "label"]
    assert len(labelled) == 1 and "wave" in lib.tags[labelled[0][0]]
    played = {s for s, _ in shown if s >= 0}
    assert played - set(np.nonzero(mask)[0]) <= {labelled[0][0]}
    assert all(dd[1] == lib.starts[dd[0]] for dd in decisions)
    assert len(played) > 5


def test_style_dial_biases_toward_energetic_segments(small_lib):
    g = build_graph(small_lib, alpha=0.5)
    means = []
    for dial in (-1.0, 1.0):
        ch = MimicChooser(g, small_lib, seed=0, style_gain=2.0, motion_weight=0.0)
        ch.set_style(dial)
        picks = [ch.decide_at(np.ones(1), a, small_lib.n_interrupts, 0.0).segment_id
                 for a in range(small_lib.n_segments) for _ in range(5)]
        means.append(g.energy[picks].mean())
    assert means[1] > means[0] + 0.3


def test_projection_mapping_follows_the_belief(small_lib, small_model):
    g = build_graph(small_lib, alpha=0.5)
    p = projection_mapping(g, small_lib, small_model)
    assert p.shape == (small_model.n_states, g.n_clusters)
    assert np.allclose(p.sum(axis=1), 1.0)
    ch = MimicChooser(g, small_lib, model=small_model)
    w = [ch.input_weights(np.eye(small_model.n_states)[s]) for s in range(small_model.n_states)]
    assert np.allclose(w[0].sum(), 1.0)
    assert max(np.abs(w[i] - w[0]).max() for i in range(1, len(w))) > 0.05
    assert np.allclose(MimicChooser(g, small_lib).input_weights(np.ones(5)), 1 / g.n_clusters)


def test_lookahead_prefers_paths_to_the_destination(handmade):
    _, _, lib, g = handmade
    ch = MimicChooser(g, lib, lookahead=3)
    a = int(g.start_cluster[0])
    w = np.full(3, 1 / 3)
    lam = ch.lookahead_log(a, w)
    assert lam.max() == 0.0 and np.all(np.isfinite(lam))
    assert np.allclose(MimicChooser(g, lib, lookahead=1).lookahead_log(a, w), 0.0)
    with pytest.raises(GestureSimError):
        MimicChooser(g, lib, lookahead=0)


def test_library_graph_command(tmp_path, capsys):
    from gesture_sim.cli import main

    out, png = tmp_path / "g.npz", tmp_path / "g.png"
    rc = main(["library", "graph", "motion_library/default", "-o", str(out), "--plot", str(png),
               "--alpha", "0.5"])
    assert rc == 0 and out.exists() and png.stat().st_size > 10000
    g = MotionGraph.load(out)
    assert g.n_clusters >= 2 and np.allclose(g.markov.sum(axis=1), 1.0)
    assert "subsequences" in capsys.readouterr().out
    assert main(["library", "graph", str(tmp_path / "missing")]) == 2
