"""The shard schema, loaded from `schemas/shard_schema.v1.json`.

The JSON file is the single source of truth: the writer, reader, validator and `docs/schema.md`
are all derived from it. Dimensions are named (e.g. ``num_objects``) so sizes are settings.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Mapping
from importlib import resources
from pathlib import Path

import numpy as np

SCHEMA_FILE = "shard_schema.v1.json"

_NUMPY_DTYPES = {"float": np.float32, "int64": np.int64, "bytes": np.object_}


@dataclasses.dataclass(frozen=True)
class FeatureSpec:
    """One tf.Example feature: its key, dtype, named shape and padding value."""

    key: str
    dtype: str  # "float" | "int64" | "bytes"
    shape: tuple  # named dims (str) or literal ints
    pad: object
    field: str  # Scenario attribute this feature fills
    group: str  # "waymax" (a key Waymax reads) or "vmax" (our extra)
    meaning: str
    time: str | None = None  # "past" | "current" | "future" for time-split features
    layout: str | None = None  # "time_major" when the record stores [time, slot]

    def resolved_shape(self, sizes: Mapping[str, int]) -> tuple[int, ...]:
        return tuple(sizes[d] if isinstance(d, str) else int(d) for d in self.shape)

    def num_elements(self, sizes: Mapping[str, int]) -> int:
        return int(np.prod(self.resolved_shape(sizes), dtype=np.int64))

    @property
    def numpy_dtype(self):
        return _NUMPY_DTYPES[self.dtype]


@dataclasses.dataclass(frozen=True)
class ShardSchema:
    name: str
    version: str
    description: str
    dims: Mapping[str, int]  # default size of each named dim
    dim_meanings: Mapping[str, str]
    enums: Mapping[str, Mapping[int, str]]
    features: tuple[FeatureSpec, ...]

    def feature(self, key: str) -> FeatureSpec:
        for spec in self.features:
            if spec.key == key:
                return spec
        raise KeyError(key)

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(spec.key for spec in self.features)


def _schema_text() -> str:
    # A wheel carries the schema in scenariomax/_schemas/ (setup.py maps the package `scenariomax._schemas` onto
    # `schemas/`); a checkout or an editable install reads `schemas/` at the repo root. The packaged copy goes
    # first so that an installed scenariomax never picks up an unrelated `schemas/` folder beside it.
    packaged = resources.files("scenariomax") / "_schemas" / SCHEMA_FILE
    if packaged.is_file():
        return packaged.read_text()
    in_repo = Path(__file__).resolve().parent.parent / "schemas" / SCHEMA_FILE
    if in_repo.is_file():
        return in_repo.read_text()
    raise FileNotFoundError(f"{SCHEMA_FILE}: the shard schema is neither in scenariomax/_schemas (an installed "
                            f"wheel) nor in {in_repo.parent} (a checkout); reinstall vmax")


@functools.lru_cache(maxsize=1)
def load_schema() -> ShardSchema:
    raw = json.loads(_schema_text())
    features = tuple(
        FeatureSpec(
            key=f["key"], dtype=f["dtype"], shape=tuple(f["shape"]), pad=f["pad"], field=f["field"],
            group=f["group"], meaning=f["meaning"], time=f.get("time"), layout=f.get("layout"),
        )
        for f in raw["features"]
    )
    return ShardSchema(
        name=raw["name"],
        version=raw["version"],
        description=raw["description"],
        dims={k: int(v["default"]) for k, v in raw["dims"].items()},
        dim_meanings={k: v["meaning"] for k, v in raw["dims"].items()},
        enums={name: {int(k): v for k, v in values.items()} for name, values in raw["enums"].items()},
        features=features,
    )


@dataclasses.dataclass(frozen=True)
class Sizes:
    """Budget sizes for one shard set. Defaults come from the schema; any may be overridden."""

    num_objects: int = 128
    num_past: int = 10
    num_current: int = 1
    num_future: int = 80
    num_roadgraph: int = 30000
    num_lights: int = 16
    num_paths: int = 10
    num_points_per_path: int = 300
    num_lanes: int = 1024
    num_lane_links: int = 8
    num_agent_paths: int = 16

    @property
    def num_timesteps(self) -> int:
        return self.num_past + self.num_current + self.num_future

    @property
    def current_time_index(self) -> int:
        return self.num_past

    def as_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: Mapping[str, int]) -> Sizes:
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: int(v) for k, v in values.items() if k in known})


def default_sizes() -> Sizes:
    return Sizes.from_dict(load_schema().dims)


# Enum values used across the code base (facts of the WOMD format).
OBJECT_TYPE_VEHICLE, OBJECT_TYPE_PEDESTRIAN, OBJECT_TYPE_CYCLIST, OBJECT_TYPE_OTHER = 1, 2, 3, 4
RG_LANE_FREEWAY, RG_LANE_SURFACE_STREET, RG_LANE_BIKE = 1, 2, 3
RG_BROKEN_SINGLE_WHITE, RG_SOLID_SINGLE_WHITE, RG_SOLID_DOUBLE_WHITE = 6, 7, 8
RG_BROKEN_SINGLE_YELLOW, RG_BROKEN_DOUBLE_YELLOW = 9, 10
RG_SOLID_SINGLE_YELLOW, RG_SOLID_DOUBLE_YELLOW, RG_PASSING_DOUBLE_YELLOW = 11, 12, 13
RG_ROAD_EDGE_BOUNDARY, RG_ROAD_EDGE_MEDIAN = 15, 16
RG_STOP_SIGN, RG_CROSSWALK, RG_SPEED_BUMP, RG_DRIVEWAY = 17, 18, 19, 20
LANE_TYPES = (RG_LANE_FREEWAY, RG_LANE_SURFACE_STREET, RG_LANE_BIKE)
ROAD_LINE_TYPES = tuple(range(6, 14))
ROAD_EDGE_TYPES = (RG_ROAD_EDGE_BOUNDARY, RG_ROAD_EDGE_MEDIAN)
TL_UNKNOWN, TL_ARROW_STOP, TL_ARROW_CAUTION, TL_ARROW_GO = 0, 1, 2, 3
TL_STOP, TL_CAUTION, TL_GO, TL_FLASHING_STOP, TL_FLASHING_CAUTION = 4, 5, 6, 7, 8
