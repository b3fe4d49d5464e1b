"""The one sweep driver of ``tools/`` (``tools/sweep.py``): its table of named sweeps is valid
against the settings classes it names, its grid and cell rules give known answers, and its
smallest sweep runs end to end (kinematic, one short file, one seed)."""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
AUDIO = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"


@pytest.fixture(scope="module")
def sweep():
    spec = importlib.util.spec_from_file_location("sweep_tool", ROOT / "tools" / "sweep.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod                 # the dataclasses look their module up
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop(spec.name, None)


def test_every_named_variant_names_real_settings(sweep):
    from gesture_sim.control.costs import ControlSettings
    from gesture_sim.pipeline import GesturePipeline

    pipe_keys = set(GesturePipeline.__init__.__code__.co_varnames)
    policy_keys = {f.name for f in dataclasses.fields(ControlSettings)}
    assert {"smoke", "controller", "novelty", "warps", "ramp", "hold"} <= set(sweep.SWEEPS)
    for name, sw in sweep.SWEEPS.items():
        assert set(sw.columns) <= set(sweep.COLUMNS), name
        for variant, opts in sw.variants.items():
            parts = sweep.split_options(opts)
            options = sweep.pipeline_options(parts)      # builds SyncSettings / AccentConfig
            assert set(options) <= pipe_keys, (name, variant)
            assert set(parts["ctl"]) <= pipe_keys, (name, variant)
            assert set(parts["policy"]) <= policy_keys, (name, variant)
    # a ramp variant's SyncSettings follows its blend_frames
    opts = sweep.pipeline_options(sweep.split_options({"pipe.blend_frames": 6,
                                                       "sync.carry_s": 0.0}))
    assert opts["sync"].blend_s == pytest.approx(6 / 30.0) and opts["sync"].carry_s == 0.0


def test_set_values_cross_every_variant(sweep):
    key, vals = sweep.parse_set("sync.hold_rate=0,0.2")
    assert (key, vals) == ("sync.hold_rate", [0.0, 0.2])
    assert sweep.parse_set("pipe.transition=gpdm")[1] == ["gpdm"]
    assert sweep.parse_set("sync.skip_after_s=none,0.12")[1] == [None, 0.12]
    grid = sweep.expand({"a": {"pipe.blend_frames": 6}, "b": {}},
                        [("sync.hold_rate", [0.0, 0.2]), ("ctl.sample_state", [True])])
    assert len(grid) == 4
    assert grid["a; hold_rate 0.0, sample_state True"] == {
        "pipe.blend_frames": 6, "sync.hold_rate": 0.0, "ctl.sample_state": True}
    with pytest.raises(argparse.ArgumentTypeError):
        sweep.parse_set("hold_rate=0")            # no namespace


def _rows(audio, method, values):
    return [{"audio": audio, "method": method, "seed": s,
             "metrics": {"bc_excess": v, "accent_hit_excess": v, "r_intensity_best": v}}
            for s, v in enumerate(values)]


def test_file_cells_known_answer():
    from gesture_sim.metrics.cells import file_cells

    # file a: the controller is 0.1 above both baselines with seed spread 0.01: every cell
    # passes; file b: equal to random: no cell passes (it still beats mismatched).
    rows = (_rows("a", "controller", [0.20, 0.22]) + _rows("a", "random", [0.10, 0.12])
            + _rows("a", "mismatched", [0.09, 0.11]) + _rows("b", "controller", [0.10, 0.12])
            + _rows("b", "random", [0.10, 0.12]) + _rows("b", "mismatched", [0.0, 0.02]))
    c = file_cells(rows)
    assert (c.total, c.cells) == (12, 6)
    assert c.passed == 3 + 3 + 3          # a: 3 figures x 2 baselines; b: 3 vs mismatched
    assert c.cells_passed == 3
    assert c.lines[0].startswith("| a | 0.210: +0.100 [0.014] ✓")


def test_cells_of_a_saved_report_for_blocks_of_seeds(sweep, tmp_path):
    import json

    rows = (_rows("a", "controller", [0.20, 0.22, 0.30, 0.32])
            + _rows("a", "random", [0.10, 0.12, 0.30, 0.32])
            + _rows("a", "mismatched", [0.09, 0.11, 0.29, 0.31]))
    report = tmp_path / "report.json"
    report.write_text(json.dumps({"rows": rows}), encoding="utf-8")
    lines = sweep.report_cells(str(report), [2])
    assert lines[0] == "seeds 0-3: comparisons 0/6, cells 0/3"       # spread 0.06 > margin
    assert "seeds 0-1: comparisons 6/6, cells 3/3" in lines           # controller ahead
    assert "seeds 2-3: comparisons 0/6, cells 0/3" in lines           # level with random


def test_list_and_help_print_the_table():
    out = subprocess.run([sys.executable, str(ROOT / "tools" / "sweep.py"), "--list"],
                         capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "warps:" in out and "no skipped" not in out.split("warps:")[0]
    bad = subprocess.run([sys.executable, str(ROOT / "tools" / "sweep.py"), "nonsense", "x"],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and "unknown sweep" in bad.stderr


def test_the_smallest_sweep_runs(sweep):
    out = sweep.run_sweep(sweep.SWEEPS["smoke"], sweep.SWEEPS["smoke"].variants, [str(AUDIO)],
                          seeds=1, physics=False, log=lambda *a, **k: None)
    summ = out["rows"]["default"]["controller"]
    assert summ["segments_played"]["mean"] >= 1
    assert summ["switches_per_min"]["mean"] > 0
    assert 0.0 < summ["top5_share"]["mean"] <= 1.0
    lines = sweep.table(out["rows"], sweep.SWEEPS["smoke"].columns)
    assert lines[0].startswith("| variant | method |") and "| default | controller |" in lines[2]
