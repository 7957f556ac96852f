"""nuPlan: log SQLite databases + GeoPackage city maps -> Scenarios (no devkit, no GDAL)."""

from scenariomax.sources.nuplan.map_reader import find_map_file, load_city_map
from scenariomax.sources.nuplan.source import NuplanSource, expand_db_paths

__all__ = ["NuplanSource", "expand_db_paths", "find_map_file", "load_city_map"]
