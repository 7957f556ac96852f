"""Writers of tiny nuPlan files in the real on-disk layout: a log SQLite DB (devkit table and column
names, 8-byte BLOB tokens) and a GeoPackage city map (gpkg_* tables, 'GP' header + WKB geometry),
placed in the real maps folder layout. All geometry is hand-placed so tests know the answers."""

from __future__ import annotations

import dataclasses
import json
import math
import pickle
import sqlite3
import struct
from pathlib import Path

import numpy as np
import shapely

LOCATION = "us-nv-las-vegas-strip"
MAP_VERSION_DIR = "9.15.1915"
UTM_EPSG = 32611
UTM_ZONE = 11
LOG_NAME = "2021.07.16.20.45.29_veh-35_01095_01486"
E0, N0 = 664_000.0, 3_997_000.0  # the fixture's origin in UTM zone 11 (Las Vegas)
T0 = 1_626_468_329_000_000  # log start, Unix microseconds
NUM_LIDAR_PCS = 240  # 12 s at 20 Hz
EGO_SPEED = 10.0  # m/s east along lane 102
EGO_START_X = E0 - 20.0  # rear axle at t = 0
TAGGED_LIDAR_PCS = (40, 60)


def token(kind: int, index: int) -> bytes:
    """Deterministic 8-byte token; `kind` keeps the tables' tokens apart."""
    return struct.pack(">HIH", kind, index, 0x5A5A)


def lidar_time(i: int) -> int:
    """20 Hz with a little jitter (real intervals jitter around 50 ms)."""
    return T0 + 50_000 * i + ((i % 3) - 1) * 1_000


def ego_rear_x(time_micros: int) -> float:
    return EGO_START_X + EGO_SPEED * (time_micros - T0) / 1e6


# --- agents: (category, present lidar_pc indices, position(t) fn, velocity, size (l, w, h), yaw) -----
def _agents():
    return [
        ("vehicle", range(NUM_LIDAR_PCS), lambda t: (E0 + 20 + 10 * t, N0), (10.0, 0.0), (4.5, 2.0, 1.6), 0.0),
        ("vehicle", range(NUM_LIDAR_PCS), lambda t: (E0 - 50, N0 + 3.5), (0.0, 0.0), (4.8, 2.1, 1.7), 0.0),
        ("pedestrian", range(120), lambda t: (E0 + 110, N0 - 2 + 0.5 * t), (0.0, 0.5), (0.6, 0.6, 1.8),
         math.pi / 2),
        ("bicycle", range(100, NUM_LIDAR_PCS), lambda t: (E0 + 5 + 4 * t, N0 - 1.0), (4.0, 0.0), (1.8, 0.6, 1.7),
         2 * math.pi + 0.1),  # unwrapped yaw in the raw file -> wrapped in the output
        ("traffic_cone", range(NUM_LIDAR_PCS), lambda t: (E0 + 30, N0 - 1.5), (0.0, 0.0), (0.4, 0.4, 0.7), 0.0),
    ]


NUM_AGENTS = 5
CATEGORIES = ("vehicle", "pedestrian", "bicycle", "traffic_cone", "barrier", "czone_sign", "generic_object")


def light_status(connector: int, i: int) -> str:
    if connector == 201:
        return "red" if i < 100 else ("green" if i < 180 else "yellow")
    return "unknown"


