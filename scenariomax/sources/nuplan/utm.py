"""WGS 84 longitude/latitude -> UTM metres (transverse Mercator, Krueger series to n^4).

nuPlan maps may store their layers in EPSG:4326 while logs use the city's UTM zone, so map
geometry is projected here instead of pulling in PROJ. The n^4 series is accurate to well under
a millimetre inside a UTM zone.
"""

from __future__ import annotations

import math
import re

import numpy as np

WGS84_SEMI_MAJOR_M = 6378137.0
WGS84_FLATTENING = 1 / 298.257223563
UTM_SCALE = 0.9996
UTM_FALSE_EASTING_M = 500_000.0
UTM_FALSE_NORTHING_SOUTH_M = 10_000_000.0

_N = WGS84_FLATTENING / (2 - WGS84_FLATTENING)
_RECTIFYING_RADIUS_M = WGS84_SEMI_MAJOR_M / (1 + _N) * (1 + _N**2 / 4 + _N**4 / 64)
_ALPHA = (
    _N / 2 - 2 * _N**2 / 3 + 5 * _N**3 / 16 + 41 * _N**4 / 180,
    13 * _N**2 / 48 - 3 * _N**3 / 5 + 557 * _N**4 / 1440,
    61 * _N**3 / 240 - 103 * _N**4 / 140,
    49561 * _N**4 / 161280,
)
_CONFORMAL = 2 * math.sqrt(_N) / (1 + _N)


def utm_epsg_zone(epsg: int) -> tuple[int, bool] | None:
    """(zone, is_north) for EPSG:326zz / 327zz, else None."""
    if 32601 <= epsg <= 32660:
        return epsg - 32600, True
    if 32701 <= epsg <= 32760:
        return epsg - 32700, False
    return None


def parse_epsg(text: str) -> int | None:
    """'epsg:32611' / 'EPSG:32611' -> 32611; None when the text names no EPSG code."""
    match = re.search(r"epsg\s*:\s*(\d+)", str(text), flags=re.IGNORECASE)
    return int(match.group(1)) if match else None


def lonlat_to_utm(lon_deg: np.ndarray, lat_deg: np.ndarray, zone: int, is_north: bool = True
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Degrees (...) -> (easting, northing) metres (...) in the given UTM zone."""
    lon = np.radians(np.asarray(lon_deg, np.float64))
    lat = np.radians(np.asarray(lat_deg, np.float64))
    central_meridian = math.radians(zone * 6 - 183)
    dlon = lon - central_meridian
    sin_lat = np.sin(lat)
    t = np.sinh(np.arctanh(sin_lat) - _CONFORMAL * np.arctanh(_CONFORMAL * sin_lat))
    xi = np.arctan2(t, np.cos(dlon))
    eta = np.arctanh(np.sin(dlon) / np.sqrt(1 + t * t))
    east, north = eta.copy(), xi.copy()
    for j, alpha in enumerate(_ALPHA, start=1):
        east += alpha * np.cos(2 * j * xi) * np.sinh(2 * j * eta)
        north += alpha * np.sin(2 * j * xi) * np.cosh(2 * j * eta)
    easting = UTM_FALSE_EASTING_M + UTM_SCALE * _RECTIFYING_RADIUS_M * east
    northing = UTM_SCALE * _RECTIFYING_RADIUS_M * north
    if not is_north:
        northing = northing + UTM_FALSE_NORTHING_SOUTH_M
    return easting, northing
