"""Speed limit per roadgraph lane point (`roadgraph_speed_limit`, m/s).

The source's value is kept where it is >= 0. Elsewhere lane points get a default by lane type:
freeway 29 m/s (~65 mph), surface street 13.4 m/s (~30 mph), bike lane 6.7 m/s (~15 mph).
Non-lane points stay -1.
"""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.scenario import Scenario

DEFAULT_SPEED_LIMITS_MPS = {
    sch.RG_LANE_FREEWAY: 29.0,
    sch.RG_LANE_SURFACE_STREET: 13.4,
    sch.RG_LANE_BIKE: 6.7,
}


def fill_speed_limits(types: np.ndarray, valid: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """(R,), (R,), (R,) -> (R,) float32: known limits kept, lane defaults elsewhere, -1 off lanes."""
    out = np.full(types.shape, -1.0, np.float32)
    for lane_type, default in DEFAULT_SPEED_LIMITS_MPS.items():
        out[(types == lane_type) & valid] = default
    known = np.asarray(limits) >= 0
    lanes = np.isin(types, sch.LANE_TYPES) & valid
    out[known & lanes] = np.asarray(limits, np.float32)[known & lanes]
    return out


def with_speed_limits(scenario: Scenario) -> Scenario:
    return scenario.replace(roadgraph_speed_limit=fill_speed_limits(
        scenario.roadgraph_type, scenario.roadgraph_valid, scenario.roadgraph_speed_limit))
