"""`SimulatorState`: everything the simulator carries for one scenario (or a batch of them)."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from vmax_sim.datatypes.object_metadata import ObjectMetadata
from vmax_sim.datatypes.paths import Paths
from vmax_sim.datatypes.roadgraph import RoadgraphPoints
from vmax_sim.datatypes.traffic_lights import TrafficLights
from vmax_sim.datatypes.trajectory import Trajectory, select_timestep


@struct.dataclass
class SimulatorState:
    log_trajectory: Trajectory  # (..., num_objects, num_timesteps), the recorded log
    sim_trajectory: Trajectory  # (..., num_objects, num_timesteps), simulated so far (valid up to timestep)
    object_metadata: ObjectMetadata  # (..., num_objects)
    roadgraph_points: RoadgraphPoints  # (..., num_points)
    log_traffic_light: TrafficLights  # (..., num_lights, num_timesteps)
    sdc_paths: Paths  # (..., num_paths, num_points_per_path)
    map_index: Any  # vmax_sim.map_index.MapIndex with leading (...) dims, or None when not built
    timestep: jax.Array  # (...) int32, index of the current step in [0, num_timesteps)
    # Paths (..., num_objects, num_points_per_agent_path): a route per object slot for the agents that
    # reactive evaluation drives (see DataConfig.include_agent_paths), None when not loaded.
    agent_paths: Any = None
    # Trajectory (..., num_objects, 1): the simulated state at `timestep`, kept by `Environment.reset` and
    # `step` so that a step reads it here instead of slicing every (N, T) field, a read that touches one
    # cache line per object row (the trajectories are time-minor); the step and its metrics made two such
    # reads, ~13% of the full step's time at batch 128. None: sliced on demand (states from the loader).
    current_sim: Any = None
    # (...) bool: the learner's observation shows none of this scenario's lights, which its teacher, the traffic and
    # the metrics still read (DataConfig.hide_lights_from="student"). None: shown
    lights_hidden: Any = None

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(self.timestep.shape)

    @property
    def num_objects(self) -> int:
        return self.log_trajectory.num_objects

    @property
    def num_timesteps(self) -> int:
        return self.log_trajectory.num_timesteps

    @property
    def current_sim_trajectory(self) -> Trajectory:
        """Simulated state at the current step. (..., num_objects, 1)"""
        if self.current_sim is not None:
            return self.current_sim
        return select_timestep(self.sim_trajectory, self.timestep)

    @property
    def current_log_trajectory(self) -> Trajectory:
        """Logged state at the current step. (..., num_objects, 1)"""
        return select_timestep(self.log_trajectory, self.timestep, written=False)

    @property
    def next_log_trajectory(self) -> Trajectory:
        """Logged state one step ahead (clamped at the last step). (..., num_objects, 1)"""
        last = self.num_timesteps - 1
        return select_timestep(self.log_trajectory, jnp.minimum(self.timestep + 1, last), written=False)

    @property
    def current_traffic_lights(self) -> TrafficLights:
        """Logged traffic lights at the current step. (..., num_lights, 1)"""
        return select_timestep(self.log_traffic_light, self.timestep)

    @property
    def remaining_timesteps(self) -> jax.Array:
        """Steps left in the log. (...) int32"""
        return jnp.maximum(self.num_timesteps - 1 - self.timestep, 0)

    @property
    def is_done(self) -> jax.Array:
        """The log has no further step. (...) bool"""
        return self.timestep >= self.num_timesteps - 1


def _replace_keeping_current(self: SimulatorState, **updates) -> SimulatorState:
    """`replace` that keeps `current_sim` true: a new trajectory or timestep given without a new
    `current_sim` re-reads it, so a cached step can never be stale."""
    new = dataclasses.replace(self, **updates)
    moved = "sim_trajectory" in updates or "timestep" in updates
    if self.current_sim is not None and moved and "current_sim" not in updates:
        new = dataclasses.replace(new, current_sim=select_timestep(new.sim_trajectory, new.timestep))
    return new


SimulatorState.replace = _replace_keeping_current  # flax's decorator installs a plain dataclasses.replace
