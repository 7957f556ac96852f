"""Argoverse 2 motion forecasting: `scenario_<id>.parquet` + `log_map_archive_<id>.json` -> Scenarios."""

from scenariomax.sources.av2.convert import build_scenario
from scenariomax.sources.av2.map import Av2Map, parse_map
from scenariomax.sources.av2.source import Av2Source, list_av2_units
from scenariomax.sources.av2.tracks import DEFAULT_BOX_SIZES, OBJECT_TYPES, RawTracks

__all__ = [
           "DEFAULT_BOX_SIZES",
           "OBJECT_TYPES",
           "Av2Map",
           "Av2Source",
           "RawTracks",
           "build_scenario",
           "list_av2_units",
           "parse_map",
]
