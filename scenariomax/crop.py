"""Which map content a scenario keeps: distances to the SDC's logged positions.

The converter's budget fit (`scenariomax.enrich.budget`) and the simulator's state builder
(`vmax_sim.data.convert`) crop the roadgraph, lights and objects with these same measures, so a state
keeps exactly what a shard would keep.
"""

from __future__ import annotations

import numpy as np

from scenariomax.scenario import Scenario


def sdc_positions(scenario: Scenario) -> np.ndarray:
    """Valid (x, y) positions of the SDC over the whole log. -> (k, 2) float64"""
    sdc = scenario.sdc_index
    mask = scenario.valid[sdc]
    return np.stack([scenario.x[sdc, mask], scenario.y[sdc, mask]], axis=1).astype(np.float64)


def distance_to_points(points: np.ndarray, anchors: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Distance from each point (m, 2) to its nearest anchor (k, 2); 0 everywhere without anchors. -> (m,)

    Chunked so memory stays ~chunk * k whatever the roadgraph size."""
    if len(anchors) == 0:
        return np.zeros(len(points))
    out = np.empty(len(points))
    ax, ay = anchors[:, 0], anchors[:, 1]  # (k,)
    for start in range(0, len(points), chunk):
        # x and y as separate (chunk, k) planes: the bits of ((p - a) ** 2).sum(-1), without the slow 2-wide sum.
        dist2 = points[start:start + chunk, 0:1] - ax
        dist2 *= dist2
        dy = points[start:start + chunk, 1:2] - ay
        dy *= dy
        dist2 += dy
        out[start:start + chunk] = np.sqrt(dist2.min(axis=1))
    return out
