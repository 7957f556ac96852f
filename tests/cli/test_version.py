"""`--version` on both command lines prints the package version."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

import scenariomax
from vmax_cli.scenariomax_cli import main as scenariomax_main
from vmax_cli.vmax_cli import main as vmax_main


@pytest.mark.parametrize("program, main", [("scenariomax", scenariomax_main), ("vmax-sim", vmax_main)])
def test_version_prints_the_package_version(program, main):
    result = CliRunner().invoke(main, ["--version"])
    assert result.exit_code == 0, result.output
    assert result.stdout == f"{program}, version {scenariomax.__version__}\n"
