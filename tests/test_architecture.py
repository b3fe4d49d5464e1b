"""The import graph keeps the layers (docs/DESIGN.md §3): no stage imports the app, the metrics, the
commands or the pipeline, and no folder-level or file-level cycle exists."""

from __future__ import annotations

import ast
import functools
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


def _assert_acyclic(edges: dict[str, set[str]]) -> None:
    """Fail with the first circle found in the import graph ``edges`` (depth first)."""
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


def test_no_folder_level_cycle() -> None:
    _assert_acyclic(_edges())


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _module_edges() -> dict[str, set[str]]:
    """Module -> the package modules it imports, at file level or inside functions."""
    modules = {_module_name(p): p for p in PKG.rglob("*.py") if "_data" not in p.parts}
    edges: dict[str, set[str]] = {}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
            else:
                continue
            for t in targets:
                # the longest package module the dotted name starts with (a module, not a name)
                while t and t not in modules:
                    t = t.rpartition(".")[0]
                if t and t != name and t != "gesture_sim":
                    edges.setdefault(name, set()).add(t)
    return edges


def test_no_file_level_cycle() -> None:
    """No two modules import each other, directly or round a longer circle (a factory that
    imports its own subclass goes into a module beside both)."""
    _assert_acyclic(_module_edges())


def test_the_audio_and_control_stages_do_not_import_each_other() -> None:
    edges = _edges()
    assert "control" not in edges.get("audio", set())
    assert "audio" not in edges.get("control", set())


# ------------------------------------------------------------------------------------------
# docs/ARCHITECTURE.md names only what exists
# ------------------------------------------------------------------------------------------

REPO = PKG.parent
DOC = REPO / "docs" / "ARCHITECTURE.md"


class _Index:
    """Every module of the package, its top-level names, and the members of its classes (methods,
    class-level and annotated names, ``self.X`` assignments, and the same of its bases found in
    the package), from the AST: nothing is imported."""

    def __init__(self) -> None:
        #: "sim.world" -> top-level name -> its node
        self.modules: dict[str, dict[str, ast.AST]] = {}
        self.classes: dict[str, list[ast.ClassDef]] = {}      # class name -> its definitions
        self.members: set[str] = set()                        # every member name of any class
        for path in PKG.rglob("*.py"):
            rel = path.relative_to(PKG).with_suffix("")
            mod = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
            tree = ast.parse(path.read_text(encoding="utf-8"))
            top: dict[str, ast.AST] = {}
            for node in tree.body:
                for name in _bound_names(node):
                    top[name] = node
                if isinstance(node, ast.ClassDef):
                    self.classes.setdefault(node.name, []).append(node)
                    self.members |= _class_members(node)
            self.modules[mod] = top

    def class_members(self, name: str, seen: frozenset[str] = frozenset()) -> set[str]:
        out: set[str] = set()
        for cls in self.classes.get(name, []):
            out |= _class_members(cls)
            for base in cls.bases:
                b = base.id if isinstance(base, ast.Name) else getattr(base, "attr", None)
                if b and b not in seen:
                    out |= self.class_members(b, seen | {name})
        return out

    def resolve(self, dotted: str) -> bool:
        """Does ``a.b.c`` (a module path, then a top-level name, then class members) exist?"""
        parts = dotted.split(".")
        for k in range(len(parts), 0, -1):                   # the longest module prefix
            mod = ".".join(parts[:k])
            if mod in self.modules:
                rest = parts[k:]
                if not rest:
                    return True
                node = self.modules[mod].get(rest[0])
                if node is None:
                    return False
                return self._members_ok(node, rest[1:])
        first, rest = parts[0], parts[1:]
        if first in self.classes:
            return self._members_ok(self.classes[first][0], rest)
        if any(first in top for top in self.modules.values()):
            return not rest
        return not rest and first in self.members           # a member name (``reset``, ``joints``)

    def _members_ok(self, node: ast.AST, rest: list[str]) -> bool:
        if not rest:
            return True
        if not isinstance(node, ast.ClassDef):
            return False
        return len(rest) == 1 and rest[0] in self.class_members(node.name)


