"""GeoPackage (OGC, SQLite-based) vector layers without GDAL: geometry blobs are 'GP' header + WKB."""

from __future__ import annotations

import dataclasses
import sqlite3
import struct
from collections.abc import Sequence

import numpy as np
import shapely

from scenariomax.errors import InputError
from scenariomax.sources.nuplan import utm
from scenariomax.sources.nuplan.sqlite_access import fetch_all, one_line, require_columns, table_columns

_ENVELOPE_DOUBLES = {0: 0, 1: 4, 2: 6, 3: 6, 4: 8}
_HEADER_BYTES = 8
WGS84_SRS_ID = 4326


def geometry_wkb(blob: bytes) -> bytes:
    """The WKB part of a GeoPackage geometry blob (raises ValueError when the header is malformed)."""
    blob = bytes(blob)
    if len(blob) < _HEADER_BYTES or blob[:2] != b"GP":
        raise ValueError("not a GeoPackage geometry blob")
    flags = blob[3]
    envelope_code = (flags >> 1) & 0b111
    if envelope_code not in _ENVELOPE_DOUBLES:
        raise ValueError(f"bad envelope code {envelope_code}")
    if flags & 0b100000:
        raise ValueError("extended GeoPackage geometry is not supported")
    start = _HEADER_BYTES + 8 * _ENVELOPE_DOUBLES[envelope_code]
    if len(blob) <= start:
        raise ValueError("geometry blob truncated")
    return blob[start:]


def blob_srs_id(blob: bytes) -> int:
    order = "<" if blob[3] & 1 else ">"
    return struct.unpack(order + "i", bytes(blob[4:8]))[0]


def decode_geometries(path: str, layer: str, blobs: Sequence[bytes]) -> np.ndarray:
    """GeoPackage blobs -> shapely geometries (object array); InputError on malformed blobs."""
    try:
        wkbs = [geometry_wkb(b) if b is not None else None for b in blobs]
        return np.asarray(shapely.from_wkb(wkbs, on_invalid="raise"), dtype=object).reshape(-1)
    except (ValueError, TypeError, shapely.errors.ShapelyError) as exc:
        raise InputError(f"{path}: layer '{layer}' has a malformed geometry ({one_line(exc)})") from None


@dataclasses.dataclass(frozen=True)
class LayerProjection:
    """How to bring a layer's stored coordinates into the log's UTM metres."""

    srs_id: int
    zone: int | None = None  # set when stored in lon/lat (EPSG:4326)
    is_north: bool = True

    def apply(self, geometries: np.ndarray) -> np.ndarray:
        if self.zone is None:
            return geometries
        zone, north = self.zone, self.is_north

        def project(coords: np.ndarray) -> np.ndarray:
            east, northing = utm.lonlat_to_utm(coords[:, 0], coords[:, 1], zone, north)
            return np.stack([east, northing], axis=1)

        return shapely.transform(geometries, project)


def layer_projection(conn: sqlite3.Connection, path: str, layer: str, utm_epsg: int) -> LayerProjection:
    """Reads gpkg_geometry_columns.srs_id of the layer; lon/lat layers get projected to `utm_epsg`."""
    require_columns(conn, path, "gpkg_geometry_columns", ("table_name", "srs_id"))
    rows = fetch_all(conn, path, "SELECT srs_id FROM gpkg_geometry_columns WHERE table_name = ?", (layer,))
    if not rows:
        raise InputError(f"{path}: layer '{layer}' is missing from gpkg_geometry_columns")
    srs_id = int(rows[0][0])
    if srs_id == WGS84_SRS_ID:
        zone = utm.utm_epsg_zone(utm_epsg)
        if zone is None:
            raise InputError(f"{path}: layer '{layer}' is stored in lon/lat but no UTM zone is known")
        return LayerProjection(srs_id, zone[0], zone[1])
    if srs_id == utm_epsg or utm.utm_epsg_zone(srs_id) is not None:
        return LayerProjection(srs_id)
    raise InputError(f"{path}: layer '{layer}' uses unsupported srs_id {srs_id} (expected 4326 or a UTM code)")


def read_layer(conn: sqlite3.Connection, path: str, layer: str, columns: Sequence[str], utm_epsg: int
               ) -> tuple[np.ndarray, list[tuple]]:
    """(geometries in UTM (F,) object, attribute rows [(fid, *columns)]) of one feature layer."""
    geometry_column = _geometry_column(conn, path, layer)
    require_columns(conn, path, layer, ("fid", geometry_column, *columns), kind="layer")
    projection = layer_projection(conn, path, layer, utm_epsg)
    select = ", ".join(f'"{c}"' for c in ("fid", *columns, geometry_column))
    rows = fetch_all(conn, path, f'SELECT {select} FROM "{layer}" ORDER BY fid')
    rows = [row for row in rows if row[-1] is not None]
    geometries = decode_geometries(path, layer, [row[-1] for row in rows])
    return projection.apply(geometries), [row[:-1] for row in rows]


def _geometry_column(conn: sqlite3.Connection, path: str, layer: str) -> str:
    require_columns(conn, path, "gpkg_geometry_columns", ("table_name", "column_name"))
    rows = fetch_all(conn, path, "SELECT column_name FROM gpkg_geometry_columns WHERE table_name = ?", (layer,))
    if not rows:
        if table_columns(conn, path, layer) is None:
            raise InputError(f"{path}: layer '{layer}' is missing")
        raise InputError(f"{path}: layer '{layer}' is missing from gpkg_geometry_columns")
    return str(rows[0][0])