LOG_DDL = """
CREATE TABLE log (token BLOB(8) PRIMARY KEY, vehicle_name VARCHAR(64), date VARCHAR(64), timestamp INTEGER,
    logfile VARCHAR(64), location VARCHAR(64), map_version VARCHAR(64));
CREATE TABLE ego_pose (token BLOB(8) PRIMARY KEY, timestamp INTEGER, x FLOAT, y FLOAT, z FLOAT, qw FLOAT, qx FLOAT,
    qy FLOAT, qz FLOAT, vx FLOAT, vy FLOAT, vz FLOAT, acceleration_x FLOAT, acceleration_y FLOAT,
    acceleration_z FLOAT, angular_rate_x FLOAT, angular_rate_y FLOAT, angular_rate_z FLOAT, epsg INTEGER,
    log_token BLOB(8) NOT NULL);
CREATE TABLE lidar (token BLOB(8) PRIMARY KEY, log_token BLOB(8) NOT NULL, channel VARCHAR(64), model VARCHAR(64),
    translation BLOB, rotation BLOB);
CREATE TABLE scene (token BLOB(8) PRIMARY KEY, log_token BLOB(8) NOT NULL, name TEXT, goal_ego_pose_token BLOB(8),
    roadblock_ids TEXT);
CREATE TABLE lidar_pc (token BLOB(8) PRIMARY KEY, next_token BLOB(8), prev_token BLOB(8),
    ego_pose_token BLOB(8) NOT NULL, lidar_token BLOB(8) NOT NULL, scene_token BLOB(8) NOT NULL,
    filename VARCHAR(128), timestamp INTEGER);
CREATE TABLE category (token BLOB(8) PRIMARY KEY, name VARCHAR(64), description TEXT);
CREATE TABLE track (token BLOB(8) PRIMARY KEY, category_token BLOB(8) NOT NULL, width FLOAT, length FLOAT,
    height FLOAT);
CREATE TABLE lidar_box (token BLOB(8) PRIMARY KEY, lidar_pc_token BLOB(8) NOT NULL, track_token BLOB(8),
    next_token BLOB(8), prev_token BLOB(8), x FLOAT, y FLOAT, z FLOAT, width FLOAT, length FLOAT, height FLOAT,
    vx FLOAT, vy FLOAT, vz FLOAT, yaw FLOAT, confidence FLOAT);
CREATE TABLE scenario_tag (token BLOB(8) PRIMARY KEY, lidar_pc_token BLOB(8) NOT NULL, type TEXT,
    agent_track_token BLOB(8));
CREATE TABLE traffic_light_status (token BLOB(8) PRIMARY KEY, lidar_pc_token BLOB(8) NOT NULL,
    lane_connector_id INTEGER, status VARCHAR(8));
"""


def write_log_db(path: Path, map_version: str = LOCATION, skip_tables: tuple = ()) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    conn = sqlite3.connect(path)
    conn.executescript(LOG_DDL)
    log_token = token(1, 0)
    conn.execute("INSERT INTO log VALUES (?,?,?,?,?,?,?)",
                 (log_token, "veh-35", "2021-07-16", T0, LOG_NAME, "las_vegas", map_version))
    lidar_token = token(2, 0)
    conn.execute("INSERT INTO lidar VALUES (?,?,?,?,?,?)", (lidar_token, log_token, "MergedPointCloud", "merged",
                                                          pickle.dumps([0.0, 0.0, 1.8]), pickle.dumps([1.0, 0, 0, 0])))
    scene_token = token(3, 0)
    conn.execute("INSERT INTO scene VALUES (?,?,?,?,?)", (scene_token, log_token, "scene-0000", None, "10 11"))
    # ego_pose at 100 Hz, a little beyond the lidar span on both ends
    poses = []
    for j in range(-2, NUM_LIDAR_PCS * 5 + 2):  # 100 Hz, 20 ms beyond both ends
        t = T0 + 10_000 * j
        poses.append((token(4, j + 2), t, ego_rear_x(t), N0, 600.0, 1.0, 0.0, 0.0, 0.0, EGO_SPEED, 0.0, 0.0,
                      0.0, 0.0, 0.0, 0.0, 0.0, 0.0, UTM_EPSG, log_token))
    conn.executemany(f"INSERT INTO ego_pose VALUES ({','.join('?' * 20)})", poses)
    for i in range(NUM_LIDAR_PCS):
        pose_index = round((lidar_time(i) - T0) / 10_000) + 2
        conn.execute("INSERT INTO lidar_pc VALUES (?,?,?,?,?,?,?,?)", (
            token(5, i), token(5, i + 1) if i + 1 < NUM_LIDAR_PCS else None, token(5, i - 1) if i else None,
            token(4, pose_index), lidar_token, scene_token, f"{LOG_NAME}/MergedPointCloud/{i:016x}.pcd",
            lidar_time(i)))
    for c, name in enumerate(CATEGORIES):
        conn.execute("INSERT INTO category VALUES (?,?,?)", (token(6, c), name, name))
    box_index = 0
    for a, (category, present, position_fn, velocity, size, yaw) in enumerate(_agents()):
        conn.execute("INSERT INTO track VALUES (?,?,?,?,?)",
                     (token(7, a), token(6, CATEGORIES.index(category)), size[1], size[0], size[2]))
        for i in present:
            x, y = position_fn((lidar_time(i) - T0) / 1e6)
            conn.execute(f"INSERT INTO lidar_box VALUES ({','.join('?' * 16)})", (
                token(8, box_index), token(5, i), token(7, a), None, None, x, y, 601.0, size[1], size[0], size[2],
                velocity[0], velocity[1], 0.0, yaw, 0.9))
            box_index += 1
    conn.execute("INSERT INTO scenario_tag VALUES (?,?,?,?)",
                 (token(9, 0), token(5, 40), "starting_straight_traffic_light_intersection_traversal", token(7, 0)))
    conn.execute("INSERT INTO scenario_tag VALUES (?,?,?,?)", (token(9, 1), token(5, 60), "following_lane_with_lead",
                                                              token(7, 0)))
    conn.execute("INSERT INTO scenario_tag VALUES (?,?,?,?)", (token(9, 2), token(5, 60), "near_multiple_vehicles",
                                                              None))
    status_index = 0
    for i in range(NUM_LIDAR_PCS):
        for connector in (201, 202, 999):  # 999 is not in the map
            conn.execute("INSERT INTO traffic_light_status VALUES (?,?,?,?)",
                         (token(10, status_index), token(5, i), connector, light_status(connector, i)))
            status_index += 1
    for table in skip_tables:
        conn.execute(f"DROP TABLE {table}")
    conn.commit()
    conn.close()
    return path


