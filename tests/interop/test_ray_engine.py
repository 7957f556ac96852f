"""`--engine ray` on a local Ray instance (needs the `ray` extra; run with `pytest -m ray`)."""

import pytest

from scenariomax import Sizes, read_shards
from scenariomax.pipeline import ConvertSettings, convert
from tests.foundation.toy_source import ToySource

pytestmark = pytest.mark.ray
ray = pytest.importorskip("ray", reason="the ray extra is not installed")

SIZES = Sizes(num_objects=8, num_roadgraph=2000, num_lanes=4)


def test_ray_engine_writes_the_same_shards_as_processes(tmp_path):
    source = ToySource(broken_units=(3,))
    by_process = convert(source, ConvertSettings(out=tmp_path / "p", sizes=SIZES, shard_size=5, workers=2,
                                                 progress=False))
    by_ray = convert(source, ConvertSettings(out=tmp_path / "r", sizes=SIZES, shard_size=5, workers=2,
                                             progress=False, engine="ray"))
    ray.shutdown()
    assert by_ray.shards == by_process.shards and by_ray.failures == by_process.failures
    for name in by_ray.shards:
        assert (tmp_path / "r" / name).read_bytes() == (tmp_path / "p" / name).read_bytes()
    assert len(list(read_shards(tmp_path / "r"))) == by_ray.num_scenarios == 19
