"""AV2 vector map JSON (`log_map_archive_<id>.json`) -> `MapPolyline`s and `LaneLinks`.

The archive holds three tables keyed by id: `lane_segments` (3D left/right boundaries in driving
direction, mark types, lane graph links), `pedestrian_crossings` (two parallel edges) and
`drivable_areas` (one boundary polygon each). Conventions (see docs/datasets/av2.md):
- lane centreline = mean of the two boundaries paired by normalised arc length;
- road lines = painted lane boundaries (NONE / UNKNOWN / SOLID_BLUE skipped), each shared
  boundary kept once;
- road edges = drivable-area boundaries turned counter-clockwise (the area on their left);
- crosswalks = edge1 followed by edge2 reversed, closed.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline
from scenariomax.sources.av2.errors import Av2FormatError
from scenariomax.sources.base import parse_json

LANE_TYPES = {"VEHICLE": sch.RG_LANE_SURFACE_STREET, "BUS": sch.RG_LANE_SURFACE_STREET,
              "BIKE": sch.RG_LANE_BIKE}
# AV2 mark types -> WOMD road line types. WOMD has no white mixed/double-dashed lines: mixed white
# pairs are treated as solid double white (the stricter reading), double dashed white as broken white.
MARK_TYPES = {
    "DASHED_WHITE": sch.RG_BROKEN_SINGLE_WHITE,
    "DOUBLE_DASH_WHITE": sch.RG_BROKEN_SINGLE_WHITE,
    "SOLID_WHITE": sch.RG_SOLID_SINGLE_WHITE,
    "DOUBLE_SOLID_WHITE": sch.RG_SOLID_DOUBLE_WHITE,
    "DASH_SOLID_WHITE": sch.RG_SOLID_DOUBLE_WHITE,
    "SOLID_DASH_WHITE": sch.RG_SOLID_DOUBLE_WHITE,
    "DASHED_YELLOW": sch.RG_BROKEN_SINGLE_YELLOW,
    "DOUBLE_DASH_YELLOW": sch.RG_BROKEN_DOUBLE_YELLOW,
    "SOLID_YELLOW": sch.RG_SOLID_SINGLE_YELLOW,
    "DOUBLE_SOLID_YELLOW": sch.RG_SOLID_DOUBLE_YELLOW,
    "DASH_SOLID_YELLOW": sch.RG_PASSING_DOUBLE_YELLOW,
    "SOLID_DASH_YELLOW": sch.RG_PASSING_DOUBLE_YELLOW,
}
# Road lines have no AV2 id: 2 * lane_id + side, shifted far above any AV2 map id.
ROAD_LINE_ID_OFFSET = 10**12
# Crosswalk / drivable-area ids that collide with a lane id are moved here.
COLLIDING_ID_OFFSET = 3 * 10**12
MAX_MAP_ID = 10**11  # AV2 ids are < 2**31; bounding them keeps the derived ids collision-free
CENTRELINE_SPACING_M = 0.5
# AV2 local maps span a few hundred metres of city coordinates; beyond these the file is corrupt.
MAX_ABS_COORD_M = 1e6
MAX_FEATURE_LENGTH_M = 10_000.0


@dataclasses.dataclass(frozen=True)
class Av2Map:
    lanes: tuple[MapPolyline, ...]  # centrelines, sorted by lane id
    road_lines: tuple[MapPolyline, ...]
    road_edges: tuple[MapPolyline, ...]
    crosswalks: tuple[MapPolyline, ...]
    lane_links: tuple[LaneLinks, ...]  # one per lane, same order as `lanes`
    ground_xyz: np.ndarray  # (g, 3) float64, every 3D vertex of the archive (for object heights)

    @property
    def polylines(self) -> tuple[MapPolyline, ...]:
        return self.lanes + self.road_lines + self.road_edges + self.crosswalks


# --- small parsing helpers -------------------------------------------------------------------------
def _field(record: Mapping, key: str, where: str) -> Any:
    if not isinstance(record, Mapping) or key not in record:
        raise Av2FormatError(f"{where}: missing '{key}'")
    return record[key]


def _as_id(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise Av2FormatError(f"{where}: id {value!r} is not an integer")
    try:
        feature_id = int(value)
    except ValueError:
        raise Av2FormatError(f"{where}: id {value!r} is not an integer") from None
    if not 0 <= feature_id < MAX_MAP_ID:
        raise Av2FormatError(f"{where}: id {feature_id} outside [0, {MAX_MAP_ID})")
    return feature_id


def _lookup(table: Mapping[str, int], value: Any, default: int | None) -> int | None:
    return table.get(value, default) if isinstance(value, str) else default


def _as_id_list(value: Any, where: str) -> list[int]:
    if value is None:
        return []
    if not isinstance(value, list):
        raise Av2FormatError(f"{where}: expected a list of ids, got {type(value).__name__}")
    return [_as_id(v, where) for v in value]


def parse_points(value: Any, where: str, min_points: int = 2) -> np.ndarray:
    """A JSON list of {"x", "y", "z"} dicts -> (n, 3) float64 (z defaults to 0)."""
    if not isinstance(value, list) or len(value) < min_points:
        raise Av2FormatError(f"{where}: expected a list of at least {min_points} points")
    out = np.empty((len(value), 3), np.float64)
    for row, point in enumerate(value):
        if not isinstance(point, Mapping):
            raise Av2FormatError(f"{where}: point {row} is not an object")
        try:
            out[row] = (float(point["x"]), float(point["y"]), float(point.get("z", 0.0)))
        except (KeyError, TypeError, ValueError):
            raise Av2FormatError(f"{where}: point {row} lacks numeric x/y") from None
    if not np.all(np.abs(out) < MAX_ABS_COORD_M):  # also catches NaN / inf
        raise Av2FormatError(f"{where}: coordinates not finite or beyond {MAX_ABS_COORD_M:g} m")
    if polyline_length(out) > MAX_FEATURE_LENGTH_M:  # resampling at 1 m must stay small
        raise Av2FormatError(f"{where}: longer than {MAX_FEATURE_LENGTH_M:g} m")
    return out


# --- geometry ---------------------------------------------------------------------------------------
def resample_by_fraction(xyz: np.ndarray, num_points: int) -> np.ndarray:
    """`num_points` points at equal fractions of the polyline's xy arc length. (n, 3) -> (num_points, 3)"""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1))])
    if arc[-1] <= 1e-9:
        return np.repeat(xyz[:1], num_points, axis=0)
    targets = np.linspace(0.0, 1.0, num_points) * arc[-1]
    return np.stack([np.interp(targets, arc, xyz[:, k]) for k in range(3)], axis=1)


