"""Every subcommand that ``--help`` lists runs once here, with minimal input, and exits 0.

The list of commands is read from the parser itself: a command added to the CLI without an
entry in :data:`RUNS` fails :func:`test_every_command_has_a_smoke_run`, so no command can be
left untested (a command nobody runs is a broken command: ``bench control`` crashed on every
run for a while because nothing ran it). ``--json`` runs also check that the output parses.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import pytest

from gesture_sim import cli

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
SPEECH = DATA / "audio" / "arctic_a0007.wav"         # 4 s of real read speech
PAIR_MOTION = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
PAIR_AUDIO = DATA / "eval" / "2_scott_0_1_1_first10s.wav"
BVH = DATA / "motion" / "dataset-1_bow_active_001.bvh"
LIBRARY = ROOT / "motion_library" / "default"
SMALL = ["--width", "160", "--height", "90", "--quality", "fast"]


def leaf_commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()
                  ) -> list[tuple[str, ...]]:
    """Every runnable command path of ``parser`` (``("bench", "control")``, ...)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [prefix]
    return [leaf for name, sp in subs[0].choices.items() for leaf in leaf_commands(sp,
                                                                                  (*prefix, name))]


#: command -> function of a temporary folder giving the argv (after the command words).
RUNS: dict[str, Callable[[Path], list[str]]] = {
    "demo": lambda d: ["-o", str(d / "demo.mp4"), *SMALL, "--json"],
    "render": lambda d: [str(SPEECH), "-o", str(d / "r.mp4"), *SMALL, "--metrics",
                         str(d / "r.json"), "--json"],
    "prosody": lambda d: [str(SPEECH), "--json"],
    "words": lambda d: [str(SPEECH), "--json"],
    "library build": lambda d: [str(BVH), "-o", str(d / "lib"), "--json"],
    "library subset": lambda d: [str(LIBRARY), "--clips", "dataset-1_*", "-o", str(d / "sub"),
                                 "--json"],
    "library policy": lambda d: [str(_subset(d)), "--json"],
    "library info": lambda d: [str(LIBRARY), "--json"],
    "library preview": lambda d: [str(LIBRARY), "-o", str(d / "p.png"), "--max", "4", "--json"],
    "library graph": lambda d: [str(LIBRARY), "-o", str(d / "g.npz"), "--json"],
    "train": lambda d: ["--pair", str(PAIR_MOTION), str(PAIR_AUDIO), "-o", str(d / "model"),
                        "--json"],
    "train --signs": lambda d: [str(_sign_takes(d)), "-o", str(d / "signs"), "--unlabelled",
                                "Beats", "--json"],
    "listener mine": lambda d: [str(_annotations(d)), "-o", str(d / "rules.json"), "--json"],
    "eval inference": lambda d: ["--pair", str(PAIR_MOTION), str(PAIR_AUDIO), "--windows", "1",
                                 "--json"],
    "eval motion": lambda d: [str(SPEECH), "--no-physics", "--methods", "controller", "random",
                              "--seeds", "1", "--json"],
    "bench physics": lambda d: ["--duration", "1", "--json"],
    "bench prosody": lambda d: [str(SPEECH), "--repeat", "1", "--json"],
    "bench inference": lambda d: ["--steps", "50", "--json"],
    "bench control": lambda d: ["--lengths", "20", "40", "--decisions", "50", "--no-memory",
                                "--json"],
    "bench pipeline": lambda d: [str(SPEECH), "--json"],
    "bench render": lambda d: ["--seconds", "0.5", "--sizes", "160x90", "--workers", "1",
                               "--quality", "fast", "--json"],
    "bench robot": lambda d: ["--body", "g1", "--audio", str(SPEECH), "--seeds", "1",
                              "--no-controls", "--json"],
    "bench onset": lambda d: [str(SPEECH), "--seeds", "1", "--pause", "1.5", "--json"],
    "bench train": lambda d: ["--pair", str(PAIR_MOTION), str(PAIR_AUDIO), "--minutes", "0.25",
                              "0.5", "--states", "3", "--decisions", "50", "--in-process",
                              "--json"],
}

#: commands that need a display (a GLFW window): run under Xvfb by the named test instead.
ELSEWHERE = {"live": "tests/app/test_live.py::test_viewer_under_xvfb_shows_the_humanoid_moving",
             "export": "tests/export/test_export_command.py::"
                       "test_each_format_is_what_render_writes"}


def _annotations(d: Path) -> Path:
    """A tiny annotated conversation: A nods, B nods back soon after."""
    rows = ["start,end,signal,person", "0,20,talking,A"]
    for k in range(20):
        rows += [f"{k}.0,{k}.2,nod,A", f"{k}.25,{k}.4,nod,B"]
    path = d / "signals.csv"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def _sign_takes(d: Path) -> Path:
    """TAKES_DIR of ``train --signs``: the 4-s speech, its words as a TextGrid tier, signs."""
    import shutil

    takes = d / "takes"
    takes.mkdir()
    shutil.copy(SPEECH, takes / "t.wav")
    words = [(0.0, 0.35, ""), (0.35, 1.0, "i"), (1.0, 1.6, "everything"), (1.6, 4.0, "")]
    grid = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "xmin = 0", "xmax = 4",
            "tiers? <exists>", "size = 1", "item []:", "item [1]:", 'class = "IntervalTier"',
            'name = "words"', "xmin = 0", "xmax = 4", f"intervals: size = {len(words)}"]
    for k, (a, b, w) in enumerate(words, start=1):
        grid += [f"intervals [{k}]:", f"xmin = {a}", f"xmax = {b}", f'text = "{w}"']
    (takes / "t.TextGrid").write_text("\n".join(grid) + "\n", encoding="utf-8")
    (takes / "t.signs.csv").write_text("0,1,Deictic.Self\n1,2,Whole\n", encoding="utf-8")
    return takes


def _subset(d: Path) -> Path:
    out = d / "policy_lib"
    assert cli.main(["library", "subset", str(LIBRARY), "--clips", "dataset-1_*", "-o",
                     str(out)]) == 0
    return out


def test_every_command_has_a_smoke_run() -> None:
    leaves = {" ".join(leaf) for leaf in leaf_commands(cli.build_parser())}
    runs = {c.split(" --")[0] for c in RUNS}     # "train --signs": a mode of "train"
    assert leaves == runs | set(ELSEWHERE), (
        f"without a smoke run: {sorted(leaves - runs - set(ELSEWHERE))}; "
        f"no longer a command: {sorted(runs | set(ELSEWHERE) - leaves)}")


def test_commands_run_elsewhere_are_run_there() -> None:
    for name, node in ELSEWHERE.items():
        path, test = node.split("::")
        assert f"def {test}(" in (ROOT / path).read_text(), (name, node)


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(RUNS))
def test_command_runs(command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = [*command.split(), *RUNS[command](tmp_path)]
    capsys.readouterr()   # what preparing the input printed
    status = cli.main(argv)
    captured = capsys.readouterr()
    assert status == 0, (argv, captured.err[-2000:])
    if "--json" in argv:
        json.loads(captured.out)
