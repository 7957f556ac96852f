"""`enrich_scenario`: every enrichment step, in order, behind one frozen settings object.

Order: ids -> road-edge orientation -> directions -> speed limits -> lane graph -> SDC paths ->
controllable labels and agent paths -> traffic-light inference. Each step is pure; the input
scenario is never modified.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.enrich.controllable import ControllableSettings, agent_paths, controllable_mask
from scenariomax.enrich.directions import with_recomputed_directions
from scenariomax.enrich.ids import with_missing_ids_assigned
from scenariomax.enrich.lane_graph import LaneGraphSettings, lane_graph_to_arrays, scenario_lane_graph
from scenariomax.enrich.lanes import extract_lanes
from scenariomax.enrich.orientation import with_edges_oriented
from scenariomax.enrich.paths import PATHS_SOURCE, PathSettings, logged_track, paths_to_arrays, search_paths
from scenariomax.enrich.speed_limits import with_speed_limits
from scenariomax.enrich.traffic_lights import LightSettings, with_inferred_lights
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES


@dataclasses.dataclass(frozen=True)
class EnrichSettings:
    resample_spacing: float = 1.0  # metres between path points (SDC and agent paths)
    fix_edge_orientation: bool = True
    recompute_directions: bool = True
    fill_speed_limits: bool = True
    rebuild_lane_graph: bool = True  # when the source has no explicit lane links
    num_paths: int = 10
    points_per_path: int = 300
    build_paths: bool = True
    label_controllable: bool = True
    build_agent_paths: bool = True
    num_agent_paths: int = 16
    num_lane_links: int = 8
    infer_lights: bool = True
    paths: PathSettings = PathSettings()  # search knobs; num/points/spacing above take precedence
    lane_graph: LaneGraphSettings = LaneGraphSettings()
    controllable: ControllableSettings = ControllableSettings()
    lights: LightSettings = LightSettings()

    def path_settings(self) -> PathSettings:
        return dataclasses.replace(self.paths, num_paths=self.num_paths, points_per_path=self.points_per_path,
                                   spacing_m=self.resample_spacing)


def _sdc_paths(scenario: Scenario, lanes, graph, settings: EnrichSettings) -> dict:
    sdc, start = scenario.sdc_index, scenario.current_time_index
    track, track_yaw = logged_track(scenario.x[sdc], scenario.y[sdc], scenario.bbox_yaw[sdc], scenario.valid[sdc],
                                    start)
    position = np.array([scenario.x[sdc, start], scenario.y[sdc, start], scenario.z[sdc, start]])
    paths = search_paths(lanes, graph, position, float(scenario.bbox_yaw[sdc, start]), track, track_yaw,
                         settings.path_settings())
    # No lane near the SDC's start, heading aligned (e.g. it starts off the mapped roads): the scenario still
    # simulates, without an on-route path; `enrich_scenario` notes it for the manifest instead of failing it.
    return paths_to_arrays(paths, settings.num_paths, settings.points_per_path)


def with_note(metadata: dict, key: str, value) -> dict:
    """`metadata` with one more manifest note (see scenariomax.sources.base.MANIFEST_NOTES)."""
    return {**metadata, MANIFEST_NOTES: {**(metadata.get(MANIFEST_NOTES) or {}), key: value}}


def enrich_scenario(scenario: Scenario, settings: EnrichSettings = EnrichSettings()) -> Scenario:
    """The scenario with roadgraph fixes, lane graph, SDC paths, controllable labels, agent paths and
    inferred lights. Raises ValueError (one line) when nothing can be simulated (empty roadgraph, no SDC
    at the current step); no lane near the SDC start leaves the paths empty, noted under MANIFEST_NOTES."""
    if scenario.roadgraph_xyz.shape[0] == 0:
        raise ValueError(f"scenario {scenario.scenario_id}: empty roadgraph")
    sdc = scenario.sdc_index  # raises ValueError when there is not exactly one SDC
    if not scenario.valid[sdc, scenario.current_time_index]:
        raise ValueError(f"scenario {scenario.scenario_id}: the SDC is not valid at the current step")
    scenario = with_missing_ids_assigned(scenario)
    lanes = extract_lanes(scenario)
    if settings.fix_edge_orientation:
        scenario = with_edges_oriented(scenario, lanes)
    if settings.recompute_directions or settings.fix_edge_orientation:
        scenario = with_recomputed_directions(scenario)
    if settings.fill_speed_limits:
        scenario = with_speed_limits(scenario)
    graph, rebuilt = scenario_lane_graph(scenario, lanes, settings.lane_graph)
    changes: dict = {}
    if rebuilt and settings.rebuild_lane_graph:
        changes.update(lane_graph_to_arrays(lanes, graph, settings.num_lane_links))
    if settings.build_paths and not scenario.metadata.get(PATHS_SOURCE):  # a source's own paths are kept
        changes.update(_sdc_paths(scenario, lanes, graph, settings))
        if not changes["path_valid"].any():
            changes["metadata"] = with_note(scenario.metadata, "no_sdc_path",
                                            f"no lane within {settings.paths.fallback_start_radius_m:g} m of the "
                                            f"SDC start, heading aligned")
    if settings.label_controllable:
        controllable = controllable_mask(scenario, lanes, settings.controllable)
        changes["is_controllable"] = controllable
        if settings.build_agent_paths:
            changes.update(agent_paths(scenario, lanes, graph, controllable, settings.num_agent_paths,
                                       settings.path_settings()))
    scenario = scenario.replace(**changes)
    if settings.infer_lights:
        scenario = with_inferred_lights(scenario, lanes, settings.lights)
    return scenario