def polyline_length(xyz: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1).sum())


def centreline(left: np.ndarray, right: np.ndarray, spacing: float = CENTRELINE_SPACING_M) -> np.ndarray:
    """Mean of the two boundaries paired by normalised arc length. -> (m, 3)"""
    longest = max(polyline_length(left), polyline_length(right))
    num_points = max(math.ceil(longest / spacing) + 1, 2, len(left), len(right))
    return 0.5 * (resample_by_fraction(left, num_points) + resample_by_fraction(right, num_points))


def signed_area(xy: np.ndarray) -> float:
    """Shoelace area of a polygon; positive when the vertices run counter-clockwise."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def counter_clockwise_ring(xyz: np.ndarray) -> np.ndarray:
    """Drops a repeated closing vertex and orders the ring counter-clockwise (interior on the left)."""
    if len(xyz) > 2 and np.allclose(xyz[0, :2], xyz[-1, :2]):
        xyz = xyz[:-1]
    return xyz[::-1].copy() if signed_area(xyz[:, :2]) < 0 else xyz


def drivable_area_edges(areas: list[tuple[int, np.ndarray]]) -> list[MapPolyline]:
    """Road edges = the outline of the UNION of the drivable areas: exteriors counter-clockwise
    (boundary type), holes clockwise (median type), so the drivable area is always on the left.

    AV2 splits the drivable area into polygons that touch; their shared seams are not road edges
    (a car crossing a seam would look off-road to the nearest-edge rule). Each union polygon keeps
    the smallest id of the areas it contains; holes get stable derived ids. z comes from the
    nearest input boundary vertex.
    """
    import zlib

    import shapely

    if not areas:
        return []
    polygons = [shapely.Polygon(boundary[:, :2]).buffer(0) for _, boundary in areas]
    # A 2 cm close-open merges seams that are not exactly shared (AV2 quantises to 1 cm).
    union = shapely.union_all(polygons).buffer(0.02, join_style="mitre").buffer(-0.02, join_style="mitre")
    vertices = np.concatenate([boundary for _, boundary in areas])

    def with_z(xy: np.ndarray) -> np.ndarray:
        nearest = np.argmin(((xy[:, None, :] - vertices[None, :, :2]) ** 2).sum(-1), axis=1)
        return np.column_stack([xy, vertices[nearest, 2]])

    edges = []
    for polygon in sorted(shapely.get_parts(union), key=lambda poly: poly.bounds):
        if polygon.is_empty or polygon.area < 1.0:
            continue
        polygon = shapely.orient_polygons(polygon) if hasattr(shapely, "orient_polygons") else \
            shapely.geometry.polygon.orient(polygon, 1.0)
        poly_id = min(area_id for (area_id, _), part in zip(areas, polygons) if part.intersects(polygon))
        exterior = np.asarray(polygon.exterior.coords)[:-1]
        edges.append(MapPolyline(poly_id, sch.RG_ROAD_EDGE_BOUNDARY, with_z(exterior), closed=True))
        for index, hole in enumerate(polygon.interiors):
            hole_id = zlib.crc32(f"av2-hole-{poly_id}-{index}".encode()) & 0x7FFFFFFF
            edges.append(MapPolyline(hole_id, sch.RG_ROAD_EDGE_MEDIAN, with_z(np.asarray(hole.coords)[:-1]),
                                     closed=True))
    return edges


def _geometry_key(xyz: np.ndarray) -> bytes:
    """Direction-independent key of a polyline at 1 cm (AV2's quantisation), to find shared boundaries."""
    cm = np.round(xyz[:, :2] * 100.0).astype(np.int64)
    forward, backward = cm.tobytes(), cm[::-1].tobytes()
    return min(forward, backward)


# --- tables -----------------------------------------------------------------------------------------
def _table(archive: Mapping, key: str, required: bool) -> dict:
    if key not in archive:
        if required:
            raise Av2FormatError(f"missing '{key}'")
        return {}
    value = archive[key]
    if isinstance(value, list):  # tolerate a list of records instead of an id-keyed object
        return {str(i): v for i, v in enumerate(value)}
    if not isinstance(value, Mapping):
        raise Av2FormatError(f"'{key}' is not an object")
    return dict(value)


def _known(ids: list[int], lane_ids: set[int]) -> list[int]:
    """Links to lanes outside this archive are dropped (they would point at nothing)."""
    return [i for i in ids if i in lane_ids]


def _neighbor(record: Mapping, key: str, where: str, lane_ids: set[int]) -> list[int]:
    value = record.get(key)
    return [] if value is None else _known([_as_id(value, where)], lane_ids)


def _unique_id(feature_id: int, lane_ids: set[int]) -> int:
    return COLLIDING_ID_OFFSET + feature_id if feature_id in lane_ids else feature_id


def parse_map(archive: Any, lane_speed_limit: float = -1.0) -> Av2Map:
    """Parsed JSON archive -> Av2Map. Raises Av2FormatError on malformed structure."""
    if not isinstance(archive, Mapping):
        raise Av2FormatError("top level is not a JSON object")
    lane_records = _table(archive, "lane_segments", required=True)
    crossing_records = _table(archive, "pedestrian_crossings", required=False)
    area_records = _table(archive, "drivable_areas", required=False)

    parsed_lanes = []
    for key, record in lane_records.items():
        where = f"lane_segments[{key}]"
        lane_id = _as_id(_field(record, "id", where), where)
        left = parse_points(_field(record, "left_lane_boundary", where), f"{where}.left_lane_boundary")
        right = parse_points(_field(record, "right_lane_boundary", where), f"{where}.right_lane_boundary")
        parsed_lanes.append((lane_id, record, left, right, where))
    parsed_lanes.sort(key=lambda item: item[0])
    lane_ids = {item[0] for item in parsed_lanes}
    if len(lane_ids) != len(parsed_lanes):
        raise Av2FormatError("duplicate lane segment ids")

    lanes, links, road_lines, ground = [], [], [], []
    seen_lines: set[bytes] = set()
    for lane_id, record, left, right, where in parsed_lanes:
        lane_type = _lookup(LANE_TYPES, record.get("lane_type"), sch.RG_LANE_SURFACE_STREET)
        lanes.append(MapPolyline(lane_id, lane_type,
                                 centreline(left, right), speed_limit=float(lane_speed_limit)))
        links.append(LaneLinks(
            lane_id=lane_id,
            successors=_known(_as_id_list(record.get("successors"), where), lane_ids),
            predecessors=_known(_as_id_list(record.get("predecessors"), where), lane_ids),
            left_neighbors=_neighbor(record, "left_neighbor_id", where, lane_ids),
            right_neighbors=_neighbor(record, "right_neighbor_id", where, lane_ids),
        ))
        ground += [left, right]
        for side, boundary, mark_key in ((0, left, "left_lane_mark_type"), (1, right, "right_lane_mark_type")):
            line_type = _lookup(MARK_TYPES, record.get(mark_key), None)
            key = _geometry_key(boundary)
            if line_type is None or key in seen_lines:
                continue
            seen_lines.add(key)
            road_lines.append(MapPolyline(ROAD_LINE_ID_OFFSET + 2 * lane_id + side, line_type, boundary))

    crosswalks = []
    for key, record in sorted(crossing_records.items(), key=lambda kv: str(kv[0])):
        where = f"pedestrian_crossings[{key}]"
        feature_id = _as_id(_field(record, "id", where), where)
        edge1 = parse_points(_field(record, "edge1", where), f"{where}.edge1")
        edge2 = parse_points(_field(record, "edge2", where), f"{where}.edge2")
        # Both edges point the same way, so edge1 + reversed(edge2) walks around the crosswalk.
        crosswalks.append(MapPolyline(_unique_id(feature_id, lane_ids), sch.RG_CROSSWALK,
                                      np.vstack([edge1, edge2[::-1]]), closed=True))
        ground += [edge1, edge2]

    areas = []
    for key, record in sorted(area_records.items(), key=lambda kv: str(kv[0])):
        where = f"drivable_areas[{key}]"
        feature_id = _as_id(_field(record, "id", where), where)
        boundary = parse_points(_field(record, "area_boundary", where), f"{where}.area_boundary", min_points=3)
        areas.append((_unique_id(feature_id, lane_ids), boundary))
        ground.append(boundary)
    road_edges = drivable_area_edges(areas)

    crosswalks.sort(key=lambda line: line.feature_id)
    road_edges.sort(key=lambda line: line.feature_id)
    return Av2Map(
        lanes=tuple(lanes), road_lines=tuple(road_lines), road_edges=tuple(road_edges),
        crosswalks=tuple(crosswalks), lane_links=tuple(links),
        ground_xyz=np.concatenate(ground) if ground else np.zeros((0, 3)),
    )


def load_map_json(data: bytes) -> Any:
    """Bytes of the archive -> parsed JSON. Raises Av2FormatError (one line) when not JSON."""
    try:
        return parse_json(data)
    except ValueError as err:
        raise Av2FormatError(str(err)) from None
