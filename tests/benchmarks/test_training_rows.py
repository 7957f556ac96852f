"""benchmarks/training.py: which configurations `--only` selects (the GPU script names rows of its own)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from training import CONFIGS, _selected  # noqa: E402


def test_a_preset_name_selects_all_its_rows():
    rows = _selected(["bc-mlp", "ppo-mlp"])
    assert rows and all(preset in ("bc-mlp", "ppo-mlp") for preset, _ in rows)
    assert len(rows) == sum(1 for preset, _ in CONFIGS if preset in ("bc-mlp", "ppo-mlp"))


def test_a_listed_row_runs_once_and_a_new_row_runs_as_written():
    rows = _selected(["ppo-selfplay selfplay.max_agents=8", "ppo-selfplay selfplay.max_agents=32 algo.num_envs=256"])
    assert rows == [("ppo-selfplay", ["selfplay.max_agents=8"]),
                    ("ppo-selfplay", ["selfplay.max_agents=32", "algo.num_envs=256"])]
