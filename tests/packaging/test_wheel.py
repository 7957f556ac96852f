"""The wheel as a user gets it: built, installed in a fresh virtualenv, run from outside the checkout.

This is the CI step that builds the wheel and runs the README's main job (`vmax-sim demo`) from it: .ci/run runs
it in its slow stage. It needs the package index (pip fetches the build backend and the dependencies).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
import tomllib

REPO = Path(__file__).resolve().parents[2]
VERSION = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
# Built from a copy: the build's build/ and *.egg-info stay out of the working tree, and files left in a stale
# build/ there cannot slip into the wheel. The patterns are .gitignore's.
NOT_SOURCE = shutil.ignore_patterns(".git", ".venv*", "build", "dist", "runs", "out", "*.egg-info", "__pycache__",
                                    ".pytest_cache", ".hypothesis", ".ruff_cache", "*.tmp")
NO_SIM_LINE = "error: vmax-sim needs the simulator extra (jax is not installed): pip install 'vmax[sim]'"


def _clean_env() -> dict[str, str]:
    """The caller's environment without what would let the checkout or its virtualenv leak into the new one."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    return env | {"PIP_DISABLE_PIP_VERSION_CHECK": "1"}


def _run(args, cwd: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    done = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=_clean_env())
    assert done.returncode == 0, f"{args}: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


def _build_wheel(tmp_path: Path) -> Path:
    source, dist = tmp_path / "source", tmp_path / "dist"
    shutil.copytree(REPO, source, ignore=NOT_SOURCE)
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", dist, source], cwd=tmp_path)
    (wheel,) = dist.glob("vmax-*.whl")
    return wheel


@pytest.mark.slow
def test_the_wheel_converts_validates_and_runs_the_demo_outside_the_checkout(tmp_path):
    wheel = _build_wheel(tmp_path)
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {name.split("/")[0] for name in names}
    assert top_level == {"scenariomax", "vmax_sim", "vmax_cli", f"vmax-{VERSION}.dist-info"}  # no `cli`, no `schemas`
    assert {"scenariomax/_schemas/shard_schema.v1.json", "scenariomax/view/viewer.html",
            "vmax_cli/vmax_cli.py"} <= set(names)
    print(f"\n{wheel.name}: {wheel.stat().st_size / 1e3:.0f} kB")

    venv, work = tmp_path / "venv", tmp_path / "work"
    work.mkdir()
    python, bin_dir = venv / "bin" / "python", venv / "bin"
    started = time.monotonic()
    _run([sys.executable, "-m", "venv", venv], cwd=work)

    # The base install: the converter works and JAX is not there.
    _run([python, "-m", "pip", "install", "-q", wheel], cwd=work)
    _run([bin_dir / "scenariomax", "convert", "--dataset", "synthetic", "--num-scenarios", "4", "--workers", "1",
          "--out", "shards"], cwd=work)
    _run([bin_dir / "scenariomax", "validate", "shards"], cwd=work)  # exit 1 on any bad record
    where = _run([python, "-c", "import importlib.util, scenariomax; print(scenariomax.__file__, "
                  "importlib.util.find_spec('jax'))"], cwd=work).stdout.split()
    assert Path(where[0]).is_relative_to(venv) and where[1] == "None"
    no_sim = subprocess.run([bin_dir / "vmax-sim", "demo"], cwd=work, capture_output=True, text=True, timeout=300,
                            env=_clean_env())
    assert no_sim.returncode == 2 and no_sim.stderr.strip().splitlines() == [NO_SIM_LINE]

    # The sim extra: the README's main job, made small.
    _run([python, "-m", "pip", "install", "-q", f"{wheel}[sim]"], cwd=work)
    _run([bin_dir / "vmax-sim", "demo", "--out", "demo"], cwd=work, timeout=1500)  # the README's main job, as is
    assert "| Metric (%) | expert | constant | trained BC |" in (work / "demo" / "comparison.md").read_text()
    assert (work / "demo" / "rollout.png").stat().st_size > 10_000
    print(f"fresh install + convert + demo from the wheel: {time.monotonic() - started:.0f} s")
