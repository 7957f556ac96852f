"""Roadgraph direction vectors re-derived from the points themselves.

A polyline is a consecutive run of valid points with equal `roadgraph_id`. Each point's direction
is the unit vector to the next point of its polyline; the last point of a polyline gets zeros.
Repeated points (zero-length steps) borrow the direction of the next real step of their polyline,
so every point that has a successor in its polyline gets a unit vector when one exists.
"""

from __future__ import annotations

import numpy as np

from scenariomax.enrich.geometry import row_norm
from scenariomax.scenario import Scenario


def roadgraph_directions(xyz: np.ndarray, ids: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Unit 3-D direction to the next point of the same polyline. (R, 3), (R,), (R,) -> (R, 3) float32"""
    xyz = np.asarray(xyz, np.float64)
    valid = np.asarray(valid, bool)
    dirs = np.zeros_like(xyz)
    if len(xyz) < 2:
        return dirs.astype(np.float32)
    has_next = (ids[1:] == ids[:-1]) & valid[1:] & valid[:-1]  # (R-1,)
    step = np.diff(xyz, axis=0)
    norm = row_norm(step)
    usable = has_next & (norm > 1e-6)
    # For a repeated point, look ahead to the next usable step; it must still be in the same run.
    index = np.where(usable, np.arange(len(step)), len(step))
    next_usable = np.minimum.accumulate(index[::-1])[::-1]
    run_break = np.concatenate([[0], np.cumsum(~has_next)])  # equal values = same polyline
    found = next_usable < len(step)
    source = np.where(found, next_usable, 0)
    same_run = found & (run_break[source] == run_break[np.arange(len(step))])
    chosen = has_next & same_run
    dirs[:-1][chosen] = step[source[chosen]] / norm[source[chosen], None]
    return dirs.astype(np.float32)


def with_recomputed_directions(scenario: Scenario) -> Scenario:
    """The scenario with `roadgraph_dir` re-derived from its points."""
    dirs = roadgraph_directions(scenario.roadgraph_xyz, scenario.roadgraph_id, scenario.roadgraph_valid)
    return scenario.replace(roadgraph_dir=dirs)
