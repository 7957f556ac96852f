"""What a wheel of `vmax` installs and depends on, checked from pyproject.toml and setup.py without building.

The slow twin, test_wheel.py, builds the wheel and runs it from a fresh virtualenv.
"""

from __future__ import annotations

import ast
import fnmatch
import re
import runpy
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import setuptools
import tomllib

REPO = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
PROJECT = PYPROJECT["project"]
EXTRAS = PROJECT["optional-dependencies"]
FIRST_PARTY = {"scenariomax", "vmax_sim", "vmax_cli"}
SCENARIOMAX_HALF = (REPO / "scenariomax", REPO / "cli" / "__init__.py", REPO / "cli" / "scenariomax_cli.py")
SIM_HALF = (REPO / "vmax_sim", REPO / "cli" / "vmax_cli.py")
# Distribution name (lower case) -> the module it provides, where that is not the name with '-' -> '_'.
MODULE_OF_DISTRIBUTION = {"protobuf": "google.protobuf", "google-crc32c": "google_crc32c", "pillow": "PIL",
                          "orbax-checkpoint": "orbax", "tensorflow-cpu": "tensorflow", "pyyaml": "yaml"}
README_COMMANDS = ["python3.11 -m venv .venv && .venv/bin/pip install -e '.[sim]' && .venv/bin/vmax-sim demo",
                   "python3.11 -m venv .venv && .venv/bin/pip install -e '.[dev]' && .venv/bin/python -m pytest"]


def _requirement_name(requirement: str) -> str:
    return re.match(r"[A-Za-z0-9._-]+", requirement).group(0)


def _module_of(requirement: str) -> str:
    name = _requirement_name(requirement)
    return MODULE_OF_DISTRIBUTION.get(name.lower(), name.replace("-", "_"))


def _third_party(requirements: list[str]) -> list[str]:
    return [r for r in requirements if _requirement_name(r) != PROJECT["name"]]  # drop "vmax[sim]"


def _python_files(paths) -> list[Path]:
    return [file for path in paths for file in ([path] if path.is_file() else sorted(path.rglob("*.py")))]


def _imported_modules(paths) -> set[str]:
    """Every absolute module name imported in these files or folders, at the top or inside a function."""
    names: set[str] = set()
    for file in _python_files(paths):
        for node in ast.walk(ast.parse(file.read_text(), str(file))):
            if isinstance(node, ast.Import):
                names.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module)
                names.update(f"{node.module}.{alias.name}" for alias in node.names)  # from google import protobuf
    return names


def _is_imported(module: str, imported: set[str]) -> bool:
    return any(name == module or name.startswith(module + ".") for name in imported)


def _top_level_third_party(imported: set[str], local: set[str] = frozenset()) -> set[str]:
    tops = {name.split(".")[0] for name in imported}
    return tops - set(sys.stdlib_module_names) - FIRST_PARTY - set(local)


def _tops(requirements: list[str]) -> set[str]:
    return {_module_of(r).split(".")[0] for r in _third_party(requirements)}


@pytest.fixture(scope="module")
def setup_call() -> dict:
    """The keyword arguments setup.py hands to setuptools (its package list and folder mapping)."""
    captured: dict = {}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(setuptools, "setup", lambda **kwargs: captured.update(kwargs))
        patch.chdir(REPO)
        runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    return captured


def test_no_top_level_cli_package_is_installed(setup_call):
    packages = setup_call["packages"]
    assert not [p for p in packages if p == "cli" or p.startswith("cli.")]
    assert {p.split(".")[0] for p in packages} == FIRST_PARTY
    assert setup_call["package_dir"]["vmax_cli"] == "cli"
    assert "packages" not in PYPROJECT["tool"]["setuptools"], "pyproject.toml would override setup.py's package list"


def test_every_source_folder_is_packaged(setup_call):
    """A folder of modules missing from the list would be silently left out of the wheel."""
    installed_as = {"cli": "vmax_cli"}
    expected = set()
    for top in ("scenariomax", "vmax_sim", "cli"):
        for module in (REPO / top).rglob("*.py"):
            parts = module.parent.relative_to(REPO).parts
            expected.add(".".join((installed_as.get(parts[0], parts[0]), *parts[1:])))
    assert expected <= set(setup_call["packages"])


def test_schema_files_travel_inside_scenariomax(setup_call):
    assert setup_call["package_dir"]["scenariomax._schemas"] == "schemas"
    assert "scenariomax._schemas" in setup_call["packages"]
    package_data = PYPROJECT["tool"]["setuptools"]["package-data"]
    patterns = package_data.get("scenariomax._schemas", []) + package_data.get("*", [])
    schema_files = sorted((REPO / "schemas").iterdir())
    assert schema_files
    for file in schema_files:
        assert any(fnmatch.fnmatch(file.name, pattern) for pattern in patterns), f"{file.name} is not packaged"


