"""Every command and option the README names exists: `--help` runs and lists the option."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from vmax_cli.scenariomax_cli import main as scenariomax_main
from vmax_cli.vmax_cli import main as vmax_main

README = Path(__file__).resolve().parents[2] / "README.md"
APPS = {"scenariomax": scenariomax_main, "vmax-sim": vmax_main}
# A command line in a code block: the program at the start of the line, then the sub-command.
COMMAND_LINE = re.compile(r"^(?:\.venv/bin/)?(scenariomax|vmax-sim) ([a-z][a-z-]*)(.*)$", re.MULTILINE)


def _readme_commands() -> list[tuple[str, str, tuple[str, ...]]]:
    found = []
    for program, command, rest in COMMAND_LINE.findall(README.read_text()):
        options = tuple(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest.split("#")[0]))
        found.append((program, command, options))
    return found


def test_the_readme_names_commands():
    assert {(p, c) for p, c, _ in _readme_commands()} >= {("scenariomax", "convert"), ("vmax-sim", "train"),
                                                          ("vmax-sim", "evaluate")}


@pytest.mark.parametrize("program, command, options", _readme_commands(),
                         ids=lambda value: value if isinstance(value, str) else None)
def test_each_readme_command_runs_with_help_and_has_its_options(program, command, options):
    result = CliRunner().invoke(APPS[program], [command, "--help"])
    assert result.exit_code == 0, f"`{program} {command} --help` failed: {result.output}"
    for option in options:
        assert option in result.output, f"`{program} {command}` has no {option} (named in the README)"


def test_the_readme_names_every_dataset_convert_accepts_and_no_other():
    from scenariomax.sources.registry import DATASETS

    named = set()
    for choice in re.findall(r"--dataset (\{[a-z0-9_,]+\}|[a-z0-9_]+)", README.read_text()):
        named.update(choice.strip("{}").split(","))
    assert named == set(DATASETS)


# What the README's commands write inside a checkout (convert --out shards/, view, vmax-sim view, train/demo).
README_OUTPUTS = ("shards/train-00000-of-00001.tfrecord", "view.html", "rollouts.html", "runs/demo/config.json")


def test_what_the_readme_commands_write_is_git_ignored():
    repo = README.parent
    if shutil.which("git") is None or not (repo / ".git").exists():
        pytest.skip("not a git checkout")
    text = README.read_text()
    assert all(output.split("/")[0] in text for output in README_OUTPUTS)
    done = subprocess.run(["git", "check-ignore", "--no-index", *README_OUTPUTS], cwd=repo, capture_output=True,
                          text=True, check=False)
    assert sorted(done.stdout.split()) == sorted(README_OUTPUTS), done.stderr
