"""The bulk parse (states and map points decoded from their bytes with numpy) gives the regular parse's values,
whatever the layout of each message."""

from __future__ import annotations

import numpy as np
import pytest

from scenariomax.sources.womd import bulk, proto


def _states() -> list:
    rng = np.random.default_rng(0)
    full = [proto.ObjectStateProto(center_x=x, center_y=-x, center_z=0.5, length=4.5, width=1.9, height=1.6,
                                   heading=0.3, velocity_x=3.0, velocity_y=-1.0, valid=True)
            for x in rng.normal(size=5) * 1e4]
    return full + [
        proto.ObjectStateProto(center_z=-1e-4, valid=False),  # Waymo's invalid state
        proto.ObjectStateProto(center_z=2.0, valid=True),  # z-only but valid
        proto.ObjectStateProto(center_x=1.0, valid=True),  # fields missing
        proto.ObjectStateProto(),  # nothing set
        proto.ObjectStateProto(center_x=0.0, center_y=0.0, center_z=0.0, length=0.0, width=0.0, height=0.0,
                               heading=0.0, velocity_x=0.0, velocity_y=0.0, valid=False),  # zeros, present
    ]


def test_state_table_is_the_regular_parse():
    states = _states()
    data = [s.SerializeToString() for s in states]
    data.append(data[0] + proto.ObjectStateProto(valid=False).SerializeToString())  # a field repeated: last wins
    want = [bulk._STATE_GETTER(proto.ObjectStateProto.FromString(d)) for d in data]
    np.testing.assert_array_equal(bulk.state_table(data), np.array(want, np.float64))


def test_point_table_is_the_regular_parse():
    points = [proto.MapPointProto(x=1.5, y=-2.0, z=0.25), proto.MapPointProto(x=3.0, y=4.0),
              proto.MapPointProto(), proto.MapPointProto(x=-1e6, y=1e6, z=0.0)]
    data = [p.SerializeToString() for p in points] + [b""]  # b"": an unset stop-sign position
    want = [bulk._POINT_GETTER(proto.MapPointProto.FromString(d)) for d in data]
    np.testing.assert_array_equal(bulk.point_table(data), np.array(want, np.float64))
    assert bulk.point_table([]).shape == (0, 3)


@pytest.mark.parametrize("table", [bulk.state_table, bulk.point_table])
def test_bytes_that_are_no_message_fail_with_one_line(table):
    with pytest.raises(ValueError, match="not a WOMD Scenario message"):
        table([b"\x09\x01"])  # a double cut short


def test_light_arrays_keep_the_last_report_of_a_lane_in_a_step():
    from scenariomax import schema as sch
    from scenariomax.sources.womd.convert import traffic_light_arrays

    message = proto.ScenarioProto()
    for step in range(3):
        dynamic = message.dynamic_map_states.add()
        for lane, state in ((5, 3), (2, 99), (5, 4)):  # lane 5 twice; 99 is no light state
            report = dynamic.lane_states.add(lane=lane, state=state)
            report.stop_point.x, report.stop_point.y, report.stop_point.z = step + lane, 1.5, -2.0
    message.dynamic_map_states.add()  # a step without reports
    arrays = traffic_light_arrays(message, 0, 5)
    np.testing.assert_array_equal(arrays["tl_state"], [[sch.TL_UNKNOWN] * 3 + [0, 0], [4, 4, 4, 0, 0]])
    np.testing.assert_array_equal(arrays["tl_valid"], [[True] * 3 + [False] * 2] * 2)
    np.testing.assert_array_equal(arrays["tl_lane_id"], [[2, 2, 2, -1, -1], [5, 5, 5, -1, -1]])
    np.testing.assert_array_equal(arrays["tl_x"][1], [5, 6, 7, -1, -1])


def _bulk_class(name: str):
    return proto._message_class(name, proto._BULK_POOL, proto._BULK_PACKAGE)


