"""Every Python block of the README runs, as written, in a folder holding what the README's convert line makes
(`shards/` of synthetic scenarios with the default 128 object slots), in the README's order."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)


def test_the_readme_has_python_blocks():
    assert len(python_blocks()) >= 3


@pytest.mark.slow  # converts, evaluates and trains a small PPO run (~2 min on 2 cores)
def test_every_readme_python_block_runs(tmp_path):
    from scenariomax import ConvertSettings, Sizes, SyntheticSource, convert, make_transform

    sizes = Sizes()  # what `scenariomax convert --dataset synthetic` writes
    transform, transform_settings = make_transform()
    convert(SyntheticSource(num_scenarios=8, seed=0, sizes=sizes),
            ConvertSettings(out=tmp_path / "shards", workers=1, sizes=sizes, progress=False, transform=transform,
                            transform_settings=transform_settings))
    for number, block in enumerate(python_blocks()):
        done = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True,
                              timeout=900)
        assert done.returncode == 0, f"README Python block {number + 1} failed:\n{block}\n{done.stderr[-3000:]}"
        assert "Traceback" not in done.stderr
    assert (tmp_path / "out" / "manifest.json").exists() and (tmp_path / "runs" / "ppo" / "summary.json").exists()
