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