def _map_features() -> tuple[list[bytes], list[bool]]:
    """Serialised MapFeatures in Waymo's layout and in others, and whether each is Waymo's (decoded by run)."""
    feature, lane, line, edge, polygon = (_bulk_class(name) for name in
                                          ("MapFeature", "LaneCenter", "RoadLine", "RoadEdge", "Crosswalk"))
    point = proto.MapPointProto
    xyz = [point(x=1.5 + k, y=-2.0 * k, z=0.25 * k).SerializeToString() for k in range(4)]
    out = [
        (feature(id=1, lane=lane(speed_limit_mph=25.0, type=2, interpolating=True, polyline=xyz, entry_lanes=[3],
                                 exit_lanes=[4, 5])).SerializeToString(), True),
        (feature(id=2 ** 40, road_line=line(type=6, polyline=xyz[:3])).SerializeToString(), True),
        (feature(id=3, road_edge=edge(polyline=xyz[1:])).SerializeToString(), True),  # no type field
        (feature(crosswalk=polygon(polygon=xyz)).SerializeToString(), True),  # no id
        (feature(id=4, lane=lane(type=1)).SerializeToString(), True),  # no points
        # Not Waymo's layout: each must fall back to the regular parse.
        (feature(id=5, lane=lane(polyline=[point(x=1.0, y=2.0).SerializeToString()] * 2)).SerializeToString(),
         False),  # z unset: 18-byte points
        (feature(id=6, road_line=line(polyline=[xyz[0], point(x=7.0).SerializeToString() + xyz[1]])
                 ).SerializeToString(), False),  # a field twice: 36 bytes, the last value wins
        (feature(id=7, road_edge=edge(polyline=[point(y=2.0).SerializeToString() + point(x=1.0, z=3.0)
                                                .SerializeToString()])).SerializeToString(), False),  # y before x
        (feature(road_line=line(polyline=xyz[:2])).SerializeToString() + feature(id=8).SerializeToString(),
         False),  # id after the geometry
        (feature(id=9, road_edge=edge(type=1, polyline=xyz[:2])).SerializeToString()
         + feature(road_edge=edge(polyline=xyz[2:])).SerializeToString(), False),  # geometry in two parts
        (feature(id=10).SerializeToString()  # a header field between the points
         + _field_bytes(3, lane(polyline=xyz[:2]).SerializeToString() + lane(type=1).SerializeToString()
                        + lane(polyline=xyz[2:]).SerializeToString()), False),
        (feature(id=11, lane=lane(speed_limit_mph=30.0, polyline=xyz)).SerializeToString()
         + _field_bytes(99, b"x"), False),  # an unknown field after the geometry
        (feature(id=12, stop_sign=_bulk_class("StopSign")(lane=[1], position=xyz[0])).SerializeToString(), False),
    ]
    return [data for data, _ in out], [waymo for _, waymo in out]


def _field_bytes(number: int, payload: bytes) -> bytes:
    """A length-delimited field (number < 2048, payload < 16384 bytes)."""
    tag = (number << 3) | 2
    head = bytes([tag]) if tag < 0x80 else bytes([(tag & 0x7F) | 0x80, tag >> 7])
    size = len(payload)
    return head + (bytes([size]) if size < 0x80 else bytes([(size & 0x7F) | 0x80, size >> 7])) + payload


