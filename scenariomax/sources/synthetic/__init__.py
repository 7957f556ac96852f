"""Procedurally generated driving scenarios: `scenariomax convert --dataset synthetic`.

Road networks are built from blocks (straight streets, bends, 3- and 4-way junctions with signal
phases or stop signs, on-ramp merges, lane drops, roundabouts); traffic is simulated on them (IDM car
following, junction reservations, signals, stop signs, pedestrians on crosswalks, cyclists,
parked cars). Everything is deterministic in (seed, index); `SyntheticKnobs` randomise the scenes
(traffic density, tracking noise, lane widths, speed limits, driver styles, parked cars, topology mix).
"""

from scenariomax.sources.synthetic.checks import (
                                                  lane_graph_distance,
                                                  overlapping_vehicle_pairs,
                                                  red_light_crossings,
                                                  road_edge_signed_distance,
)
from scenariomax.sources.synthetic.generator import GenerationError, generate_scenario, scenario_id
from scenariomax.sources.synthetic.knobs import SyntheticKnobs
from scenariomax.sources.synthetic.network import Crosswalk, Lane, RoadNetwork
from scenariomax.sources.synthetic.source import SyntheticSource
from scenariomax.sources.synthetic.topologies import TOPOLOGIES, build_network
from scenariomax.sources.synthetic.traffic import Traffic, simulate

__all__ = [
                                                  "TOPOLOGIES",
                                                  "Crosswalk",
                                                  "GenerationError",
                                                  "Lane",
                                                  "RoadNetwork",
                                                  "SyntheticKnobs",
                                                  "SyntheticSource",
                                                  "Traffic",
                                                  "build_network",
                                                  "generate_scenario",
                                                  "lane_graph_distance",
                                                  "overlapping_vehicle_pairs",
                                                  "red_light_crossings",
                                                  "road_edge_signed_distance",
                                                  "scenario_id",
                                                  "simulate",
]
