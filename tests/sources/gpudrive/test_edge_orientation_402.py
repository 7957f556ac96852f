"""Regression: the road-edge orientation rule on the real GPUDrive file `tfrecord-00000-of-01000_402.json`.

One of its road edges is a side of a 1.6 m barrier between a freeway and a street with a bike lane. The
former nearest-lane vote took the bike lane beyond the barrier as that edge's road, reversed 5 correct
edges and put the logged SDC off the road at all 91 steps (2233 of 4630 vehicle box positions). The rule
now only lets lanes in sight vote (scenariomax.enrich.orientation).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.enrich.transform import make_transform
from scenariomax.sources.gpudrive import GpuDriveSource
from tests.conftest import realdata_file

FILE = "gpudrive/tfrecord-00000-of-01000_402.json"


@pytest.fixture(scope="module")
def raw_and_converted():
    path = str(realdata_file(FILE))
    raw = next(GpuDriveSource(path).read_unit(path))
    transform, _ = make_transform()  # the enrichment `scenariomax convert` applies
    return raw, decode_scenario(encode_scenario(transform(raw)))


def test_no_road_edge_is_reversed(raw_and_converted):
    raw, converted = raw_and_converted
    for edge_id in np.unique(raw.roadgraph_id[np.isin(raw.roadgraph_type, sch.ROAD_EDGE_TYPES)]):
        before = raw.roadgraph_xyz[raw.roadgraph_id == edge_id]
        after = converted.roadgraph_xyz[converted.roadgraph_id == edge_id]
        np.testing.assert_allclose(after, before, atol=1e-3, err_msg=f"edge {edge_id}")


def test_logged_sdc_is_never_off_road(raw_and_converted):
    from vmax_sim.data import DataConfig, scenario_to_numpy_state
    from vmax_sim.metrics import offroad

    _, s = raw_and_converted
    index = jax.device_put(scenario_to_numpy_state(s, DataConfig(num_objects=128)).map_index)
    sdc = s.sdc_index
    steps = np.flatnonzero(s.valid[sdc])
    assert len(steps) == 91
    boxes = np.stack([s.x[sdc], s.y[sdc], s.length[sdc], s.width[sdc], s.bbox_yaw[sdc]], -1)[steps]
    is_offroad, distance = jax.jit(jax.vmap(lambda box: offroad(index, box)))(jnp.asarray(boxes, jnp.float32))
    assert not bool(jnp.any(is_offroad)), np.flatnonzero(np.asarray(is_offroad))
    assert float(jnp.max(distance)) < 0.0
