"""Expert replay bars: the real WOMD sample (no off-road) and, slow, 200 synthetic scenarios."""

from __future__ import annotations

import pytest

from scenariomax.enrich.transform import make_transform
from scenariomax.pipeline import ConvertSettings, convert
from scenariomax.schema import Sizes
from tests.integration_sim.conftest import REALDATA
from vmax_sim.data import DataConfig
from vmax_sim.evaluation import evaluate


def _convert(source, out, sizes, workers=1):
    transform, settings = make_transform()
    result = convert(source, ConvertSettings(out=out, workers=workers, sizes=sizes, progress=False,
                                             transform=transform, transform_settings=settings))
    assert result.num_failures == 0
    return out


def test_expert_on_the_real_womd_scenario_stays_on_the_road(tmp_path):
    raw = REALDATA / "womd" / "motion_data_one_scenario.tfrecord"
    if not raw.exists():
        pytest.skip(f"real WOMD sample not found at {raw} (the shared folder is absent)")
    from scenariomax.sources.womd import WomdSource

    shards = _convert(WomdSource(str(raw), sizes=Sizes()), tmp_path / "womd", Sizes())
    summary = evaluate("expert", DataConfig(path=str(shards), batch_size=1)).summary
    assert summary["num_episodes"] == 1
    assert summary["metrics"]["offroad"] == 0.0
    assert summary["accuracy"] == 1.0
    assert summary["metrics"]["log_divergence"] < 0.1


def test_expert_on_the_real_av2_scenario_stays_on_the_road(tmp_path):
    # AV2 splits the drivable area into touching polygons; a car crossing their seam must not be off-road.
    raw = REALDATA / "av2"
    if not raw.exists():
        pytest.skip(f"real AV2 sample not found at {raw} (the shared folder is absent)")
    from scenariomax.sources.av2 import Av2Source

    shards = _convert(Av2Source(str(raw), sizes=Sizes()), tmp_path / "av2", Sizes())
    summary = evaluate("expert", DataConfig(path=str(shards), batch_size=1)).summary
    assert summary["metrics"]["offroad"] == 0.0
    assert summary["accuracy"] == 1.0
    assert summary["metrics"]["ego_progress"] > 0.95


@pytest.mark.slow
def test_expert_replay_bar_on_200_synthetic_scenarios(tmp_path):
    from scenariomax.sources.synthetic import SyntheticSource

    sizes = Sizes(num_objects=64)
    shards = _convert(SyntheticSource(num_scenarios=200, seed=0, sizes=sizes), tmp_path / "syn", sizes, workers=2)
    summary = evaluate("expert", DataConfig(path=str(shards), batch_size=8)).summary
    assert summary["num_episodes"] == 200
    assert summary["accuracy"] >= 0.99
    assert summary["vmax_score"] >= 0.9
