"""Real nuPlan logs, when a sample is present under ../shared/realdata/nuplan/ (it is not shipped:
real logs are ~125 MB). The same independent-read checks also run on the generated fixture."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
import shapely

from scenariomax import Scenario, decode_scenario, encode_scenario
from scenariomax import schema as sch
from scenariomax.sources.nuplan import NuplanSource, find_map_file

REALDATA = Path(__file__).resolve().parents[3] / ".." / "shared" / "realdata"
REAR_AXLE_TO_CENTER_M = 1.461


def _raw_ego_centre(conn, time_micros: int) -> tuple[float, float]:
    """Independent read: the ego_pose nearest the sweep, moved from the rear axle to the box centre."""
    x, y, qw, qx, qy, qz = conn.execute(
        "SELECT x, y, qw, qx, qy, qz FROM ego_pose ORDER BY abs(timestamp - ?) LIMIT 1", (time_micros,)).fetchone()
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return x + REAR_AXLE_TO_CENTER_M * np.cos(yaw), y + REAR_AXLE_TO_CENTER_M * np.sin(yaw)


def _raw_lane_count(map_path: Path, box) -> int:
    """Lanes (with a baseline path) and lane connectors whose centreline bounds overlap the box."""
    conn = sqlite3.connect(map_path)
    srs = conn.execute("SELECT srs_id FROM gpkg_geometry_columns WHERE table_name = 'baseline_paths'").fetchone()[0]
    if srs == 4326:
        pytest.skip("independent lane count implemented for UTM-stored maps only")
    count = 0
    for blob, lane, connector in conn.execute("SELECT geom, lane_fid, lane_connector_fid FROM baseline_paths"):
        envelope = {0: 0, 1: 32, 2: 48, 3: 48, 4: 64}[(blob[3] >> 1) & 7]
        minx, miny, maxx, maxy = shapely.from_wkb(bytes(blob[8 + envelope:])).bounds
        overlaps = minx <= box[2] and maxx >= box[0] and miny <= box[3] and maxy >= box[1]
        count += bool(overlaps and (lane is not None or connector is not None))
    conn.close()
    return count


def check_against_raw(db_path: Path, maps_root: Path, max_scenarios: int = 3) -> None:
    source = NuplanSource(str(db_path), str(maps_root))
    items = list(source.read_unit(str(db_path)))
    scenarios = [s for s in items if isinstance(s, Scenario)][:max_scenarios]
    assert scenarios, f"no scenario converted from {db_path}: {items[:3]}"
    conn = sqlite3.connect(db_path)
    map_version = conn.execute("SELECT map_version FROM log").fetchone()[0]
    map_path = find_map_file(str(maps_root), map_version)
    for scenario in scenarios:
        assert scenario.validate() == []
        decoded = decode_scenario(encode_scenario(scenario))
        assert decoded.validate() == []
        np.testing.assert_array_equal(decoded.x[: scenario.num_objects], scenario.x)
        # window sweeps: every other lidar_pc around the anchor
        anchor_time = scenario.metadata["anchor_timestamp_micros"]
        times = [t for (t,) in conn.execute("SELECT timestamp FROM lidar_pc ORDER BY timestamp")]
        anchor = times.index(anchor_time)
        window = [times[anchor + 2 * (k - 10)] if 0 <= anchor + 2 * (k - 10) < len(times) else None
                  for k in range(91)]
        placeholders = ",".join("?" * sum(t is not None for t in window))
        num_tracks = conn.execute(
            "SELECT count(DISTINCT b.track_token) FROM lidar_box b JOIN lidar_pc p ON p.token = b.lidar_pc_token "
            f"JOIN track t ON t.token = b.track_token WHERE p.timestamp IN ({placeholders})",
            [t for t in window if t is not None]).fetchone()[0]
        assert scenario.num_objects == min(1 + num_tracks, sch.default_sizes().num_objects)
        sdc = scenario.sdc_index
        for k, t in enumerate(window):
            if t is not None and scenario.valid[sdc, k]:
                x, y = _raw_ego_centre(conn, t)
                # Positions are relative to a whole-metre world_origin, so millimetres survive float32.
                assert abs(scenario.x[sdc, k] + scenario.world_origin[0] - x) <= 1e-3
                assert abs(scenario.y[sdc, k] + scenario.world_origin[1] - y) <= 1e-3
        xs = scenario.x[sdc, scenario.valid[sdc]] + scenario.world_origin[0]
        ys = scenario.y[sdc, scenario.valid[sdc]] + scenario.world_origin[1]
        box = (xs.min() - 100.0, ys.min() - 100.0, xs.max() + 100.0, ys.max() + 100.0)
        lane_ids = set(scenario.roadgraph_id[np.isin(scenario.roadgraph_type, sch.LANE_TYPES)].tolist())
        raw_lanes = _raw_lane_count(map_path, box)
        if scenario.roadgraph_xyz.shape[0] < sch.default_sizes().num_roadgraph:
            assert len(lane_ids) == raw_lanes
        else:
            assert len(lane_ids) <= raw_lanes
    conn.close()


def test_independent_read_on_generated_fixture(nuplan_files):
    check_against_raw(nuplan_files.db_path, nuplan_files.maps_root)


def test_real_nuplan_log():
    folder = REALDATA / "nuplan"
    logs = sorted(folder.glob("*.db")) if folder.is_dir() else []
    if not logs or not (folder / "maps").is_dir():
        pytest.skip(f"no real nuPlan sample under {folder} (a *.db log and a maps/ folder; none is shipped "
                    "because real logs are ~125 MB)")
    check_against_raw(logs[0], folder / "maps")
