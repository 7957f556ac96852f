"""`vmax_sim` uses only scenariomax's public API: the names `scenariomax` exports and its PUBLIC_MODULES.

Walks every vmax_sim source file with `ast` (no import of vmax_sim, so no jax needed) and lists each
import of a scenariomax module outside that API, each private name taken from one, and each private
attribute read through one.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import scenariomax

VMAX_SIM = Path(__file__).resolve().parents[2] / "vmax_sim"


def _is_scenariomax(module: str) -> bool:
    return module == "scenariomax" or module.startswith("scenariomax.")


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _public_submodules() -> set[str]:
    """Public modules importable as `from scenariomax import <name>` (schema, errors, render, ...)."""
    return {name.split(".", 1)[1] for name in scenariomax.PUBLIC_MODULES if name.count(".") == 1}


def _attribute_chain(node: ast.Attribute) -> tuple[str, list[str]] | None:
    """`a.b.c` -> ("a", ["b", "c"]); None when the chain does not start at a plain name."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return (node.id, parts[::-1]) if isinstance(node, ast.Name) else None


def boundary_violations(source: str, filename: str) -> list[str]:
    """`file:line: problem` for every use of scenariomax outside its public API in one source file."""
    tree = ast.parse(source, filename)
    problems: list[str] = []
    module_of_alias: dict[str, str] = {}  # local name -> the scenariomax module it is bound to

    def report(node: ast.AST, problem: str) -> None:
        problems.append(f"{filename}:{node.lineno}: {problem}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in (a for a in node.names if _is_scenariomax(a.name)):
                if alias.name not in scenariomax.PUBLIC_MODULES:
                    report(node, f"imports {alias.name}, not a public module")
                elif alias.asname:
                    module_of_alias[alias.asname] = alias.name
                else:
                    module_of_alias["scenariomax"] = "scenariomax"
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and _is_scenariomax(node.module or ""):
            if node.module not in scenariomax.PUBLIC_MODULES:
                report(node, f"imports from {node.module}, not a public module")
                continue
            for alias in node.names:
                if _is_private(alias.name):
                    report(node, f"imports the private name {alias.name} from {node.module}")
                elif node.module == "scenariomax" and alias.name in _public_submodules():
                    module_of_alias[alias.asname or alias.name] = f"scenariomax.{alias.name}"
                elif node.module == "scenariomax" and alias.name not in scenariomax.__all__:
                    report(node, f"imports {alias.name}, which scenariomax does not export (__all__)")
    inner = {id(node.value) for node in ast.walk(tree) if isinstance(node, ast.Attribute)}
    for node in ast.walk(tree):  # whole chains only (a.b.c, not also its a.b)
        chain = _attribute_chain(node) if isinstance(node, ast.Attribute) and id(node) not in inner else None
        if chain is None or chain[0] not in module_of_alias:
            continue
        root, parts = chain
        if module_of_alias[root] == "scenariomax" and parts[0] not in set(scenariomax.__all__) | _public_submodules():
            report(node, f"reads {root}.{parts[0]}, which scenariomax does not export (__all__)")
        elif any(_is_private(part) for part in parts):
            report(node, f"reads the private {root}.{'.'.join(parts)}")
    return problems


def test_vmax_sim_imports_only_the_public_scenariomax_api():
    problems = []
    for path in sorted(VMAX_SIM.rglob("*.py")):
        problems += boundary_violations(path.read_text(), str(path.relative_to(VMAX_SIM.parent)))
    assert not problems, "vmax_sim reaches past scenariomax's public API:\n" + "\n".join(problems)


@pytest.mark.parametrize("line, problem", [
    ("from scenariomax.enrich.budget import sdc_positions", "from scenariomax.enrich.budget, not a public module"),
    ("import scenariomax.pipeline", "scenariomax.pipeline, not a public module"),
    ("from scenariomax import objects_to_keep", "objects_to_keep, which scenariomax does not export"),
    ("from scenariomax.render import _import_pyplot", "private name _import_pyplot"),
    ("from scenariomax import render as r\nplt = r._import_pyplot()", "private r._import_pyplot"),
    ("import scenariomax\nscenariomax.enrich.budget.sdc_positions", "scenariomax.enrich, which scenariomax does not"),
])
def test_the_check_reports_each_kind_of_reach_past_the_api(line, problem):
    found = boundary_violations(line, "example.py")
    assert len(found) == 1 and problem in found[0], found


def test_the_public_api_covers_what_vmax_sim_needs():
    allowed = ["from scenariomax import Scenario, read_shards, list_shard_files, convert, ConvertSettings",
               "from scenariomax import make_transform, SyntheticSource, render_scenario, inspect_shards, Sizes",
               "from scenariomax.errors import InputError", "from scenariomax.schema import LANE_TYPES",
               "from scenariomax import schema as sch\nsch.TL_STOP", "from scenariomax.view import ShardIndex"]
    for line in allowed:
        assert boundary_violations(line, "example.py") == [], line


def test_every_exported_name_resolves_and_import_stays_light():
    code = ("import sys, scenariomax\n"
            "light = not any(m in sys.modules for m in ('jax', 'tensorflow', 'scipy', 'matplotlib'))\n"
            "missing = [n for n in scenariomax.__all__ if getattr(scenariomax, n, None) is None]\n"
            "import importlib\n"
            "[importlib.import_module(m) for m in scenariomax.PUBLIC_MODULES]\n"
            "print(light, missing, 'jax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "[]", "False"], out
