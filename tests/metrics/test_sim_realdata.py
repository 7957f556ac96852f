"""The map index and off-road metric on a real WOMD record: the logged SDC stays on the road."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.geometry import box_corners
from vmax_sim.map_index import build_map_index, signed_edge_distance

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "womd" / "motion_data_one_example.tfrecord"


@pytest.fixture(scope="module")
def scenario():
    if not REAL.is_file():
        pytest.skip(f"real WOMD sample not found at {REAL} (only present in the project workspace)")
    from scenariomax.shards import decode_record, iter_raw_records

    file, index, data = next(iter(iter_raw_records(REAL)))
    return decode_record(data, file, index)


def test_logged_sdc_is_never_off_road(scenario):
    s = scenario
    sdc, now = int(np.argmax(s.is_sdc)), 10
    index = build_map_index(s.roadgraph_xyz, s.roadgraph_dir, s.roadgraph_type, s.roadgraph_id, s.roadgraph_valid,
                            center_xy=np.array([s.x[sdc, now], s.y[sdc, now]]))
    assert int(index.seg_valid.sum()) > 500
    steps = np.flatnonzero(s.valid[sdc])
    boxes = jnp.asarray(np.stack([s.x[sdc], s.y[sdc], s.length[sdc], s.width[sdc], s.bbox_yaw[sdc]], -1)[steps])
    distance = jax.jit(jax.vmap(lambda b: signed_edge_distance(index, box_corners(b), b[:2])))(boxes)
    assert float(jnp.max(distance)) < 0.0  # every corner of the expert is on the road side of its nearest edge
    assert float(jnp.min(distance)) < -1.0


WOMD_91 = "scenarionet/womd_91steps/sd_training.tfrecord-00000-of-01000_2a1e44d405a6833f.pkl"


@pytest.fixture(scope="module")
def island_tip_shards(tmp_path_factory):
    """The real WOMD scene 2a1e44d405a6833f (ScenarioNet), converted as `scenariomax convert` does. Its SDC
    passes 4.7-7 m from the sharp tip of road edge 39, whose nearest point to two box corners is a vertex."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.sources.scenarionet import ScenarioNetSource
    from tests.conftest import realdata_file

    path = realdata_file(WOMD_91)
    out = tmp_path_factory.mktemp("island_tip")
    transform, transform_settings = make_transform()
    result = convert(ScenarioNetSource(str(path)), ConvertSettings(
        out=out, workers=1, progress=False, transform=transform, transform_settings=transform_settings))
    assert result.ok and result.num_scenarios == 1, result.failures
    return out


def test_real_island_tip_keeps_every_logged_step_on_the_road(island_tip_shards):
    """Steps 31 and 36 were judged off-road: the corner's nearest edge point is a reflex vertex and the
    side came from whichever of its two segments won the tie (a brute force and Waymax say on the road)."""
    from scenariomax.shards import read_shards
    from vmax_sim.data import DataConfig, scenario_to_numpy_state
    from vmax_sim.metrics import offroad

    (s,) = list(read_shards(island_tip_shards))
    index = scenario_to_numpy_state(s, DataConfig()).map_index
    sdc = s.sdc_index
    steps = np.flatnonzero(s.valid[sdc])
    boxes = np.stack([s.x[sdc], s.y[sdc], s.length[sdc], s.width[sdc], s.bbox_yaw[sdc]], -1)[steps]
    is_offroad, worst = jax.jit(jax.vmap(offroad, in_axes=(None, 0)))(index, jnp.asarray(boxes, jnp.float32))
    assert not np.asarray(is_offroad).any(), steps[np.asarray(is_offroad)]
    assert float(worst[steps == 31][0]) == pytest.approx(-4.27, abs=0.05)  # the corner at the tip is 4.7 m off
    assert float(worst[steps == 36][0]) == pytest.approx(-4.76, abs=0.05)


def test_real_island_tip_expert_has_no_offroad_step(island_tip_shards):
    from vmax_sim.evaluation import evaluate

    result = evaluate("expert", str(island_tip_shards), batch_size=1)
    assert result.scenario_ids == ("2a1e44d405a6833f",)
    assert float(result.episodes["offroad"][0]) == 0.0
    assert float(result.episodes["accurate"][0]) == 1.0


def test_real_nocturne_expert_drives_nowhere_against_its_lane(tmp_path):
    """Nocturne's tfrecord-00358-of-01000_65: the logged SDC goes straight through a junction in lane 115, 1.1-1.2 m
    off its centre, over connectors 112 and 117 of the crossing traffic (0-1 m away at steps 24-40). Judged against
    the nearest centreline, the expert drove 3.2 m against the lane in 1 s (driving direction 0.5, V-Max 0.421)."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.schema import Sizes
    from scenariomax.sources.registry import make_source
    from tests.conftest import realdata_file
    from vmax_sim.evaluation import evaluate

    source = make_source("gpudrive", src=str(realdata_file("nocturne/example_scenario.json")), sizes=Sizes())
    transform, transform_settings = make_transform()
    result = convert(source, ConvertSettings(out=tmp_path, workers=1, progress=False, transform=transform,
                                             transform_settings=transform_settings))
    assert result.ok and result.num_scenarios == 1, result.failures
    run = evaluate("expert", str(tmp_path), batch_size=1)
    assert run.scenario_ids == ("tfrecord-00358-of-01000_65",)
    assert float(run.episodes["distance_against_lane"][0]) < 0.1
    assert float(run.episodes["driving_direction"][0]) == 1.0