def _bound_names(node: ast.AST) -> list[str]:
    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        return [node.name]
    if isinstance(node, ast.Assign):
        return [t.id for t in node.targets if isinstance(t, ast.Name)]
    if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
        return [node.target.id]
    if isinstance(node, (ast.Import, ast.ImportFrom)):
        return [(a.asname or a.name).split(".")[0] for a in node.names]
    return []


def _class_members(cls: ast.ClassDef) -> set[str]:
    out: set[str] = set()
    for node in cls.body:
        out |= set(_bound_names(node))
    for node in ast.walk(cls):
        if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
                and isinstance(node.value, ast.Name) and node.value.id == "self"):
            out.add(node.attr)
    return out


def _doc_names(text: str) -> list[str]:
    """The backticked names of ``text``: each span cut at its first ``(``, space or ``=``
    (``step(t, heard)`` names ``step``); command lines, options, command names (with a ``-``)
    and empty cuts left out."""
    import re

    out = []
    for span in re.findall(r"`([^`\n]+)`", text):
        if (re.search(r"(^|\s)--?[A-Za-z]", span) or span.startswith(("'", '"'))
                or re.match(r"^\w+=", span)):              # a command line, a string, a keyword
            continue
        name = re.split(r"[\s(=\[]", span.strip(), maxsplit=1)[0].rstrip(",.;:")
        if name and "-" not in name:                         # not an option or a command name
            out.append(name)
    return out


def _exists(name: str, index: _Index) -> bool:
    """A path (repository- or package-relative, a folder with ``/``, a glob ``write_*``), or a
    module path with a dotted name after it (``sim/world.PhysicsLoop``), or a dotted name."""
    import fnmatch

    if "/" in name:
        head, _, tail = name.rpartition("/")
        if tail.endswith((".py", ".md", ".json", ".xml", ".toml")) or tail == "":
            return any((base / name).exists() for base in (REPO, PKG))
        module, _, attrs = tail.partition(".")              # "sim/world.PhysicsLoop"
        dotted = ".".join([*head.removeprefix("gesture_sim/").split("/"), module])
        if attrs:
            dotted += "." + attrs
        if (REPO / name).exists():                           # a folder named without "/"
            return True
        return index.resolve(dotted)
    if "*" in name:
        return any(fnmatch.fnmatch(n, name) for top in index.modules.values() for n in top)
    if name.endswith((".py", ".md")):
        return (REPO / name).exists() or (PKG / name).exists()
    return index.resolve(name)


@functools.lru_cache(maxsize=1)
def _index() -> _Index:
    return _Index()


def test_every_name_in_architecture_md_exists() -> None:
    index = _index()
    names = _doc_names(DOC.read_text(encoding="utf-8"))
    assert len(names) > 50                                   # the parser found the names
    missing = sorted({n for n in names if not _exists(n, index)})
    assert not missing, missing


def test_the_name_check_tells_real_names_from_made_up_ones() -> None:
    index = _index()
    for real in ("sim/world.PhysicsLoop", "feed.feed", "GesturePipeline.push_audio",
                 "audio/speech.SpeechState", "runlog.PipelineLog", "signals/ruth.py", "export/",
                 "tests/test_architecture.py", "Heard", "write_*_from_trace", "reset"):
        assert _exists(real, index), real
    for made_up in ("sim/world.PhysicsLoops", "feed.feeds", "GesturePipeline.no_such_method",
                    "audio/nowhere.py", "NoSuchClass", "write_*_from_nothing", "signals/ruthh.py",
                    "control/ramp.SwitchRamp.no_such"):
        assert not _exists(made_up, index), made_up
    assert _doc_names("`step(t, heard) -> x`, `--json`, `legs=`, `a.b`, `eval --methods`, "
                      "`gesture-sim`") == ["step", "a.b"]
