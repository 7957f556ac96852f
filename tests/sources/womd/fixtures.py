"""Tiny WOMD Scenario protos built by the tests, serialised in the real format (proto in TFRecord)."""

from __future__ import annotations

from pathlib import Path

from scenariomax.io.tfrecord import TFRecordWriter
from scenariomax.sources.womd.proto import ScenarioProto

LANE_ID, NEXT_LANE_ID, EDGE_ID, LINE_ID, CROSSWALK_ID, STOP_ID = 100, 101, 200, 300, 400, 500
SDC_TRACK_ID, OTHER_TRACK_ID = 7, 3


def _point(message, x, y, z=0.0):
    message.x, message.y, message.z = x, y, z


def build_scenario(num_steps: int = 91, scenario_id: str = "toy-womd", current_time_index: int = 10) -> bytes:
    """Two tracks: track 0 (id 3, pedestrian) and track 1 (id 7, the SDC, vehicle driving east at
    10 m/s along y = 0 with heading 3.5 rad stored unwrapped). The pedestrian is valid only at even
    steps. Map: an east-bound lane y = 0 (25 mph) and its successor, a road edge at y = -2 drawn
    WEST-bound (lane on its right: must be flipped), a road line, a 2 x 2 m crosswalk, a stop sign.
    A traffic light on the lane: STOP (4) at step 0..49, GO (6) afterwards, stop point (30, 0, 1)."""
    message = ScenarioProto()
    message.scenario_id = scenario_id
    message.current_time_index = current_time_index
    message.timestamps_seconds.extend([0.1 * k + 5.0 for k in range(num_steps)])
    pedestrian = message.tracks.add(id=OTHER_TRACK_ID, object_type=2)
    sdc = message.tracks.add(id=SDC_TRACK_ID, object_type=1)
    for k in range(num_steps):
        state = sdc.states.add(center_x=10.0 * 0.1 * k, center_y=0.0, center_z=1.0, length=4.5, width=2.0,
                               height=1.5, heading=3.5, velocity_x=10.0, velocity_y=0.0, valid=True)
        assert state.valid
        pedestrian.states.add(center_x=5.0, center_y=3.0 + 0.1 * k, center_z=0.5, length=0.5, width=0.5,
                              height=1.8, heading=1.5, velocity_x=0.0, velocity_y=1.0, valid=k % 2 == 0)
    message.sdc_track_index = 1
    message.objects_of_interest.append(OTHER_TRACK_ID)
    message.tracks_to_predict.add(track_index=0, difficulty=2)

    lane = message.map_features.add(id=LANE_ID).lane
    lane.speed_limit_mph = 25.0
    lane.type = 2
    for x in range(0, 41, 2):
        _point(lane.polyline.add(), float(x), 0.0)
    lane.exit_lanes.append(NEXT_LANE_ID)
    lane.right_neighbors.add(feature_id=999)
    next_lane = message.map_features.add(id=NEXT_LANE_ID).lane
    next_lane.type = 1
    for x in range(40, 61, 2):
        _point(next_lane.polyline.add(), float(x), 0.0)
    next_lane.entry_lanes.append(LANE_ID)
    edge = message.map_features.add(id=EDGE_ID).road_edge
    edge.type = 1
    for x in range(60, -1, -5):  # west-bound at y = -2: the lane (y = 0) lies on its RIGHT
        _point(edge.polyline.add(), float(x), -2.0)
    line = message.map_features.add(id=LINE_ID).road_line
    line.type = 7  # TYPE_SOLID_DOUBLE_YELLOW -> 12
    for x in (0.0, 3.0):
        _point(line.polyline.add(), x, 2.0)
    crosswalk = message.map_features.add(id=CROSSWALK_ID).crosswalk
    for x, y in ((20, -1), (22, -1), (22, 1), (20, 1)):
        _point(crosswalk.polygon.add(), float(x), float(y))
    stop = message.map_features.add(id=STOP_ID).stop_sign
    stop.lane.append(LANE_ID)
    _point(stop.position, 38.0, -1.5)

    for k in range(num_steps):
        step = message.dynamic_map_states.add()
        lane_state = step.lane_states.add(lane=LANE_ID, state=4 if k < 50 else 6)
        _point(lane_state.stop_point, 30.0, 0.0, 1.0)
    return message.SerializeToString()


def write_records(path: Path, records: list[bytes]) -> Path:
    with TFRecordWriter(path) as writer:
        for record in records:
            writer.write(record)
    return path