# --- map -------------------------------------------------------------------------------------------
LANE_Y = {101: N0 + 3.5, 102: N0, 103: N0}
SPEED_LIMITS = {101: 13.4, 102: 13.4, 103: None, 201: 11.0, 202: None}


def _rect(x0, y0, x1, y1):
    return shapely.box(x0, y0, x1, y1)


def map_features() -> dict:
    """layer -> (geometry type, [(column, sql type)], [row dicts with 'geom' in UTM])."""
    line = shapely.LineString
    lanes = [
        {"fid": 101, "lane_fid": 101, "lane_group_fid": 10, "lane_index": 0, "left_boundary_fid": 401,
             "right_boundary_fid": 402,
             "speed_limit_mps": 13.4, "lane_type_fid": 0, "geom": _rect(E0 - 200, N0 + 1.75, E0 + 100, N0 + 5.25)},
        {"fid": 102, "lane_fid": 102, "lane_group_fid": 10, "lane_index": 1, "left_boundary_fid": 402,
             "right_boundary_fid": 403,
             "speed_limit_mps": 13.4, "lane_type_fid": 0, "geom": _rect(E0 - 200, N0 - 1.75, E0 + 100, N0 + 1.75)},
        {"fid": 103, "lane_fid": 103, "lane_group_fid": 11, "lane_index": 0, "left_boundary_fid": None,
             "right_boundary_fid": None, "speed_limit_mps": None, "lane_type_fid": 0,
             "geom": _rect(E0 + 120, N0 - 1.75, E0 + 400, N0 + 1.75)},
    ]
    connectors = [
        {"fid": 201, "exit_lane_fid": 102, "entry_lane_fid": 103, "exit_lane_group_fid": 10, "entry_lane_group_fid": 11,
             "lane_group_connector_fid": 20, "intersection_fid": 30, "traffic_light_stop_line_fids": "501",
             "speed_limit_mps": 11.0, "geom": line([(E0 + 100, N0), (E0 + 120, N0)])},
        {"fid": 202, "exit_lane_fid": 101, "entry_lane_fid": 103, "exit_lane_group_fid": 10, "entry_lane_group_fid": 11,
             "lane_group_connector_fid": 20, "intersection_fid": 30, "traffic_light_stop_line_fids": "",
             "speed_limit_mps": None, "geom": line([(E0 + 100, N0 + 3.5), (E0 + 120, N0)])},
    ]
    baselines = [{"fid": 300 + k, "lane_fid": lane, "lane_connector_fid": None, "path_type_fid": 0,
                      "dubins_node_fids": "", "geom": line([(x0, LANE_Y[lane]), (x1, LANE_Y[lane])])}
                 for k, (lane, x0, x1) in enumerate([(101, E0 - 200, E0 + 100), (102, E0 - 200, E0 + 100),
                                                     (103, E0 + 120, E0 + 400)], start=1)]
    baselines += [{"fid": 304 + k, "lane_fid": None, "lane_connector_fid": c["fid"], "path_type_fid": 0,
                       "dubins_node_fids": "", "geom": c["geom"]} for k, c in enumerate(connectors)]
    boundaries = [{"fid": 401, "boundary_type_fid": 2, "geom": line([(E0 - 200, N0 + 5.25), (E0 + 100, N0 + 5.25)])},
                  {"fid": 402, "boundary_type_fid": 0, "geom": line([(E0 - 200, N0 + 1.75), (E0 + 100, N0 + 1.75)])},
                  {"fid": 403, "boundary_type_fid": 2, "geom": line([(E0 + 100, N0 - 1.75), (E0 - 200, N0 - 1.75)])}]
    crosswalks = [{"fid": 601, "is_marked": 1, "geom": _rect(E0 + 105, N0 - 2, E0 + 115, N0 + 6)}]
    stops = [{"fid": 501, "stop_polygon_type_fid": 2, "geom": _rect(E0 + 99, N0 - 1.75, E0 + 100, N0 + 1.75)},
             {"fid": 502, "stop_polygon_type_fid": 1, "geom": _rect(E0 + 99, N0 + 1.75, E0 + 100, N0 + 5.25)}]
    road_segments = [{"fid": 701, "geom": _rect(E0 - 200, N0 - 1.75, E0 + 100, N0 + 5.25)}]
    intersections = [{"fid": 30, "intersection_type_fid": 1, "is_mini": 0,
                          "geom": _rect(E0 + 100, N0 - 1.75, E0 + 120, N0 + 5.25)}]
    generic = [{"fid": 801, "geom": _rect(E0 + 120, N0 - 1.75, E0 + 400, N0 + 1.75)}]
    INT, R, T = "INTEGER", "REAL", "TEXT(256)"
    return {
        "lanes_polygons": ("POLYGON", [("lane_fid", INT), ("lane_group_fid", INT), ("lane_index", "MEDIUMINT"),
                                       ("left_boundary_fid", INT), ("right_boundary_fid", INT), ("speed_limit_mps", R),
                                       ("lane_type_fid", INT)], lanes),
        "lane_connectors": ("LINESTRING", [("exit_lane_fid", INT), ("entry_lane_fid", INT),
                                           ("exit_lane_group_fid", INT), ("entry_lane_group_fid", INT),
                                           ("lane_group_connector_fid", INT), ("intersection_fid", INT),
                                           ("traffic_light_stop_line_fids", T),
                                           ("speed_limit_mps", R)], connectors),
        "baseline_paths": ("LINESTRING", [("lane_fid", INT), ("lane_connector_fid", INT), ("path_type_fid", INT),
                                          ("dubins_node_fids", T)], baselines),
        "boundaries": ("LINESTRING", [("boundary_type_fid", INT)], boundaries),
        "crosswalks": ("POLYGON", [("is_marked", "BOOLEAN")], crosswalks),
        "stop_polygons": ("POLYGON", [("stop_polygon_type_fid", INT)], stops),
        "road_segments": ("POLYGON", [], road_segments),
        "intersections": ("POLYGON", [("intersection_type_fid", INT), ("is_mini", "BOOLEAN")], intersections),
        "generic_drivable_areas": ("POLYGON", [], generic),
        "carpark_areas": ("POLYGON", [("heading", R)], []),
        "traffic_lights": ("POINT", [("ori_mean_yaw", R)],
                           [{"fid": 901, "ori_mean_yaw": math.pi, "geom": shapely.Point(E0 + 121, N0 + 6)}]),
    }


