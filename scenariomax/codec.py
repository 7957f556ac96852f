"""Scenario <-> tf.Example features, driven by the schema.

`encode_scenario` pads every field to the budget in `Sizes` (and refuses data over budget);
`decode_scenario` infers sizes from the record itself, so raw WOMD tf.Example files (no paths,
no V-Max extras) decode too, with the missing parts empty.
"""

from __future__ import annotations

import numpy as np

from scenariomax.io.example import ExampleError, decode_example, encode_example
from scenariomax.io.record_kind import WOMD_SCENARIO_NOT_A_SHARD, looks_like_womd_scenario
from scenariomax.scenario import Scenario
from scenariomax.schema import FeatureSpec, Sizes, default_sizes, load_schema

_TIME_DIM = {"past": "num_past", "current": "num_current", "future": "num_future"}


class BudgetError(ValueError):
    """A scenario holds more objects/points/lights than the shard budget allows."""


class SchemaError(ValueError):
    """A record does not match the shard schema."""


def _time_slice(time: str, sizes: Sizes) -> slice:
    start = {"past": 0, "current": sizes.num_past, "future": sizes.num_past + sizes.num_current}[time]
    return slice(start, start + getattr(sizes, _TIME_DIM[time]))


def _pad_to(array: np.ndarray, shape: tuple[int, ...], pad, key: str) -> np.ndarray:
    if array.shape == shape:
        return array
    if array.ndim != len(shape):
        raise SchemaError(f"{key}: array has {array.ndim} dims, schema expects {len(shape)}")
    if any(have > want for have, want in zip(array.shape, shape)):
        # Slots past the budget that hold only padding may be dropped; real data may not.
        kept = tuple(slice(0, min(have, want)) for have, want in zip(array.shape, shape))
        excess = np.ones(array.shape, bool)
        excess[kept] = False
        if np.any(array[excess] != pad):
            raise BudgetError(f"{key}: shape {array.shape} exceeds the budget {shape}")
        array = array[kept]
    out = np.full(shape, pad, dtype=array.dtype)
    out[tuple(slice(0, n) for n in array.shape)] = array
    return out


def _field_value(scenario: Scenario, spec: FeatureSpec, sizes: Sizes, dims: dict[str, int]):
    value = getattr(scenario, spec.field)
    if spec.dtype == "bytes":
        return [value.encode()]
    array = np.asarray(value)
    if spec.time is not None:
        t_slice = _time_slice(spec.time, sizes)
        if spec.field == "tl_timestamp_micros":
            array = array[t_slice]
        else:
            array = array[:, t_slice]
            if spec.layout == "time_major":  # (L, t) -> (t, L)
                array = array.T
    if spec.field == "path_on_route":
        array = array[:, None]
    shape = spec.resolved_shape(dims)
    return _pad_to(array.astype(spec.numpy_dtype), shape, spec.pad, spec.key)


def scenario_to_features(scenario: Scenario, sizes: Sizes | None = None) -> dict:
    sizes = sizes or default_sizes()
    if scenario.num_timesteps != sizes.num_timesteps:
        raise SchemaError(f"scenario {scenario.scenario_id} has {scenario.num_timesteps} steps, "
                          f"the schema wants {sizes.num_timesteps}")
    dims = sizes.as_dict()  # once: it copies the dataclass
    return {spec.key: _field_value(scenario, spec, sizes, dims) for spec in load_schema().features}


def encode_scenario(scenario: Scenario, sizes: Sizes | None = None) -> bytes:
    """Serialises a Scenario to tf.Example bytes (deterministic)."""
    return encode_example(scenario_to_features(scenario, sizes))


def infer_sizes(features: dict) -> Sizes:
    """Reads the budget sizes from the element counts of a record."""

    def count(key: str, default: int = 0) -> int:
        value = features.get(key)
        return default if value is None else len(value)

    num_objects = count("state/id")
    if num_objects == 0:
        raise SchemaError("record has no state/id feature")
    num_paths = count("path_samples/on_route")
    num_lanes = count("vmax/lane/id")
    num_agent_paths = count("vmax/agent_paths/object_index")
    return Sizes(
        num_objects=num_objects,
        num_past=count("state/past/x") // num_objects,
        num_current=count("state/current/x") // num_objects,
        num_future=count("state/future/x") // num_objects,
        num_roadgraph=count("roadgraph_samples/valid"),
        num_lights=count("traffic_light_state/current/state"),
        num_paths=num_paths,
        num_points_per_path=count("path_samples/valid") // num_paths if num_paths else 0,
        num_lanes=num_lanes,
        num_lane_links=count("vmax/lane/successors") // num_lanes if num_lanes else 0,
        num_agent_paths=num_agent_paths,
    )


def _required_keys() -> list[str]:
    # Keys every WOMD motion tf.Example has; the rest may be absent (filled empty).
    return [spec.key for spec in load_schema().features
            if spec.group == "waymax" and not spec.key.startswith("path_samples/")
            and spec.key != "state/difficulty_level"]


def features_to_scenario(features: dict, sizes: Sizes | None = None) -> Scenario:
    """Builds a Scenario from decoded features; raises SchemaError on missing keys or bad sizes."""
    missing = [key for key in _required_keys() if key not in features]
    if missing:
        raise SchemaError(f"missing feature {missing[0]}"
                          + (f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""))
    sizes = sizes or infer_sizes(features)
    dims = sizes.as_dict()
    num_timesteps = sizes.num_timesteps
    fields: dict[str, np.ndarray | str] = {}
    for spec in load_schema().features:
        shape = spec.resolved_shape(dims)
        value = features.get(spec.key)
        if spec.dtype == "bytes":
            fields[spec.field] = value[0].decode("utf-8", "replace") if value else ""
            continue
        if value is None:
            value = np.full(shape, spec.pad, dtype=spec.numpy_dtype)
        value = np.asarray(value)
        expected = int(np.prod(shape, dtype=np.int64))
        if value.size != expected:
            raise SchemaError(f"{spec.key} has {value.size} values, expected {expected} for shape {shape}")
        value = value.reshape(shape)
        if spec.field == "path_on_route":
            value = value[:, 0]
        if spec.time is None:
            fields[spec.field] = value
            continue
        if spec.layout == "time_major":
            value = value.T
        if spec.field not in fields:
            if spec.field == "tl_timestamp_micros":
                fields[spec.field] = np.empty((num_timesteps,), dtype=value.dtype)
            else:
                fields[spec.field] = np.empty((value.shape[0], num_timesteps), dtype=value.dtype)
        target = fields[spec.field]
        target[..., _time_slice(spec.time, sizes)] = value
    fields["object_id"] = fields["object_id"].astype(np.int64)
    fields["object_type"] = fields["object_type"].astype(np.int64)
    return Scenario(current_time_index=sizes.num_past, **fields)


def decode_scenario(data: bytes, sizes: Sizes | None = None) -> Scenario:
    # A raw WOMD Scenario proto is not a tf.Example: say what the file is, not "missing 71 features".
    try:
        features = decode_example(data)
    except ExampleError:
        if looks_like_womd_scenario(data):
            raise SchemaError(WOMD_SCENARIO_NOT_A_SHARD) from None
        raise
    if not features and looks_like_womd_scenario(data):
        raise SchemaError(WOMD_SCENARIO_NOT_A_SHARD)
    return features_to_scenario(features, sizes)
