"""Immutable pytree dataclasses (arrays only) that the simulator passes around."""

from vmax_sim.datatypes.action import Action, sdc_action
from vmax_sim.datatypes.object_metadata import ObjectMetadata
from vmax_sim.datatypes.paths import Paths
from vmax_sim.datatypes.roadgraph import RoadgraphPoints
from vmax_sim.datatypes.simulator_state import SimulatorState
from vmax_sim.datatypes.traffic_lights import TrafficLights
from vmax_sim.datatypes.trajectory import (
    STEP_MICROS,
    TRAJECTORY_FIELDS,
    Trajectory,
    fill_invalid,
    select_timestep,
    stack_fields,
    update_timestep,
)

__all__ = [
    "STEP_MICROS",
    "TRAJECTORY_FIELDS",
    "Action",
    "ObjectMetadata",
    "Paths",
    "RoadgraphPoints",
    "SimulatorState",
    "TrafficLights",
    "Trajectory",
    "fill_invalid",
    "sdc_action",
    "select_timestep",
    "stack_fields",
    "update_timestep",
]
