"""Hand-worked checks of the nuPlan helpers: projection, ego geometry, windows, GeoPackage blobs."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
import shapely

from scenariomax import schema as sch
from scenariomax.sources.nuplan import ego, utm
from scenariomax.sources.nuplan.geopackage import geometry_wkb
from scenariomax.sources.nuplan.log_db import light_state, nearest_pose_index
from scenariomax.sources.nuplan.windows import scenario_anchors, stride_anchors, window_indices
from tests.sources.nuplan.builders import gpkg_blob


def test_utm_on_the_central_meridian():
    # meridian arc to 45 deg N on WGS 84 is 4 984 944.378 m; UTM scales it by 0.9996
    east, north = utm.lonlat_to_utm(np.array([-117.0, -117.0]), np.array([0.0, 45.0]), zone=11)
    np.testing.assert_allclose(east, 500_000.0, atol=1e-6)
    np.testing.assert_allclose(north, [0.0, 0.9996 * 4_984_944.378], atol=2e-3)
    _, south = utm.lonlat_to_utm(np.array([-117.0]), np.array([-45.0]), zone=11, is_north=False)
    np.testing.assert_allclose(south, 10_000_000.0 - 0.9996 * 4_984_944.378, atol=2e-3)


def test_utm_is_symmetric_about_the_central_meridian():
    east, north = utm.lonlat_to_utm(np.array([-118.0, -116.0]), np.array([36.0, 36.0]), zone=11)
    assert east[0] - 500_000 == pytest.approx(500_000 - east[1], abs=1e-6)
    assert north[0] == pytest.approx(north[1], abs=1e-6)


def test_epsg_parsing():
    assert utm.parse_epsg("EPSG:32611") == 32611 and utm.parse_epsg("epsg: 32648") == 32648
    assert utm.parse_epsg("+proj=utm") is None
    assert utm.utm_epsg_zone(32619) == (19, True) and utm.utm_epsg_zone(32733) == (33, False)
    assert utm.utm_epsg_zone(4326) is None


def test_quaternion_yaw_and_rear_axle_offset():
    half = math.pi / 4  # 90 deg about z: (cos 45, 0, 0, sin 45)
    assert ego.quaternion_yaw(math.cos(half), 0.0, 0.0, math.sin(half)) == pytest.approx(math.pi / 2)
    assert ego.quaternion_yaw(1.0, 0.0, 0.0, 0.0) == pytest.approx(0.0)
    x, y = ego.rear_axle_to_center(np.array(10.0), np.array(20.0), np.array(math.pi / 2))
    assert (float(x), float(y)) == pytest.approx((10.0, 21.461))


def test_centre_velocity_includes_yaw_rate_lever_arm():
    # heading north, rear axle at 2 m/s forward, turning left at 1 rad/s: the centre also moves
    # 1.461 m/s to the left (west)
    vx, vy = ego.center_velocity_global(np.array(2.0), np.array(0.0), np.array(1.0), np.array(math.pi / 2))
    assert (float(vx), float(vy)) == pytest.approx((-1.461, 2.0))


def test_wrap_angle():
    np.testing.assert_allclose(ego.wrap_angle(np.array([2 * math.pi + 0.1, -3.5, 3.0])),
                               [0.1, -3.5 + 2 * math.pi, 3.0], atol=1e-12)


def test_window_indices_every_other_lidar_pc():
    steps = window_indices(anchor=30, num_lidar_pcs=100)
    assert steps[10] == 30 and steps[0] == 10 and steps[11] == 32
    assert steps[44] == 98 and steps[45] == -1  # 30 + 2 * 35 = 100 is past the end of the log
    assert (window_indices(anchor=4, num_lidar_pcs=100)[:8] == -1).all()


def test_scenario_anchors():
    assert stride_anchors(240, 20) == [20, 60]  # last full window starts at 240 - 1 - 160 = 79
    assert stride_anchors(100, 80) == [20]  # too short for a full window: one partial scenario
    assert stride_anchors(15, 80) == []
    assert scenario_anchors(240, [60, 40, 60], None) == [40, 60]
    assert scenario_anchors(240, [], None) == [20]
    assert scenario_anchors(240, [41], 20) == [20, 41, 60]


def test_nearest_pose_index_respects_the_gap():
    poses = np.array([0, 100_000, 200_000], np.int64)
    queries = np.array([40_000, 60_000, 200_000, 460_000], np.int64)
    np.testing.assert_array_equal(nearest_pose_index(poses, queries), [0, 1, 2, -1])
    np.testing.assert_array_equal(nearest_pose_index(poses[:0], queries), [-1, -1, -1, -1])


def test_light_status_mapping():
    assert [light_state(s) for s in ("green", "red", "yellow", "unknown", "GREEN ", None)] == [
        sch.TL_GO, sch.TL_STOP, sch.TL_CAUTION, sch.TL_UNKNOWN, sch.TL_GO, sch.TL_UNKNOWN]


@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("envelope", [False, True])
def test_geopackage_header_is_stripped(big_endian, envelope):
    line = shapely.LineString([(1.5, 2.0), (3.0, 4.5)])
    blob = gpkg_blob(line, 4326, big_endian=big_endian, envelope=envelope)
    assert len(blob) == 8 + (32 if envelope else 0) + len(shapely.to_wkb(line))
    assert shapely.from_wkb(geometry_wkb(blob)).equals(line)


def test_geopackage_header_xyz_envelope_and_bad_blobs():
    point = shapely.Point(1.0, 2.0)
    blob = b"GP" + bytes([0, 1 | (2 << 1)]) + struct.pack("<i", 4326) + struct.pack("<6d", *range(6))
    assert shapely.from_wkb(geometry_wkb(blob + shapely.to_wkb(point))).equals(point)
    for bad in (b"", b"XX\x00\x01\x00\x00\x00\x00", b"GP\x00\x0f\x00\x00\x00\x00" + b"\x00" * 16, blob):
        with pytest.raises(ValueError):
            geometry_wkb(bad)


def test_anchor_groups_bound_each_read_pass():
    from scenariomax.sources.nuplan.windows import anchor_groups

    assert anchor_groups([700, 20, 40, 620, 621]) == [[20, 40, 620], [621, 700]]
    assert anchor_groups([]) == []
