"""WOMD motion tf.Example records -> `Scenario` (the layout our shards already follow).

The record is decoded by the shard codec, then normalised: headings wrapped to [-pi, pi] (WOMD
tf.Examples store unwrapped yaws), padding roadgraph points dropped, the source set to "womd"
and the scenario fitted to the budget (SDC to slot 0).
"""

from __future__ import annotations

import numpy as np

from scenariomax.codec import SchemaError, decode_scenario
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.io.example import Example, ExampleError
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.womd.convert import SOURCE_NAME, ScenarioBuildError
from scenariomax.sources.womd.windows import wrap_angle

FORMAT_SCENARIO, FORMAT_TF_EXAMPLE, FORMAT_AUTO = "scenario", "tf_example", "auto"
_POINT_FIELDS = ("roadgraph_xyz", "roadgraph_dir", "roadgraph_type", "roadgraph_id", "roadgraph_valid",
                 "roadgraph_speed_limit")


def looks_like_tf_example(data: bytes) -> bool:
    """True when the record parses as a tf.Example holding WOMD state features. (A Scenario proto
    never does: its field 1 is packed doubles, not a Features map with a `state/id` key.)"""
    example = Example()
    try:
        example.ParseFromString(data)
    except Exception:  # noqa: BLE001 - any parse failure means "not a tf.Example"
        return False
    return "state/id" in example.features.feature


def tf_example_to_scenario(data: bytes, sizes: Sizes) -> Scenario:
    try:
        scenario = decode_scenario(data)
    except (SchemaError, ExampleError, ValueError) as error:
        raise ScenarioBuildError(f"bad WOMD tf.Example ({error})") from None
    if scenario.num_timesteps != sizes.num_timesteps:
        raise ScenarioBuildError(f"tf.Example has {scenario.num_timesteps} steps, expected {sizes.num_timesteps}")
    if int(scenario.is_sdc.sum()) != 1:
        raise ScenarioBuildError(f"tf.Example marks {int(scenario.is_sdc.sum())} SDCs, expected 1")
    keep = np.flatnonzero(scenario.roadgraph_valid)
    if keep.size and keep.size == scenario.roadgraph_valid.size:
        # WOMD cut this map to the tf.Example's capacity: lanes (junction connectors first) may be missing, and the
        # metrics judge the SDC against the lanes left. The Scenario protos hold the whole map.
        notes = {"tf_example_roadgraph_full_points": int(keep.size)}
        scenario = scenario.replace(metadata={**scenario.metadata, MANIFEST_NOTES: notes})
    changes = {name: getattr(scenario, name)[keep] for name in _POINT_FIELDS}
    changes["bbox_yaw"] = np.where(scenario.valid, wrap_angle(scenario.bbox_yaw), -1.0).astype(np.float32)
    changes["vel_yaw"] = np.where(scenario.valid, wrap_angle(scenario.vel_yaw), -1.0).astype(np.float32)
    scenario = scenario.replace(source_dataset=SOURCE_NAME, current_time_index=sizes.num_past, **changes)
    return fit_to_budget(scenario, sizes)
