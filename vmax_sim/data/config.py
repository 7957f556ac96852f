"""`DataConfig`: how shards become fixed-size simulator batches."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any


def cache_dir() -> Path:
    """Root of vmax_sim's caches (synthetic shards, map indices): $VMAX_CACHE_DIR, default ~/.cache/vmax_sim."""
    return Path(os.environ.get("VMAX_CACHE_DIR", Path.home() / ".cache" / "vmax_sim"))


HIDE_LIGHTS_FROM = ("all", "student")  # DataConfig.hide_lights_from


@dataclasses.dataclass(frozen=True)
class DataConfig:
    path: str = ""  # shard directory, file or glob
    batch_size: int = 1
    num_objects: int = 64  # first slots of the record (the SDC is slot 0 in our shards)
    num_roadgraph_points: int = 30000  # valid points nearest the SDC trajectory, then padding
    num_paths: int = 10
    num_points_per_path: int = 300
    max_num_lights: int = 16
    shuffle_seed: int | None = None  # None keeps file order (deterministic evaluation)
    shuffle_buffer: int = 256  # scenarios held for shuffling
    repeat: bool = False  # loop over the data forever (reshuffled each pass)
    prefetch: int = 2  # batches prepared ahead by a background thread
    num_workers: int = 0  # processes converting scenarios (map-index building is ~0.5 s each); 0: in the thread
    drop_remainder: bool = True  # a final short batch would change shapes (and recompile)
    include_map_index: bool = True  # build vmax_sim.map_index structures on the host
    # per-slot routes of the controllable agents (SimulatorState.agent_paths), for reactive evaluation
    include_agent_paths: bool = False
    num_points_per_agent_path: int = 200  # 1 m apart: longer shard paths are cut, shorter padded
    map_index_config: Any = None  # passed to vmax_sim.map_index.build_map_index (None: its default)
    # reuse map indices built before, kept per shard under $VMAX_CACHE_DIR/map_index (vmax_sim.data.map_index_cache;
    # the environment variable VMAX_MAP_INDEX_CACHE=0 also turns it off)
    map_index_cache: bool = True
    map_index_cache_max_gb: float = 32.0  # bound of that folder (an entry: the index's bytes x scenarios)
    # share of the scenarios read as if recorded without traffic-light states (nuScenes and AV2 have none, and 9 of
    # the 10 GPUDrive JSON scenes here). A fixed draw per scenario id (vmax_sim.data.convert.lights_hidden).
    # Training sets it (`data.hide_lights`)
    hide_lights: float = 0.0
    # from whom: "all" (no light reaches the observation, the planners or the metrics: an unlit recording) or
    # "student" (only the learner's observation loses them, SimulatorState.lights_hidden; its teacher, the traffic and
    # the metrics still read the signal, as the recorded driver of an unlit recording saw it)
    hide_lights_from: str = "all"

    def __post_init__(self) -> None:
        for name in ("batch_size", "num_objects", "num_roadgraph_points", "num_paths", "num_points_per_path",
                     "max_num_lights", "num_points_per_agent_path"):
            if getattr(self, name) < 1:
                raise ValueError(f"DataConfig.{name} must be at least 1, got {getattr(self, name)}")
        if self.prefetch < 0 or self.shuffle_buffer < 0 or self.num_workers < 0:
            raise ValueError("DataConfig.prefetch, shuffle_buffer and num_workers must not be negative")
        if not 0.0 <= self.hide_lights <= 1.0:
            raise ValueError(f"DataConfig.hide_lights must be in [0, 1], got {self.hide_lights}")
        if self.hide_lights_from not in HIDE_LIGHTS_FROM:
            raise ValueError(f"DataConfig.hide_lights_from must be one of {HIDE_LIGHTS_FROM}, "
                             f"got {self.hide_lights_from!r}")
        if not self.map_index_cache_max_gb > 0:
            raise ValueError(f"DataConfig.map_index_cache_max_gb must be positive, got {self.map_index_cache_max_gb}")