def test_map_points_decoded_by_run_are_the_regular_parse():
    from scenariomax.sources.womd.convert import map_polylines, parse_raw_scenario, parse_scenario

    features, waymo = _map_features()
    data = proto.ScenarioRawProto(map_features=features).SerializeToString()
    raw = list(parse_raw_scenario(data).map_features)
    assert raw == features
    regular, links = map_polylines(parse_scenario(data), orient_edges=False)
    fast, fast_links = map_polylines(parse_scenario(data, bulk=True), orient_edges=False, raw_features=raw)
    assert [line.feature_id for line in fast] == [line.feature_id for line in regular]
    assert len(regular) == len(features) - 1  # every feature but the lane without points
    for want, got in zip(regular, fast):
        np.testing.assert_array_equal(got.xyz, want.xyz)
        assert got.xyz.dtype == want.xyz.dtype and got.xyz.shape == want.xyz.shape
    assert [vars(link) for link in fast_links] == [vars(link) for link in links]
    # The run decoder took exactly Waymo's layouts (the others went to the regular parse).
    message = parse_scenario(data, bulk=True)
    counts = []
    for feature in message.map_features:
        kind = feature.WhichOneof("feature_data")
        geometry = getattr(feature, kind)
        counts.append(1 if kind == "stop_sign" else len(geometry.polygon if kind == "crosswalk" else geometry.polyline))
    decoded = bulk.feature_points(raw, counts)
    assert [xyz is not None for xyz in decoded] == waymo


def test_map_points_of_cut_features_fall_back():
    features, _ = _map_features()
    for data in features[:4]:
        for cut in (1, 2, 5, len(data) - 1):
            assert bulk.feature_points([data[:cut]], [4])[0] is None


def test_lane_state_table_is_the_regular_parse():
    state_class = proto.TrafficSignalLaneStateProto
    point = proto.MapPointProto
    reports = [state_class(lane=lane, state=4, stop_point=point(x=1.5, y=-2.5, z=0.125))
               for lane in (1, 127, 128, 300, 2 ** 21, 2 ** 40, 2 ** 63 - 1, -5)]  # 1..9 varint bytes; -5: 10
    reports += [
        state_class(lane=7, state=200, stop_point=point(x=1.0, y=2.0, z=3.0)),  # a state of two bytes
        state_class(lane=7, state=3, stop_point=point(x=1.0, y=2.0)),  # stop point without z
        state_class(lane=7, state=3),  # no stop point
        state_class(state=3, stop_point=point(x=1.0, y=2.0, z=3.0)),  # lane 0: not written
        state_class(),
    ]
    data = [report.SerializeToString() for report in reports]
    data.append(state_class(stop_point=point(x=9.0, y=8.0, z=7.0)).SerializeToString()
                + state_class(lane=12, state=5).SerializeToString())  # stop point first: 36 bytes, another order
    data.append(b"\x08\x85\x00\x10\x01" + data[0][-29:])  # lane 5 as a two-byte varint: 34 bytes, Waymo's order
    data.append(b"\x08\x07\x18\x05" + data[0][-29:])  # field 3 (unknown) where the state goes: Waymo's length
    data.append(b"\x08\x07\x10\x05\x1a\x1b" + data[0][-27:].replace(b"\x11", b"\x19", 1))  # y's tag on a z
    want = [bulk._LANE_STATE_GETTER(state_class.FromString(d)) for d in data]
    lane, code, stop = bulk.lane_state_table(data)
    np.testing.assert_array_equal(lane, [w[0] for w in want])
    np.testing.assert_array_equal(code, [w[1] for w in want])
    np.testing.assert_array_equal(stop, [w[2:] for w in want])
    assert lane.dtype == code.dtype == np.int64
    assert [len(array) for array in bulk.lane_state_table([])] == [0, 0, 0]
    with pytest.raises(ValueError, match="not a WOMD Scenario message"):
        bulk.lane_state_table([data[0][:-3]])


def test_light_arrays_of_the_bulk_parse_are_the_regular_ones():
    from scenariomax.sources.womd.convert import parse_scenario, traffic_light_arrays

    message = proto.ScenarioProto()
    for step in range(4):
        dynamic = message.dynamic_map_states.add()
        for lane, state in ((300, 3), (2, 99), (300, 4), (2 ** 40, 5)):
            report = dynamic.lane_states.add(lane=lane, state=state)
            report.stop_point.x, report.stop_point.y = step + lane, 1.5
            if step != 2:
                report.stop_point.z = -2.0
    message.dynamic_map_states.add()
    data = message.SerializeToString()
    want = traffic_light_arrays(parse_scenario(data), 1, 4)
    got = traffic_light_arrays(parse_scenario(data, bulk=True), 1, 4)
    assert want.keys() == got.keys()
    for key in want:
        np.testing.assert_array_equal(got[key], want[key])
        assert got[key].dtype == want[key].dtype


