"""The issue bars on 200 synthetic scenarios (slow: `pytest -m slow`)."""

import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from scenariomax import read_shards
from vmax_cli.scenariomax_cli import main

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from sdc_path_quality import path_quality  # noqa: E402

pytestmark = pytest.mark.slow


def _convert(out, workers):
    result = CliRunner().invoke(main, ["convert", "--dataset", "synthetic", "--num-scenarios", "200", "--seed", "0",
                                       "--out", str(out), "--workers", str(workers)], catch_exceptions=False)
    assert result.exit_code == 0, result.output


def test_200_synthetic_validate_are_deterministic_and_have_sdc_paths(tmp_path):
    _convert(tmp_path / "a", 2)
    assert CliRunner().invoke(main, ["validate", str(tmp_path / "a")]).exit_code == 0
    _convert(tmp_path / "b", 1)
    for shard in (tmp_path / "a").glob("*.tfrecord"):
        assert (tmp_path / "b" / shard.name).read_bytes() == shard.read_bytes()
    quality = path_quality(str(tmp_path / "a"))
    assert quality["with_on_route_path"] == 200
    assert quality["scenarios_with_95pct_within_1m"] == 200
    # Direction vectors are unit wherever the next point is in the same polyline.
    for scenario in read_shards(tmp_path / "a"):
        ids, valid = scenario.roadgraph_id, scenario.roadgraph_valid
        same_next = np.zeros_like(valid)
        same_next[:-1] = valid[:-1] & valid[1:] & (ids[:-1] == ids[1:])
        norms = np.linalg.norm(scenario.roadgraph_dir[same_next], axis=1)
        assert np.allclose(norms, 1.0, atol=1e-3)
