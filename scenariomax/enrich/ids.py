"""Deterministic feature ids: the same input gives the same id in every process and on every run.

Python's `hash()` of a string is salted per process, so it must never be used for ids that land
in shards (resumed or parallel conversions would disagree).
"""

from __future__ import annotations

import hashlib

import numpy as np

from scenariomax.enrich.geometry import polyline_runs
from scenariomax.scenario import Scenario

_ID_BITS = 62  # positive int64, far from the -1 pad


def stable_id(key: str) -> int:
    """A positive 62-bit id derived from a string key (blake2b, process-independent)."""
    digest = hashlib.blake2b(key.encode("utf-8"), digest_size=8).digest()
    return int.from_bytes(digest, "little") >> (64 - _ID_BITS)


def with_missing_ids_assigned(scenario: Scenario) -> Scenario:
    """Gives every valid roadgraph run with a negative id a fresh id (max id + 1, + 2, ... in order)."""
    ids = scenario.roadgraph_id
    valid = scenario.roadgraph_valid
    missing = valid & (ids < 0)
    if not missing.any():
        return scenario
    new_ids = ids.copy()
    next_id = int(ids[valid].max(initial=-1)) + 1
    # Runs of missing-id points are split by type, so adjacent features of different kinds stay apart.
    keys = np.where(missing, scenario.roadgraph_type, -1)
    for start, stop in polyline_runs(keys, missing):
        new_ids[start:stop] = next_id
        next_id += 1
    return scenario.replace(roadgraph_id=new_ids)