# --- inverse UTM (independent of the converter's forward series: Krueger beta/delta series) -------------
def utm_to_lonlat(easting, northing, zone: int = UTM_ZONE):
    a, f = 6378137.0, 1 / 298.257223563
    n = f / (2 - f)
    big_a = a / (1 + n) * (1 + n**2 / 4 + n**4 / 64)
    beta = (n / 2 - 2 * n**2 / 3 + 37 * n**3 / 96 - n**4 / 360, n**2 / 48 + n**3 / 15 - 437 * n**4 / 1440,
            17 * n**3 / 480 - 37 * n**4 / 840, 4397 * n**4 / 161280)
    xi = np.asarray(northing, float) / (0.9996 * big_a)
    eta = (np.asarray(easting, float) - 500_000.0) / (0.9996 * big_a)
    xi_p, eta_p = xi.copy(), eta.copy()
    for j, b in enumerate(beta, start=1):
        xi_p -= b * np.sin(2 * j * xi) * np.cosh(2 * j * eta)
        eta_p -= b * np.cos(2 * j * xi) * np.sinh(2 * j * eta)
    chi = np.arcsin(np.sin(xi_p) / np.cosh(eta_p))
    # conformal -> geodetic latitude by fixed-point iteration (exact, no truncated series)
    e = math.sqrt(f * (2 - f))
    lat = chi.copy()
    for _ in range(20):
        lat = 2 * np.arctan(np.tan(math.pi / 4 + chi / 2)
                            * ((1 + e * np.sin(lat)) / (1 - e * np.sin(lat))) ** (e / 2)) - math.pi / 2
    lon = math.radians(zone * 6 - 183) + np.arctan2(np.sinh(eta_p), np.cos(xi_p))
    return np.degrees(lon), np.degrees(lat)


def _to_lonlat(geometry):
    def fn(coords):
        lon, lat = utm_to_lonlat(coords[:, 0], coords[:, 1])
        return np.stack([lon, lat], axis=1)
    return shapely.transform(geometry, fn)


