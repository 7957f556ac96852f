"""nuPlan city maps (GeoPackage): find the file for a log's map_version and load the vector layers
the converter needs, restricted to a region (the map is city-sized, a log covers a few km)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import shapely

from scenariomax.errors import InputError
from scenariomax.sources.nuplan import utm
from scenariomax.sources.nuplan.geopackage import read_layer
from scenariomax.sources.nuplan.sqlite_access import fetch_all, open_readonly, table_columns

MAPS_INDEX_FILE = "nuplan-maps-v1.0.json"
# Map folder versions and UTM zones of the four nuPlan cities (fallbacks when the files do not say).
KNOWN_MAP_VERSIONS = {
    "us-nv-las-vegas-strip": "9.15.1915",
    "us-pa-pittsburgh-hazelwood": "9.17.1937",
    "us-ma-boston": "9.12.1817",
    "sg-one-north": "9.17.1964",
}
KNOWN_UTM_EPSG = {
    "us-nv-las-vegas-strip": 32611,
    "us-pa-pittsburgh-hazelwood": 32617,
    "us-ma-boston": 32619,
    "sg-one-north": 32648,
}
DRIVABLE_LAYERS = ("road_segments", "intersections", "generic_drivable_areas", "carpark_areas")
REQUIRED_LAYERS = ("lanes_polygons", "lane_connectors", "baseline_paths", "boundaries", "crosswalks",
                   "stop_polygons") + DRIVABLE_LAYERS


@dataclasses.dataclass(frozen=True)
class FeatureTable:
    """Map features of one kind with their attributes."""

    fid: np.ndarray  # (F,) int64, GeoPackage fid
    geometry: np.ndarray  # (F,) object, shapely geometries in UTM metres
    bounds: np.ndarray  # (F, 4) float64, minx, miny, maxx, maxy
    attributes: dict  # name -> (F,) array

    @staticmethod
    def build(fid, geometry, attributes=None) -> FeatureTable:
        geometry = np.asarray(geometry, dtype=object).reshape(-1)
        bounds = shapely.bounds(geometry).reshape(-1, 4) if len(geometry) else np.zeros((0, 4))
        return FeatureTable(np.asarray(fid, np.int64).reshape(-1), geometry, bounds, dict(attributes or {}))

    def __len__(self) -> int:
        return len(self.fid)

    def take(self, index: np.ndarray) -> FeatureTable:
        return FeatureTable(self.fid[index], self.geometry[index], self.bounds[index],
                            {k: v[index] for k, v in self.attributes.items()})

    def within_box(self, box: tuple[float, float, float, float]) -> FeatureTable:
        """Features whose bounding box overlaps (minx, miny, maxx, maxy)."""
        minx, miny, maxx, maxy = box
        b = self.bounds
        hit = (b[:, 0] <= maxx) & (b[:, 2] >= minx) & (b[:, 1] <= maxy) & (b[:, 3] >= miny)
        return self.take(np.flatnonzero(hit & np.isfinite(b).all(axis=1)))


@dataclasses.dataclass(frozen=True)
class CityMap:
    path: str
    lanes: FeatureTable  # centrelines; attrs lane_group, lane_index, speed_limit, lane_type
    connectors: FeatureTable  # centrelines; attrs upstream_lane, downstream_lane, speed_limit
    boundaries: FeatureTable  # lines; attr boundary_type
    crosswalks: FeatureTable  # polygons
    stop_polygons: FeatureTable  # polygons; attr stop_type
    drivable: FeatureTable  # polygons of the drivable area


def find_map_file(maps_root: str, map_version: str) -> Path:
    """`<maps_root>/<location>/<version>/map.gpkg` for a log's map_version (a '.gpkg' suffix is dropped)."""
    location = str(map_version).replace(".gpkg", "").strip()
    root = Path(maps_root)
    version = _version_from_index(root, location) or KNOWN_MAP_VERSIONS.get(location)
    if version and (root / location / version / "map.gpkg").is_file():
        return root / location / version / "map.gpkg"
    candidates = sorted((root / location).glob("*/map.gpkg")) if location else []
    if len(candidates) == 1 and version is None:
        return candidates[0]
    expected = root / location / (version or "<version>") / "map.gpkg"
    raise InputError(f"{expected}: map file for map_version '{map_version}' is missing")


def _version_from_index(root: Path, location: str) -> str | None:
    index = root / MAPS_INDEX_FILE
    if not index.is_file():
        return None
    try:
        entry = json.loads(index.read_text()).get(location, {})
        return str(entry["version"]) if isinstance(entry, dict) and "version" in entry else None
    except (ValueError, OSError, AttributeError) as exc:
        raise InputError(f"{index}: unreadable maps index ({exc})") from None


def map_utm_epsg(conn, path: str, location: str) -> int:
    """The projected CRS the log uses: meta.projectedCoordSystem, else the known code of the city."""
    columns = table_columns(conn, path, "meta")
    if columns is not None and {"key", "value"} <= columns:
        for key, value in fetch_all(conn, path, "SELECT key, value FROM meta"):
            if str(key) == "projectedCoordSystem":
                epsg = utm.parse_epsg(value)
                if epsg is not None and utm.utm_epsg_zone(epsg) is not None:
                    return epsg
    epsg = KNOWN_UTM_EPSG.get(location.replace(".gpkg", ""))
    if epsg is None:
        raise InputError(f"{path}: no projectedCoordSystem in table 'meta' and unknown location '{location}'")
    return epsg


