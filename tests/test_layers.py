"""The package's layers, read from its imports: study -> neural / tabular -> shared parts -> envs,
no module importing from a layer above its own (nor neural <-> tabular); inside study, its rooms
in the order data flows (catalogue -> runs -> judge -> studies -> report), each importing only
from rooms before it; and no import cycle."""
import ast
import shutil
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "oapo_lite"
# a layer may import from the layers ranked below it; the shared parts are algorithms, reuse,
# store and cli, above envs/ (every engine behind one interface), above renamed (retired keywords,
# which every layer may use); __main__ is the command line on top
RANK = {"__main__": 5, "study": 4, "neural": 3, "tabular": 3, "shared": 2, "envs": 1, "renamed": 0}
# the rooms of study/, in the order data flows: a room imports only from itself and the rooms before it
ROOMS = ("catalogue", "runs", "judge", "studies", "report")


def module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer(module: str) -> str:
    part = module.split(".")[1] if "." in module else ""
    return part if part in RANK else "shared"


def room(module: str) -> str | None:
    """The room of a study module (None: not in one, e.g. ``oapo_lite.study`` itself)."""
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[1] == "study" and parts[2] in ROOMS else None


def imports(path: Path, root: Path, modules: set[str]) -> set[str]:
    """The package's modules that ``path`` imports: at the top or inside a function, by a string
    naming the module (an engine table's), and the ``__init__`` of every package on the way
    that is not one of its own. ``from oapo_lite.study.catalogue import grid`` imports ``oapo_lite.study.catalogue.grid``."""
    me, found = module_name(path, root), set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in modules:
            found.add(node.value)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from .maps import X
                package = me.split(".")[:len(me.split(".")) - node.level + (path.name == "__init__.py")]
                base = ".".join(package + ([node.module] if node.module else []))
            else:
                base = node.module
            names = {f"{base}.{a.name}" for a in node.names}
            found |= (names & modules) or {base}
    own = {".".join(me.split(".")[:k]) for k in range(1, me.count(".") + 1)}  # being imported already
    packages = {".".join(m.split(".")[:k]) for m in found for k in range(1, m.count(".") + 1)}
    return {m for m in found | packages if m in modules} - own - {me}


def graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    paths = {module_name(p, root): p for p in root.rglob("*.py")}
    return {m: imports(p, root, set(paths)) for m, p in paths.items()}


def violations(g: dict[str, set[str]]) -> list[str]:
    """Every import of a module from a layer above its own, or beside it (neural <-> tabular), and
    every import of a study room from a room after its own."""
    across = [f"{m} ({layer(m)}) imports {d} ({layer(d)})" for m, deps in g.items() for d in deps
              if layer(d) != layer(m) and RANK[layer(d)] >= RANK[layer(m)]]
    upstream = [f"{m} ({room(m)}) imports {d} ({room(d)})" for m, deps in g.items() for d in deps
                if room(m) and room(d) and ROOMS.index(room(d)) > ROOMS.index(room(m))]
    return sorted(across + upstream)


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected set of two or more modules (Tarjan's algorithm): a cycle of imports."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = [stack.pop()]
            while group[-1] != v:
                group.append(stack.pop())
            on.difference_update(group)
            if len(group) > 1:
                out.append(sorted(group))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def test_every_module_imports_only_from_its_layer_or_below():
    assert violations(graph()) == []


def test_no_module_imports_itself_back_through_others():
    assert cycles(graph()) == []


def test_the_shared_parts_outside_the_layer_folders_are_few():
    top = {m for m in graph() if layer(m) in ("shared", "renamed") and m.count(".") == 1}
    assert top == {"oapo_lite.algorithms", "oapo_lite.cli", "oapo_lite.renamed", "oapo_lite.reuse", "oapo_lite.store"}


def test_every_study_module_sits_in_a_room():
    loose = {m for m in graph() if layer(m) == "study" and room(m) is None} - {"oapo_lite.study"}
    assert not loose


def test_the_train_command_reaches_no_study_module():
    """A run's identity lives beside its config: ``python -m oapo_lite train`` needs nothing of
    the study layer, through any chain of imports."""
    main = ast.parse((PACKAGE / "__main__.py").read_text())
    (fn,) = [n for n in ast.walk(main) if isinstance(n, ast.FunctionDef) and n.name == "train_main"]
    g, todo = graph(), {n.module for n in ast.walk(fn) if isinstance(n, ast.ImportFrom)}
    reached = set()
    while todo:
        m = todo.pop()
        reached.add(m)
        todo |= g.get(m, set()) - reached
    assert reached and not {m for m in reached if layer(m) == "study"}, sorted(reached)


@pytest.mark.parametrize("where, line, words", [
    ("neural/nets.py", "from oapo_lite.study.catalogue import grid",
     "oapo_lite.neural.nets (neural) imports oapo_lite.study.catalogue.grid (study)"),
    ("reuse.py", "from oapo_lite.neural.config import TrainConfig",
     "oapo_lite.reuse (shared) imports oapo_lite.neural.config (neural)"),
    ("tabular/exact.py", "from oapo_lite.neural import nets",
     "oapo_lite.tabular.exact (tabular) imports oapo_lite.neural.nets (neural)"),
    ("envs/maps.py", "from .core import VecMaze", None),  # a cycle: core imports maps
    ("envs/core.py", "from oapo_lite.store import write_frame", "oapo_lite.envs.core (envs) imports oapo_lite.store (shared)"),
    ("study/catalogue/grid.py", "from oapo_lite.study.judge import evidence",
     "oapo_lite.study.catalogue.grid (catalogue) imports oapo_lite.study.judge.evidence (judge)"),
    ("study/judge/verdicts.py", "from oapo_lite.study.report import words",
     "oapo_lite.study.judge.verdicts (judge) imports oapo_lite.study.report.words (report)"),
])
def test_an_import_upwards_or_round_fails_the_check(tmp_path, where, line, words):
    """The checks catch what they are for: a copy of the package with one import added."""
    copy = tmp_path / "oapo_lite"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / where).write_text(f"{line}\n" + (copy / where).read_text())
    g = graph(copy)
    if words:
        assert words in violations(g)
    else:
        assert ["oapo_lite.envs.core", "oapo_lite.envs.maps"] in [[m for m in c if m.endswith(("core", "maps"))]
                                                                  for c in cycles(g)]


def test_tarjan_finds_a_cycle_of_three_and_nothing_else():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