def _tracks_message(odd: str = "") -> bytes:
    """A Scenario of three tracks, 5 steps each, in Waymo's layout (full states, z-only invalid ones) unless
    `odd` names a change."""
    import struct

    message = proto.ScenarioProto()
    message.timestamps_seconds.extend([0.1 * k for k in range(5)])
    tricky = struct.unpack("<d", b"\x1a\x3b\x11\x00\x00\x00\xf0\x3f")[0]  # bytes that look like a state's start
    for index, (track_id, kind) in enumerate(((3, 1), (2 ** 30, 2), (0, 0))):
        track = message.tracks.add(id=track_id, object_type=kind)
        for k in range(5):
            if (k + index) % 3 == 0:
                track.states.add(center_z=-1e-4 * k, valid=False)  # Waymo's invalid state
            else:
                track.states.add(center_x=1e4 * k + index, center_y=-k, center_z=0.5, length=4.5, width=1.9,
                                 height=1.6, heading=0.3 * k, velocity_x=3.0, velocity_y=-1.0, valid=True)
    if odd == "tricky value":
        message.tracks[1].states[1].center_x = tricky
    elif odd == "field unset":
        message.tracks[2].states[3].ClearField("velocity_y")
    elif odd == "valid z only":
        message.tracks[0].states[0].valid = True
    data = message.SerializeToString()
    if odd == "fields reordered":  # a state of Waymo's size whose width comes before its length
        track_class = proto._message_class("Track", proto._BULK_POOL, proto._BULK_PACKAGE)
        state = proto.ObjectStateProto
        track = track_class.FromString(proto.ScenarioRawProto.FromString(data).tracks[1])
        track.states[0] = (state(center_x=1.0, center_y=2.0, center_z=3.0, width=1.5).SerializeToString()
                           + state(length=4.0, height=1.2, heading=0.1, velocity_x=1.0, velocity_y=2.0,
                                   valid=True).SerializeToString())
        assert len(track.states[0]) == 59
        tracks = list(proto.ScenarioRawProto.FromString(data).tracks)
        tracks[1] = track.SerializeToString()
        data = (proto.ScenarioProto(timestamps_seconds=message.timestamps_seconds).SerializeToString()
                + b"".join(_field_bytes(2, track) for track in tracks))
    if odd == "type first":  # object_type before id in track 0: not Waymo's order
        track_class = proto._message_class("Track", proto._BULK_POOL, proto._BULK_PACKAGE)
        tracks = list(proto.ScenarioRawProto.FromString(data).tracks)
        tracks[0] = track_class(object_type=1).SerializeToString() + tracks[0]  # merged: type 1 twice, then id
        data = (proto.ScenarioProto(timestamps_seconds=message.timestamps_seconds).SerializeToString()
                + b"".join(_field_bytes(2, track) for track in tracks))
    return data


@pytest.mark.parametrize("odd, by_track", [("", True), ("tricky value", False), ("valid z only", True),
                                           ("field unset", False), ("type first", False),
                                           ("fields reordered", False)])
def test_track_states_decoded_by_track_are_the_regular_parse(odd, by_track):
    from scenariomax.sources.womd.convert import parse_raw_scenario, parse_scenario, track_arrays

    data = _tracks_message(odd)
    raw = parse_raw_scenario(data)
    want = track_arrays(parse_scenario(data))
    got = track_arrays(parse_scenario(data, bulk=True), raw.tracks)
    assert want.keys() == got.keys()
    for key in want:
        np.testing.assert_array_equal(got[key], want[key])
    decoded = bulk.track_state_table(list(raw.tracks), 5)
    assert (decoded is not None) == by_track
    assert bulk.track_state_table(list(raw.tracks), 4) is None  # not the number of states the tracks hold
