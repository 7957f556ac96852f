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