def gpkg_blob(geometry, srs_id: int, big_endian: bool = False, envelope: bool = True) -> bytes:
    order = ">" if big_endian else "<"
    flags = (0 if big_endian else 1) | ((1 if envelope else 0) << 1)
    header = b"GP" + bytes([0, flags]) + struct.pack(order + "i", srs_id)
    if envelope:
        minx, miny, maxx, maxy = geometry.bounds
        header += struct.pack(order + "4d", minx, maxx, miny, maxy)
    return header + shapely.to_wkb(geometry, byte_order=1)


def write_gpkg(path: Path, lonlat: bool = False, skip_layers: tuple = (), with_meta: bool = True) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    srs_id = 4326 if lonlat else UTM_EPSG
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA application_id = 1196444487")
    conn.execute("PRAGMA user_version = 10200")
    conn.executescript("""
    CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY, organization TEXT NOT NULL,
        organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);
    CREATE TABLE gpkg_contents (table_name TEXT PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT UNIQUE,
        description TEXT DEFAULT '', last_change DATETIME, min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE,
        srs_id INTEGER);
    CREATE TABLE gpkg_geometry_columns (table_name TEXT NOT NULL, column_name TEXT NOT NULL,
        geometry_type_name TEXT NOT NULL, srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL,
        PRIMARY KEY (table_name, column_name));
    """)
    conn.executemany("INSERT INTO gpkg_spatial_ref_sys VALUES (?,?,?,?,?,?)", [
        ("Undefined cartesian SRS", -1, "NONE", -1, "undefined", ""),
        ("Undefined geographic SRS", 0, "NONE", 0, "undefined", ""),
        ("WGS 84 geodetic", 4326, "EPSG", 4326, "GEOGCS[\"WGS 84\"]", ""),
        ("WGS 84 / UTM zone 11N", UTM_EPSG, "EPSG", UTM_EPSG, "PROJCS[\"WGS 84 / UTM zone 11N\"]", "")])
    if with_meta:
        conn.execute("CREATE TABLE meta (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, key TEXT, value TEXT)")
        conn.executemany("INSERT INTO meta (key, value) VALUES (?, ?)",
                         [("projectedCoordSystem", "epsg:32611"), ("geographicCoordSystem", "epsg:4326")])
        conn.execute("INSERT INTO gpkg_contents (table_name, data_type, identifier) VALUES ('meta', 'attributes', "
                     "'meta')")
    for layer, (geometry_type, columns, rows) in map_features().items():
        if layer in skip_layers:
            continue
        column_sql = "".join(f", {name} {sql_type}" for name, sql_type in columns)
        conn.execute(f"CREATE TABLE {layer} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom {geometry_type}"
                     f"{column_sql})")
        conn.execute("INSERT INTO gpkg_geometry_columns VALUES (?,?,?,?,0,0)", (layer, "geom", geometry_type, srs_id))
        conn.execute("INSERT INTO gpkg_contents (table_name, data_type, identifier, srs_id) VALUES (?,?,?,?)",
                     (layer, "features", layer, srs_id))
        for row in rows:
            geometry = _to_lonlat(row["geom"]) if lonlat else row["geom"]
            names = ["fid", "geom"] + [name for name, _ in columns]
            values = [row["fid"], gpkg_blob(geometry, srs_id, envelope=geometry_type != "POINT")]
            values += [row.get(name) for name, _ in columns]
            conn.execute(f"INSERT INTO {layer} ({','.join(names)}) VALUES ({','.join('?' * len(names))})", values)
    conn.commit()
    conn.close()
    return path


@dataclasses.dataclass(frozen=True)
class NuplanFixture:
    db_path: Path
    maps_root: Path
    map_path: Path


def write_fixture(root: Path, lonlat: bool = False, skip_tables: tuple = (), skip_layers: tuple = ()
                  ) -> NuplanFixture:
    """A log DB under splits/mini and its map under maps/<location>/<version>/map.gpkg."""
    maps_root = root / "maps"
    maps_root.mkdir(parents=True, exist_ok=True)
    (maps_root / "nuplan-maps-v1.0.json").write_text(json.dumps({LOCATION: {"version": MAP_VERSION_DIR,
                                                                            "layers": {}}}))
    map_path = write_gpkg(maps_root / LOCATION / MAP_VERSION_DIR / "map.gpkg", lonlat, skip_layers)
    db_path = write_log_db(root / "nuplan-v1.1" / "splits" / "mini" / f"{LOG_NAME}.db", skip_tables=skip_tables)
    return NuplanFixture(db_path, maps_root, map_path)
