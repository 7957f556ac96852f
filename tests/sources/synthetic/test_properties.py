"""Property test: any (seed, index) gives a sound, collision-free scenario."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.schema import OBJECT_TYPE_VEHICLE, Sizes
from scenariomax.sources.synthetic import (
    generate_scenario,
    lane_graph_distance,
    overlapping_vehicle_pairs,
    red_light_crossings,
    road_edge_signed_distance,
)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), index=st.integers(0, 10**6))
def test_any_seed_gives_a_sound_scenario(seed, index):
    s = generate_scenario(seed, index, Sizes())
    assert s.validate() == []
    assert s.is_sdc[0] and s.valid[0].all()
    assert overlapping_vehicle_pairs(s) == []
    assert red_light_crossings(s, 0) == []
    assert lane_graph_distance(s, 0).max() < 1.0
    mask = s.valid & (s.object_type == OBJECT_TYPE_VEHICLE)[:, None]
    points = np.stack([s.x[mask], s.y[mask]], axis=-1).astype(np.float64)
    assert road_edge_signed_distance(s, points).max() < 0.0
