from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

MODULES = ["scenariomax", "scenariomax.pipeline", "scenariomax.inspect", "scenariomax.validate",
           "scenariomax.render", "scenariomax.enrich", "scenariomax.sources.synthetic", "scenariomax.sources.womd",
           "scenariomax.sources.av2", "scenariomax.sources.nuplan", "scenariomax.sources.scenarionet",
           "vmax_cli.scenariomax_cli"]


def test_scenariomax_never_imports_jax_or_tensorflow():
    code = ("import sys\n" + "".join(f"import {m}\n" for m in MODULES) +
            "bad = [m for m in ('jax', 'tensorflow', 'ray', 'torch') if m in sys.modules]\n"
            "print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"scenariomax imported {out} at import time"


def test_scenariomax_commands_run_without_jax(tmp_path):
    """convert, validate, inspect --render and view work in a process where importing JAX fails (the base install
    has no JAX): the commands' lazy imports stay on the numpy side too."""
    shards, picture, page = tmp_path / "shards", tmp_path / "scene.png", tmp_path / "view.html"
    commands = [["convert", "--dataset", "synthetic", "--num-scenarios", "2", "--num-objects", "16",
                 "--roadgraph-points", "2000", "--workers", "1", "--out", str(shards)],
                ["validate", str(shards)], ["inspect", str(shards), "--render", str(picture)],
                ["view", str(shards), "--out", str(page)]]
    code = ("import sys\n"
            "for blocked in ('jax', 'jaxlib', 'flax', 'tensorflow', 'torch'):\n"
            "    sys.modules[blocked] = None  # any import of it raises ImportError\n"
            "from vmax_cli.scenariomax_cli import main\n"
            f"for args in {commands!r}:\n"
            "    try:\n"
            "        main(args, standalone_mode=False)\n"
            "    except SystemExit as done:  # convert ends with sys.exit(its status)\n"
            "        assert done.code in (0, None), (args, done.code)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert picture.stat().st_size > 1000 and page.stat().st_size > 1000


# ----------------------------------------------------------------------------- the module import graph
#
# Built by parsing every .py file with `ast` (nothing is imported, so no jax is needed): module-level and
# function-level imports alike, relative imports resolved, `from pkg import name` counted as an import of the
# submodule pkg.name when there is one. A package's __init__ is the package's module, so its re-exports are its
# edges; importing a submodule does not add an edge to its parent package (Python runs the parent's __init__
# first, but that is no dependency of the submodule's code), so a package importing its own submodules is no cycle.

REPO = Path(__file__).resolve().parents[2]
# source folder -> the package it installs as (setup.py installs cli/ as vmax_cli)
SOURCE_PACKAGES = {"scenariomax": "scenariomax", "vmax_sim": "vmax_sim", "cli": "vmax_cli"}

# Floors, lowest first: a module imports from its own floor and the ones below, never from a floor above.
# visualization sits above training: `vmax-sim view` evaluates training runs (vmax_sim.training.evaluate_run); the
# rollout collector and page writer that `vmax-sim evaluate --view` feeds are evaluation's (evaluation/rollout_view).
FLOORS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("converter", ("scenariomax",)),
    ("simulator", ("vmax_sim.datatypes", "vmax_sim.geometry", "vmax_sim.dynamics", "vmax_sim.map_index",
                   "vmax_sim.metrics", "vmax_sim.data", "vmax_sim.observation", "vmax_sim.rewards", "vmax_sim.env")),
    ("policies and learners", ("vmax_sim.policies", "vmax_sim.networks", "vmax_sim.agents")),
    ("evaluation", ("vmax_sim.evaluation",)),
    ("training", ("vmax_sim.training",)),
    ("visualization", ("vmax_sim.visualization",)),
    ("faces", ("vmax_sim.demo", "vmax_sim.bench", "vmax_sim.waymax_timing", "vmax_cli")),
)
# Modules placed by their exact name: `vmax_sim` itself re-exports the data loader, the environment and `evaluate`
# (and holds __version__), so it stands on the highest floor it re-exports from. Its subpackages are not placed
# by it: a new subpackage must be added to FLOORS.
EXACT_FLOORS = {"vmax_sim": "evaluation"}


def module_files(root: Path, packages: dict[str, str]) -> dict[str, tuple[Path, bool]]:
    """module name -> (its file, whether it is a package's __init__) for every .py file under the source folders."""
    modules = {}
    for folder, package in packages.items():
        for path in sorted((root / folder).rglob("*.py")):
            parts = [package, *path.relative_to(root / folder).with_suffix("").parts]
            is_package = parts[-1] == "__init__"
            modules[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return modules


def _known_module(name: str, modules) -> str | None:
    """The longest dotted prefix of `name` that is a module of the graph (None: a third-party or stdlib import)."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The module a `from X import ...` statement reads from, its relative dots resolved."""
    if node.level == 0:
        return node.module or ""
    parts = module.split(".") if is_package else module.split(".")[:-1]
    parts = parts[:len(parts) - (node.level - 1)]
    return ".".join(parts + ([node.module] if node.module else []))


def _module_names(tree: ast.AST, modules) -> list[tuple[str, int]]:
    """(module, line) of every string constant naming a graph module: a lazy table such as scenariomax's `_LAZY`."""
    return [(node.value, node.lineno) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in modules]


def imported_modules(module: str, path: Path, is_package: bool, modules) -> dict[str, int]:
    """target module -> first line importing it, for every import of a graph module anywhere in the file."""
    tree = ast.parse(path.read_text(), str(path))
    found: list[tuple[str | None, int]] = []
    for node in ast.walk(tree):  # walks function bodies too: lazy imports count
        if isinstance(node, ast.Import):
            found += [(_known_module(alias.name, modules), node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(module, is_package, node)
            found += [(f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else _known_module(base, modules),
                       node.lineno) for alias in node.names]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module":
            # importlib.import_module(name): a computed name may be any module the file names in a string
            found += _module_names(tree, modules)
    edges: dict[str, int] = {}
    for target, line in sorted(found, key=lambda pair: pair[1]):
        if target and target != module:
            edges.setdefault(target, line)
    return edges


def import_graph(root: Path = REPO, packages: dict[str, str] = SOURCE_PACKAGES) -> dict[str, dict[str, int]]:
    modules = module_files(root, packages)
    return {name: imported_modules(name, path, is_package, modules) for name, (path, is_package) in modules.items()}


def _strongly_connected(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Tarjan's components of more than one module (iterative: no recursion limit on a deep chain)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, targets = work[-1]
            target = next(targets, None)
            if target is not None:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph.get(target, {})))))
                elif target in on_stack:
                    low[node] = min(low[node], index[target])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    components.append(sorted(component))
    return components


def import_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """One shortest cycle (a -> ... -> a) through the first module of each strongly connected component."""
    cycles = []
    for component in _strongly_connected(graph):
        members, start = set(component), component[0]
        parents: dict[str, str] = {}
        frontier = [start]
        while frontier and start not in parents:
            following = []
            for node in frontier:
                for target in sorted(graph[node]):
                    if target in members and target not in parents:
                        parents[target] = node
                        following.append(target)
            frontier = following
        path = [start]
        while path[-1] != start or len(path) == 1:
            path.append(parents[path[-1]])
        cycles.append(path[::-1])
    return cycles


def floor_of(module: str) -> str | None:
    if module in EXACT_FLOORS:
        return EXACT_FLOORS[module]
    for name, prefixes in FLOORS:
        if any(module == prefix or module.startswith(prefix + ".") for prefix in prefixes):
            return name
    return None


def format_cycle(graph: dict[str, dict[str, int]], cycle: list[str]) -> str:
    """'a (line 3) -> b (line 9) -> a': each module with the line of its import of the next."""
    return " -> ".join(f"{a} (line {graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" -> {cycle[-1]}"


def test_no_import_cycles():
    graph = import_graph()
    lines = [f"{format_cycle(graph, cycle)}  [the group: {', '.join(group)}]"
             for cycle, group in zip(import_cycles(graph), _strongly_connected(graph))]
    assert not lines, "import cycles (one per group of modules that import each other):\n" + "\n".join(lines)


def test_every_module_stands_on_a_floor():
    unplaced = sorted(module for module in import_graph() if floor_of(module) is None)
    assert not unplaced, f"add these to FLOORS in {Path(__file__).name}: {', '.join(unplaced)}"


def test_imports_never_go_up_a_floor():
    rank = {name: position for position, (name, _) in enumerate(FLOORS)}
    upward = [f"{source} ({floor_of(source)}) line {line} imports {target} ({floor_of(target)})"
              for source, targets in sorted(import_graph().items()) for target, line in sorted(targets.items())
              if floor_of(source) and floor_of(target) and rank[floor_of(target)] > rank[floor_of(source)]]
    assert not upward, "imports from a higher floor:\n" + "\n".join(upward)


def test_the_graph_sees_lazy_relative_submodule_and_by_name_imports_and_reports_a_cycle(tmp_path):
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("import importlib\n\n_LAZY = {'f': 'pkg.a'}\n\n\ndef __getattr__(name):\n"
                                         "    return importlib.import_module(_LAZY[name])\n")
    (package / "a.py").write_text("def f():\n    from .sub import b\n    return b\n")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "b.py").write_text("import json\nfrom .. import a\n")
    graph = import_graph(tmp_path, {"pkg": "pkg"})
    assert graph == {"pkg": {"pkg.a": 3}, "pkg.a": {"pkg.sub.b": 2}, "pkg.sub": {}, "pkg.sub.b": {"pkg.a": 2}}
    assert import_cycles(graph) == [["pkg.a", "pkg.sub.b", "pkg.a"]]
    assert format_cycle(graph, ["pkg.a", "pkg.sub.b", "pkg.a"]) == "pkg.a (line 2) -> pkg.sub.b (line 2) -> pkg.a"
