"""GPUDrive / Nocturne JSON scenarios (WOMD converted by GPUDrive's or Nocturne's scripts), every layout."""

from scenariomax.sources.gpudrive.convert import SOURCE_NAME, clean_tracks, log_window_starts, scenario_windows
from scenariomax.sources.gpudrive.layout import (
    LAYOUT_GPUDRIVE_3D,
    LAYOUT_GPUDRIVE_METADATA,
    LAYOUT_NOCTURNE,
    RawScenario,
    headings_in_degrees,
    layout_of,
    parse_document,
    read_json,
)
from scenariomax.sources.gpudrive.roads import light_state_code, map_polylines, road_type
from scenariomax.sources.gpudrive.source import GpuDriveSource
from scenariomax.sources.gpudrive.tracks import (
    ScenarioError,
    box_dimensions,
    choose_sdc,
    consistent_velocity,
    fix_yaw_flips,
)

__all__ = [
    "LAYOUT_GPUDRIVE_3D",
    "LAYOUT_GPUDRIVE_METADATA",
    "LAYOUT_NOCTURNE",
    "SOURCE_NAME",
    "GpuDriveSource",
    "RawScenario",
    "ScenarioError",
    "box_dimensions",
    "choose_sdc",
    "clean_tracks",
    "consistent_velocity",
    "fix_yaw_flips",
    "headings_in_degrees",
    "layout_of",
    "light_state_code",
    "log_window_starts",
    "map_polylines",
    "parse_document",
    "read_json",
    "road_type",
    "scenario_windows",
]
