"""The import graph keeps the layers (docs/DESIGN.md §3): no stage imports the app, the metrics, the
commands or the pipeline, and no folder-level cycle exists."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "gesture_sim"
#: Layer of each top-level module or folder of the package; an import may only go to the same
#: layer (within a folder) or to a lower one.
LAYERS = {
    "contracts": 0, "errors": 0, "interrupt": 0, "fileio": 0, "progress": 0, "validation": 0,
    "units": 0, "running": 0, "cpus": 0,
    "_data": 0,
    "__init__": 0,
    "audio": 1, "motion": 1, "control": 1, "sim": 1, "signals": 1,
    "inference": 2, "metrics": 2, "export": 2,
    "loading": 3, "stages": 3, "methods": 3, "runlog": 3,
    "pipeline": 4, "feed": 4, "conversation": 4, "corpus": 4,
    "app": 6,
    "commands": 7, "testing": 7,
    "cli": 8, "__main__": 8,
}
#: Stages that must not know each other's internals beyond this (same layer, other folder).
SAME_LAYER_ALLOWED = {("control", "audio"): False, ("audio", "control"): False}


def _unit(path: Path) -> str:
    rel = path.relative_to(PKG)
    return rel.parts[0].removesuffix(".py")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        else:
            continue
        for n in names:
            parts = n.split(".")
            if parts[0] == "gesture_sim" and len(parts) > 1:
                out.add(parts[1])
    return out


def _edges() -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for path in PKG.rglob("*.py"):
        if "_data" in path.parts:
            continue
        src = _unit(path)
        for dst in _imports(path):
            if dst != src and dst in LAYERS:
                edges.setdefault(src, set()).add(dst)
    return edges


def test_every_unit_has_a_layer() -> None:
    units = {_unit(p) for p in PKG.rglob("*.py") if "_data" not in p.parts}
    assert units <= set(LAYERS), sorted(units - set(LAYERS))


def test_no_import_goes_up_a_layer() -> None:
    bad = sorted(f"{a} -> {b}" for a, dsts in _edges().items() for b in dsts
                 if LAYERS[b] > LAYERS[a])
    assert not bad, bad


def test_no_folder_level_cycle() -> None:
    edges = _edges()
    seen: dict[str, int] = {}

    def visit(u: str, stack: list[str]) -> None:
        seen[u] = 1
        for v in sorted(edges.get(u, ())):
            if seen.get(v) == 1:
                raise AssertionError("cycle: " + " -> ".join(stack[stack.index(v):] + [v]))
            if v not in seen:
                visit(v, stack + [v])
        seen[u] = 2

    for u in sorted(edges):
        if u not in seen:
            visit(u, [u])


def test_the_audio_and_control_stages_do_not_import_each_other() -> None:
    edges = _edges()
    assert "control" not in edges.get("audio", set())
    assert "audio" not in edges.get("control", set())