def test_console_scripts_point_into_vmax_cli():
    scripts = PROJECT["scripts"]
    assert scripts == {"scenariomax": "vmax_cli.scenariomax_cli:main", "vmax-sim": "vmax_cli.vmax_cli:main"}
    for target in scripts.values():
        module, function = target.split(":")
        source = REPO / "cli" / f"{module.split('.')[1]}.py"
        defined = {node.name for node in ast.parse(source.read_text()).body if isinstance(node, ast.FunctionDef)}
        assert function in defined, f"{target}: {source} has no {function}"


def test_every_base_dependency_is_imported_by_scenariomax():
    imported = _imported_modules(SCENARIOMAX_HALF)
    unused = [r for r in PROJECT["dependencies"] if not _is_imported(_module_of(r), imported)]
    assert not unused, f"base dependencies no scenariomax module imports (drop them or move them to an extra): {unused}"


def test_scenariomax_needs_only_the_base_install():
    """No JAX: every third-party module scenariomax imports is a base dependency, or the optional Ray engine."""
    needed = _top_level_third_party(_imported_modules(SCENARIOMAX_HALF))
    assert needed - _tops(EXTRAS["ray"]) <= _tops(PROJECT["dependencies"])
    assert not needed & _tops(EXTRAS["sim"])


def test_every_sim_dependency_is_imported_by_vmax_sim():
    imported = _imported_modules(SIM_HALF)
    unused = [r for r in EXTRAS["sim"] if not _is_imported(_module_of(r), imported)]
    assert not unused, f"sim dependencies vmax_sim never imports: {unused}"
    # vmax_sim/waymax_timing.py imports waymax, but runs only under the user's own Waymax interpreter
    # (`vmax-sim bench --compare-waymax PYTHON`): Waymax is never a dependency.
    assert _top_level_third_party(imported, local={"waymax"}) <= _tops(PROJECT["dependencies"]) | _tops(EXTRAS["sim"])


def test_dev_extra_installs_what_the_tests_import():
    """`pip install -e '.[dev]'` (README, .ci/run) is enough for the default suite; tf and ray tests skip."""
    assert f"{PROJECT['name']}[sim]" in EXTRAS["dev"]
    local = {file.stem for file in _python_files([REPO / "tests", REPO / "benchmarks"])} | {"tests"}
    needed = _top_level_third_party(_imported_modules([REPO / "tests"]), local)
    provided = set().union(*(_tops(reqs) for reqs in (PROJECT["dependencies"], EXTRAS["sim"], EXTRAS["dev"],
                                                       EXTRAS["tf"], EXTRAS["ray"])))
    assert needed <= provided, f"tests import {sorted(needed - provided)}, which no dependency installs"


def test_readme_commands_install_the_extras():
    blocks = re.findall(r"```bash\n(.*?)\n```", (REPO / "README.md").read_text(), re.S)
    assert blocks[:2] == README_COMMANDS


def test_vmax_sim_without_the_sim_extra_says_what_to_install(tmp_path):
    from vmax_cli.vmax_cli import SIM_EXTRA_MODULES

    assert _tops(EXTRAS["sim"]) <= SIM_EXTRA_MODULES
    code = ("import sys\nsys.modules['jax'] = None  # as if the sim extra were not installed\n"
            "from vmax_cli.vmax_cli import main\nmain()")
    done = subprocess.run([sys.executable, "-c", code, "demo", "--out", str(tmp_path / "demo")], capture_output=True,
                          text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "error: vmax-sim needs the simulator extra (jax is not installed): pip install 'vmax[sim]'"]


def _copy_scenariomax(site: Path) -> None:
    shutil.copytree(REPO / "scenariomax", site / "scenariomax", ignore=shutil.ignore_patterns("__pycache__"))


def _load_schema_from(site: Path) -> subprocess.CompletedProcess:
    code = "import scenariomax.schema as s\nprint(s.__file__)\nprint(len(s.load_schema().features))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=site, timeout=120)


def test_an_installed_scenariomax_reads_its_packaged_schema(tmp_path):
    """Laid out as a wheel installs it (no checkout around): the schema comes from scenariomax/_schemas, even with an
    unrelated `schemas/` folder beside the package."""
    site = tmp_path / "site-packages"
    _copy_scenariomax(site)
    (site / "scenariomax" / "_schemas").mkdir()
    shutil.copy(REPO / "schemas" / "shard_schema.v1.json", site / "scenariomax" / "_schemas")
    (site / "schemas").mkdir()
    (site / "schemas" / "shard_schema.v1.json").write_text("not the shard schema")
    done = _load_schema_from(site)
    assert done.returncode == 0, done.stderr
    file, num_features = done.stdout.split()
    assert Path(file).is_relative_to(site) and int(num_features) > 50


def test_a_scenariomax_without_its_schema_names_both_places(tmp_path):
    site = tmp_path / "site-packages"
    _copy_scenariomax(site)
    done = _load_schema_from(site)
    assert done.returncode != 0
    assert "FileNotFoundError: shard_schema.v1.json: the shard schema is neither in scenariomax/_schemas" in done.stderr