def load_city_map(path: str, location: str, region: tuple[float, float, float, float]) -> CityMap:
    """Reads the layers the converter needs, keeping features overlapping `region` (UTM box)."""
    conn = open_readonly(str(path))
    try:
        missing = [layer for layer in REQUIRED_LAYERS if table_columns(conn, str(path), layer) is None]
        if missing:
            raise InputError(f"{path}: layer '{missing[0]}' is missing")
        epsg = map_utm_epsg(conn, str(path), location)
        lane_lines, connector_lines = _baseline_paths(conn, str(path), epsg)
        return CityMap(
            path=str(path),
            lanes=_lanes(conn, str(path), epsg, region, lane_lines),
            connectors=_connectors(conn, str(path), epsg, region, connector_lines),
            boundaries=_simple(conn, str(path), "boundaries", ("boundary_type_fid",), epsg, region,
                               {"boundary_type": 0}),
            crosswalks=_simple(conn, str(path), "crosswalks", (), epsg, region, {}),
            stop_polygons=_simple(conn, str(path), "stop_polygons", ("stop_polygon_type_fid",), epsg, region,
                                  {"stop_type": 0}),
            drivable=_drivable(conn, str(path), epsg, region),
        )
    finally:
        conn.close()


def _int_column(values, default: int = -1) -> np.ndarray:
    return np.array([_as_int(v, default) for v in values], dtype=np.int64)


def _as_int(value, default: int = -1) -> int:
    try:
        return int(value) if value is not None else default
    except (TypeError, ValueError, OverflowError):
        return default


def _float_column(values, default: float = -1.0) -> np.ndarray:
    out = np.full(len(values), default, np.float64)
    for i, value in enumerate(values):
        try:
            number = float(value) if value is not None else default
        except (TypeError, ValueError):
            number = default
        out[i] = number if np.isfinite(number) and number > 0 else default
    return out


def _baseline_paths(conn, path: str, epsg: int) -> tuple[dict, dict]:
    """lane fid -> centreline, lane connector fid -> centreline (digitised in the driving direction)."""
    geometries, rows = read_layer(conn, path, "baseline_paths", ("lane_fid", "lane_connector_fid"), epsg)
    by_lane, by_connector = {}, {}
    for geometry, (_, lane_fid, connector_fid) in zip(geometries, rows):
        if lane_fid is not None:
            by_lane.setdefault(_as_int(lane_fid), geometry)
        elif connector_fid is not None:
            by_connector.setdefault(_as_int(connector_fid), geometry)
    return by_lane, by_connector


def _lanes(conn, path: str, epsg: int, region, centrelines: dict) -> FeatureTable:
    columns = ("lane_group_fid", "lane_index", "speed_limit_mps")
    optional = [c for c in ("lane_type_fid",) if c in (table_columns(conn, path, "lanes_polygons") or ())]
    _, rows = read_layer(conn, path, "lanes_polygons", columns + tuple(optional), epsg)
    kept = [row for row in rows if _as_int(row[0]) in centrelines]
    table = FeatureTable.build(
        [_as_int(r[0]) for r in kept], [centrelines[_as_int(r[0])] for r in kept],
        {"lane_group": _int_column([r[1] for r in kept]), "lane_index": _int_column([r[2] for r in kept]),
         "speed_limit": _float_column([r[3] for r in kept]),
         "lane_type": _int_column([r[4] if optional else 0 for r in kept], 0)})
    return table.within_box(region)


def _connectors(conn, path: str, epsg: int, region, centrelines: dict) -> FeatureTable:
    columns = ("exit_lane_fid", "entry_lane_fid", "speed_limit_mps")
    own_lines, rows = read_layer(conn, path, "lane_connectors", columns, epsg)
    # The baseline path is the centreline; the connector's own line is a fallback.
    lines = [centrelines.get(_as_int(r[0]), own) for r, own in zip(rows, own_lines)]
    table = FeatureTable.build(
        [_as_int(r[0]) for r in rows], lines,
        {"upstream_lane": _int_column([r[1] for r in rows]), "downstream_lane": _int_column([r[2] for r in rows]),
         "speed_limit": _float_column([r[3] for r in rows])})
    return table.within_box(region)


def _simple(conn, path: str, layer: str, columns: tuple, epsg: int, region, names: dict) -> FeatureTable:
    geometries, rows = read_layer(conn, path, layer, columns, epsg)
    attributes = {name: _int_column([r[1 + i] for r in rows], default)
                  for i, (name, default) in enumerate(names.items())}
    return FeatureTable.build([_as_int(r[0]) for r in rows], geometries, attributes).within_box(region)


def _drivable(conn, path: str, epsg: int, region) -> FeatureTable:
    fids, geometries = [], []
    for layer in DRIVABLE_LAYERS:
        layer_geometries, rows = read_layer(conn, path, layer, (), epsg)
        fids += [_as_int(r[0]) for r in rows]
        geometries += list(layer_geometries)
    return FeatureTable.build(fids, geometries).within_box(region)
