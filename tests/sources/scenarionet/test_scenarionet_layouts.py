"""Every layout the MetaDrive / ScenarioNet / UniTraj writers have produced, built here from the format
(what their converters wrote, docs/datasets.md), plus the window rules for short and early-current logs."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES, Failure
from scenariomax.sources.scenarionet import ScenarioNetSource, loads_restricted
from scenariomax.sources.womd.windows import log_window_starts, window_steps
from tests.sources.scenarionet.fixtures import build_description, write_pickle


def convert(tmp_path, desc, name="sd_case.pkl") -> list:
    return list(ScenarioNetSource(str(write_pickle(tmp_path / name, desc))).read_unit(str(tmp_path / name)))


def scenarios(items) -> list[Scenario]:
    failures = [item.reason for item in items if isinstance(item, Failure)]
    assert not failures, failures
    return items


def _drive(num_steps: int):
    """Ego along y = 0 at 2 m/s, one pedestrian standing at (5, 3): (T,) time and both positions."""
    t = np.arange(num_steps) * 0.1
    ego = np.stack([2 * t, 0 * t, 0 * t], 1).astype(np.float32)
    ped = np.stack([5 + 0 * t, 3 + 0 * t, 0 * t], 1).astype(np.float32)
    return t, ego, ped


LANE = {"type": "LANE_SURFACE_STREET", "polyline": np.array([[float(x), 0.0, 0.0] for x in range(0, 101, 5)])}


# --- MetaDrive, March-April 2023: one `size` (T, 3), heading and valid (T, 1) --------------------------
def sized_description(num_steps: int = 91, flat: bool = False) -> dict:
    t, ego, ped = _drive(num_steps)

    def state(position, size, heading):
        return {"position": position, "size": np.tile(np.float32(size), (num_steps, 1)),
                "heading": np.full((num_steps, 1), heading, np.float32),
                "velocity": np.tile(np.float32([2.0, 0.0]) if heading == 0 else np.float32([0, 0]), (num_steps, 1)),
                "valid": np.ones((num_steps, 1), bool)}

    tracks = {"100": {"type": "VEHICLE", "state": state(ego, (4.5, 2.0, 1.5), 0.0)},
              "101": {"type": "PEDESTRIAN", "state": state(ped, (0.5, 0.5, 1.8), 1.0)}}
    if flat:  # the March 2023 "old format": the state's fields on the track itself
        tracks = {key: {"type": track["type"], **track["state"]} for key, track in tracks.items()}
    return {"id": "sized", "version": "2023-03", "ts": list(t), "sdc_track_index": 100, "tracks": tracks,
            "map_features": {"1": dict(LANE)}, "dynamic_map_states": {}}


def test_size_instead_of_length_width_height(tmp_path):
    (scenario,) = scenarios(convert(tmp_path, sized_description()))
    sdc = scenario.sdc_index
    assert scenario.object_id[sdc] == 100 and scenario.valid.all()
    np.testing.assert_allclose([scenario.length[sdc, 10], scenario.width[sdc, 10], scenario.height[sdc, 10]],
                               [4.5, 2.0, 1.5])
    np.testing.assert_allclose(scenario.bbox_yaw[1 - sdc, 10], 1.0, atol=1e-6)


def test_flat_old_format_tracks_with_a_self_referencing_speed_bump(tmp_path):
    desc = sized_description(flat=True)
    desc["sdc_track_index"] = "100"  # the old format wrote the SDC's id as a string
    desc["dynamic_map_states"] = [{}]  # a list: no light states in that format
    bump = {"polygon": np.array([[30.0, -1, 0], [31, -1, 0], [31, 1, 0], [30, 1, 0]])}
    bump["type"] = bump  # what MetaDrive's converter wrote for a speed bump
    desc["map_features"].update({
        "2": bump,
        "3": {"sign": "cross_walk", "polygon": np.array([[20.0, -1, 0], [22, -1, 0], [22, 1, 0], [20, 1, 0]])},
        "4": {"type": "stop_sign", "lanes": [1], "pos": [50.0, 0.0, 0.0]},
        "5": {"type": "center_lane", "polyline": np.array([[0.0, 4, 0], [100, 4, 0]]), "entry": [], "exit": [1]},
    })
    (scenario,) = scenarios(convert(tmp_path, desc))
    types = set(scenario.roadgraph_type[scenario.roadgraph_valid].tolist())
    assert {sch.RG_SPEED_BUMP, sch.RG_CROSSWALK, sch.RG_STOP_SIGN, sch.RG_LANE_SURFACE_STREET} <= types
    np.testing.assert_allclose(scenario.length[scenario.sdc_index, 0], 4.5)


def test_march_2023_type_names(tmp_path):
    """MetaDrive's March 2023 converter named WOMD type 0 "UNKNOWN" for lanes, road lines and road edges
    alike, and the solid double white line "ROAD_LINE_DOUBLE_WHITE"."""
    desc = sized_description(flat=True)
    line = np.array([[0.0, 2, 0], [100, 2, 0]])
    desc["map_features"].update({
        "2": {"type": "UNKNOWN", "polyline": np.array([[0.0, 4, 0], [100, 4, 0]]), "speed_limit_mph": 25.0,
              "entry_lanes": [], "exit_lanes": [], "left_boundaries": [], "right_boundaries": []},
        "3": {"type": "ROAD_LINE_DOUBLE_WHITE", "polyline": line},
        "4": {"type": "UNKNOWN", "polyline": line + [0, 4, 0]},
    })
    (scenario,) = scenarios(convert(tmp_path, desc))
    valid = scenario.roadgraph_valid
    ids, types = scenario.roadgraph_id[valid], scenario.roadgraph_type[valid]
    assert set(types[ids == 2].tolist()) == {sch.RG_LANE_SURFACE_STREET}
    assert set(types[ids == 3].tolist()) == {sch.RG_SOLID_DOUBLE_WHITE}
    assert set(types[ids == 4].tolist()) == {0}


def test_2021_state_array_and_map_key(tmp_path):
    """MetaDrive 2021-2022: one (T, 10) array [x, y, z, length, width, height, heading, vx, vy, valid] per
    track, the map under `map`, the SDC's id as `sdc_index` (the enum members those files also pickled are in
    test_scenarionet_metadrive_2021.py)."""
    t, ego, ped = _drive(91)

    def rows(position, size, heading, speed):
        n = len(position)
        return np.concatenate([position, np.tile(size, (n, 1)), np.full((n, 1), heading),
                               np.tile([speed, 0.0], (n, 1)), np.ones((n, 1))], axis=1)

    desc = {"id": "array", "ts": list(t), "sdc_index": 7, "map": {"1": dict(LANE)},
            "tracks": {7: {"type": "VEHICLE", "state": rows(ego, (4.5, 2.0, 1.5), 0.0, 2.0)},
                       8: {"type": "PEDESTRIAN", "state": rows(ped, (0.5, 0.5, 1.8), 0.0, 0.0)}},
            "dynamic_map_states": [{}]}
    (scenario,) = scenarios(convert(tmp_path, desc))
    sdc = scenario.sdc_index
    assert scenario.object_id[sdc] == 7
    np.testing.assert_allclose(scenario.x[sdc, 10], 2.0, atol=1e-5)
    np.testing.assert_allclose(scenario.velocity_x[sdc, 10], 2.0)


def test_scenario_description_dict_subclass(tmp_path):
    """MetaDrive pickled its ScenarioDescription (a dict subclass) for a few days in March 2023: the class
    is named in the file, built with NEWOBJ and no arguments, then filled as a dict."""
    data = pickle.dumps(build_description(num_steps=91, step_seconds=0.1), protocol=2)
    assert data[2:3] == b"}"  # EMPTY_DICT: the root, swapped for the subclass
    data = (data[:2] + b"cmetadrive.scenario.scenario_description\nScenarioDescription\n)\x81" + data[3:])
    loaded = loads_restricted(data)
    assert type(loaded) is dict and loaded["id"] == "toy-sn"
    (tmp_path / "sd_subclass.pkl").write_bytes(data)
    path = str(tmp_path / "sd_subclass.pkl")
    assert len(scenarios(list(ScenarioNetSource(path).read_unit(path)))) == 1


def test_newobj_of_anything_else_is_still_refused():
    from scenariomax.sources.scenarionet import RefusedGlobalError

    data = b"\x80\x02cmetadrive.scenario.scenario_description\nScenarioDescription\nK\x01\x85\x81."
    with pytest.raises(RefusedGlobalError, match="NEWOBJ"):
        loads_restricted(data)  # arguments to the class: not the dict the writer made


def test_heading_theta_single_size_and_missing_velocity(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    state = desc["tracks"]["ped-a"]["state"]
    state["heading_theta"] = state.pop("heading")
    for name in ("length", "width", "height"):
        del state[name]
    state["size"] = np.array([0.6, 0.5, 1.7])  # one size for the whole track
    del state["velocity"]
    (scenario,) = scenarios(convert(tmp_path, desc))
    ped = scenario.object_id.tolist().index(2)
    np.testing.assert_allclose(scenario.height[ped, 10], 1.7)
    np.testing.assert_allclose(scenario.bbox_yaw[ped, 10], np.pi / 2, atol=1e-5)


# --- windows -------------------------------------------------------------------------------------------
def test_log_window_starts():
    assert log_window_starts(91, 10) == [0]
    assert log_window_starts(199, 10) == [0, 80]
    assert log_window_starts(199, 0) == [0, 80]  # history before step 0 cannot fit: start at 0
    assert log_window_starts(81, 20) == [10]  # UniTraj: 21 past + 60 future, one padded window
    assert log_window_starts(81, 0) == [0]
    assert log_window_starts(5, 0) == [-10]  # shorter than the history: padded before the log
    assert log_window_starts(91, 91) == [] and log_window_starts(0, 0) == []
    values = np.arange(6, dtype=float).reshape(1, 6)
    np.testing.assert_array_equal(window_steps(values, -2, 5, -1.0), [[-1, -1, 0, 1, 2]])
    np.testing.assert_array_equal(window_steps(values, 4, 4, -1.0), [[4, 5, -1, -1]])


def test_current_time_index_zero_in_a_20s_log(tmp_path):
    """ScenarioNet's 20 s WOMD databases say current_time_index 0: the SDC is valid, the history is not
    there; windows start at log step 0 (current step 10) and the move is noted."""
    desc = build_description(num_steps=199, step_seconds=0.1, scenario_id="twenty")
    desc["metadata"]["current_time_index"] = 0
    first, second = scenarios(convert(tmp_path, desc))
    assert (first.scenario_id, second.scenario_id) == ("twenty_t000", "twenty_t080")
    assert first.metadata[MANIFEST_NOTES]["current_step_moved"] == {"log": 0, "window": 10}
    assert MANIFEST_NOTES not in second.metadata or "current_step_moved" not in second.metadata[MANIFEST_NOTES]
    assert not first.tracks_to_predict.any()  # the labels belong to the log's own current step


def test_short_unitraj_log_is_one_padded_scenario(tmp_path):
    """81 steps (UniTraj's 2.1 s + 6 s nuScenes windows, current step 20): one scenario, the 20 steps after
    the log's end invalid, noted in the manifest."""
    desc = build_description(num_steps=81, step_seconds=0.1, scenario_id="unitraj")
    desc["metadata"]["current_time_index"] = 20
    (scenario,) = scenarios(convert(tmp_path, desc))
    assert scenario.scenario_id == "unitraj" and scenario.metadata["log_start_step"] == 10
    sdc = scenario.sdc_index
    assert scenario.valid[sdc, :71].all() and not scenario.valid[:, 71:].any()
    assert (scenario.x[:, 71:] == -1).all() and (scenario.timestamp_micros[:, 71:] == -1).all()
    np.testing.assert_allclose(scenario.x[sdc, 10], 2 * 2.0, atol=1e-5)  # log step 20 = 2 s
    assert scenario.metadata[MANIFEST_NOTES]["steps_padded"] == 20
    assert scenario.tracks_to_predict.any()  # its current step is the log's
    assert not scenario.tl_valid[:, 71:].any()


def test_log_shorter_than_the_history(tmp_path):
    desc = build_description(num_steps=5, step_seconds=0.1, scenario_id="tiny")
    del desc["metadata"]["timestep"]
    (scenario,) = scenarios(convert(tmp_path, desc))
    notes = scenario.metadata[MANIFEST_NOTES]
    # no current_time_index: the current step is log step 3 (one step follows it), 7 history steps before the log
    assert notes["history_padded"] == 7 and notes["steps_padded"] == 79 and notes["log_steps"] == 5
    sdc = scenario.sdc_index
    assert scenario.valid[sdc, 7:12].all() and not scenario.valid[sdc, :7].any() and not scenario.valid[sdc, 12:].any()


def test_one_step_log_names_the_cause(tmp_path):
    desc = build_description(num_steps=5, step_seconds=0.1, scenario_id="one")
    for track in desc["tracks"].values():
        track["state"] = {name: np.asarray(value)[:1] for name, value in track["state"].items()}
    (item,) = convert(tmp_path, desc)
    assert isinstance(item, Failure) and "1 step at 10 Hz: nothing follows the current step" in item.reason


def test_sdc_never_valid_at_a_current_step_names_the_sdc(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1, scenario_id="gone")
    desc["tracks"]["ego"]["state"]["valid"][5:] = 0.0
    (item,) = convert(tmp_path, desc)
    assert isinstance(item, Failure)
    assert "the SDC (track ego) is not valid at the current step of any window (log step 10)" in item.reason
    assert "valid on 5 of 91 steps at 10 Hz (steps 0-4)" in item.reason


def test_current_time_index_outside_the_log_is_ignored_and_noted(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["metadata"]["current_time_index"] = 500
    (scenario,) = scenarios(convert(tmp_path, desc))
    assert "outside the log's 91 steps" in scenario.metadata[MANIFEST_NOTES]["current_time_index_ignored"]


def test_real_20s_pickle_with_current_time_index_zero(tmp_path):
    """A real 20 s WOMD description (read in place) given ScenarioNet's current_time_index 0: the same
    windows as without it, every SDC step valid."""
    from scenariomax.sources.scenarionet import load_pickle
    from tests.conftest import realdata_file

    desc = load_pickle(realdata_file("scenarionet/womd_20s/0.pkl"))
    desc["metadata"]["current_time_index"] = 0
    items = scenarios(convert(tmp_path, desc, name="zero.pkl"))
    assert [s.metadata["log_start_step"] for s in items] == [0, 80]
    assert all(s.valid[s.sdc_index].all() for s in items)


# --- MetaDrive exports since April 2023 (PG maps, ScenarioEnv re-exports) ------------------------------
def metadrive_export(num_steps: int = 91) -> dict:
    """What `convert_recorded_scenario_exported` writes for a PG scene: a size only for objects that report one
    (not the cone, barrier and warning triangle its accident scenes place), the kerb as a painted line, the
    sidewalk as a polygon alone, 100 km/h on every lane, and the re-exported source's metadata kept aside."""
    t, ego, _ = _drive(num_steps)

    def still(x, y, kind):
        return {"type": kind, "state": {"position": np.tile(np.float32([x, y, 0.0]), (num_steps, 1)),
                                        "heading_theta": np.zeros(num_steps, np.float32),
                                        "velocity": np.zeros((num_steps, 2), np.float32),
                                        "valid": np.ones(num_steps, bool)}}

    tracks = {"ego": {"type": "VEHICLE", "state": {
        "position": ego, "heading_theta": np.zeros(num_steps, np.float32), "length": np.full(num_steps, 4.5),
        "width": np.full(num_steps, 2.0), "height": np.full(num_steps, 1.5),
        "velocity": np.tile(np.float32([2.0, 0.0]), (num_steps, 1)), "valid": np.ones(num_steps, bool)}},
              "cone": still(30.0, 1.0, "TRAFFIC_CONE"), "barrier": still(40.0, -1.0, "TRAFFIC_BARRIER"),
              "triangle": still(50.0, 0.5, "TRAFFIC_OBJECT")}
    map_features = {
        "lane": {**LANE, "speed_limit_kmh": 100.0},
        "0_0_side": {"type": "ROAD_LINE_SOLID_SINGLE_WHITE", "polyline": np.array([[0.0, -2.0], [100.0, -2.0]])},
        "sidewalk": {"type": "ROAD_EDGE_SIDEWALK",
                     "polygon": np.array([[0.0, -2.0], [100.0, -2.0], [100.0, -5.0], [0.0, -5.0]])},
    }
    return {"id": "pg", "version": "2023-10", "tracks": tracks, "map_features": map_features,
            "dynamic_map_states": {},
            "metadata": {"dataset": "metadrive", "sdc_id": "ego", "ts": list(t),
                         "history_metadata": {"dataset": "nuscenes"}}}


def test_static_objects_written_without_a_size_get_metadrive_class_sizes(tmp_path):
    (scenario,) = scenarios(convert(tmp_path, metadrive_export()))
    notes = scenario.metadata[MANIFEST_NOTES]
    assert "tracks_dropped" not in notes and sorted(notes["sizes_from_class"]) == ["barrier", "cone", "triangle"]
    assert scenario.num_objects == 4 and set(scenario.object_type[1:]) == {sch.OBJECT_TYPE_OTHER}
    boxes = {(round(float(scenario.x[i, 10])), round(float(scenario.length[i, 10]), 3),
              round(float(scenario.width[i, 10]), 3)) for i in range(1, 4)}
    assert boxes == {(30, 0.4, 0.4), (40, 0.3, 2.0), (50, 1.0, 1.0)}  # the barrier: 2 m across the lane


def test_sidewalk_polygons_are_the_road_edge_where_the_map_has_no_other(tmp_path):
    (scenario,) = scenarios(convert(tmp_path, metadrive_export()))
    edge = scenario.roadgraph_valid & (scenario.roadgraph_type == sch.RG_ROAD_EDGE_BOUNDARY)
    assert edge.any() and scenario.metadata[MANIFEST_NOTES]["road_edges_from_sidewalks"] == 1
    assert scenario.roadgraph_xyz[edge, 1].min() == pytest.approx(-5.0) and scenario.roadgraph_xyz[edge, 1].max() \
        == pytest.approx(-2.0)
    # with a drivable-area outline (nuScenes, nuPlan) the walkways are left out: they would only double it
    desc = metadrive_export()
    desc["map_features"]["boundary_0"] = {"type": "ROAD_LINE_SOLID_SINGLE_WHITE",
                                          "polyline": np.array([[0.0, -2.0], [100.0, -2.0]])}
    (scenario,) = scenarios(convert(tmp_path, desc))
    edge = scenario.roadgraph_valid & (scenario.roadgraph_type == sch.RG_ROAD_EDGE_BOUNDARY)
    assert "road_edges_from_sidewalks" not in scenario.metadata[MANIFEST_NOTES]
    np.testing.assert_allclose(scenario.roadgraph_xyz[edge, 1], -2.0)


def test_reexported_placeholder_speed_limits_are_unknown(tmp_path):
    (scenario,) = scenarios(convert(tmp_path, metadrive_export()))
    lane = scenario.roadgraph_valid & np.isin(scenario.roadgraph_type, sch.LANE_TYPES)
    assert lane.any() and (scenario.roadgraph_speed_limit[lane] == -1).all()
    assert "speed_limits_ignored" in scenario.metadata[MANIFEST_NOTES]
    desc = metadrive_export()
    desc["metadata"]["history_metadata"]["dataset"] = "waymo"  # WOMD lanes carry real limits
    (scenario,) = scenarios(convert(tmp_path, desc))
    assert scenario.roadgraph_speed_limit[lane].max() == pytest.approx(100 / 3.6, abs=1e-3)


def test_lane_heights_that_follow_the_heading_are_headings(tmp_path):
    (flat,) = scenarios(convert(tmp_path, sized_description()))  # an east-bound lane at z = 0: nothing to say
    assert "lane_z_was_heading" not in flat.metadata.get(MANIFEST_NOTES, {})
    desc = sized_description()
    arc = np.linspace(0.0, np.pi / 2, 40)  # a quarter circle of radius 30 m, written as (x, y, yaw) poses
    poses = np.stack([30 * np.sin(arc), 30 * (1 - np.cos(arc)), arc], axis=1)
    desc["map_features"] = {"1": dict(LANE), "2": {"type": "LANE_SURFACE_STREET", "polyline": poses}}
    (scenario,) = scenarios(convert(tmp_path, desc))
    lane = scenario.roadgraph_valid & np.isin(scenario.roadgraph_type, sch.LANE_TYPES)
    assert not scenario.roadgraph_xyz[lane, 2].any() and "lane_z_was_heading" in scenario.metadata[MANIFEST_NOTES]
    # heights that do not follow the heading stay (a ramp rising 1 m per 10 m)
    ramp = np.array([[float(x), 0.0, x / 10] for x in range(0, 101, 5)])
    desc["map_features"] = {"1": {"type": "LANE_SURFACE_STREET", "polyline": ramp}}
    (scenario,) = scenarios(convert(tmp_path, desc))
    lane = scenario.roadgraph_valid & np.isin(scenario.roadgraph_type, sch.LANE_TYPES)
    assert scenario.roadgraph_xyz[lane, 2].max() == pytest.approx(10.0, abs=0.01)
    assert "lane_z_was_heading" not in scenario.metadata.get(MANIFEST_NOTES, {})


def test_reexported_pedestrians_and_cyclists_without_a_size_get_metadrive_class_sizes(tmp_path):
    """MetaDrive's exports before 8fffccd9 (Dec 2024) wrote no size for pedestrians and cyclists: they get
    MetaDrive's class sizes instead of being dropped."""
    desc = metadrive_export()
    for key, kind, y in (("walker", "PEDESTRIAN", 4.0), ("rider", "CYCLIST", -4.0)):
        desc["tracks"][key] = {**desc["tracks"]["cone"], "type": kind}
        desc["tracks"][key]["state"] = {**desc["tracks"]["cone"]["state"],
                                        "position": np.tile(np.float32([20.0, y, 0.0]), (91, 1))}
    (scenario,) = scenarios(convert(tmp_path, desc))
    notes = scenario.metadata[MANIFEST_NOTES]
    assert "tracks_dropped" not in notes and {"walker", "rider"} <= set(notes["sizes_from_class"])
    sizes = {int(scenario.object_type[i]): (round(float(scenario.length[i, 10]), 2),
                                            round(float(scenario.width[i, 10]), 2))
             for i in range(scenario.num_objects) if scenario.object_type[i] in (2, 3)}
    assert sizes == {sch.OBJECT_TYPE_PEDESTRIAN: (0.7, 0.7), sch.OBJECT_TYPE_CYCLIST: (1.75, 0.4)}


def nuscenes_prediction_sample(num_steps: int) -> dict:
    """ScenarioNet's nuScenes converter in prediction mode: id `<scene>_<instance>_<sample>`, no
    current_time_index, 6 s (60 steps) after the current sample; the ego at x = 2 t."""
    desc = build_description(num_steps=num_steps, step_seconds=0.1, scenario_id="scene-0103_" + "a1" * 16 + "_"
                             + "b2" * 16)
    desc["metadata"]["dataset"] = "nuscenes"
    return desc


@pytest.mark.parametrize("num_steps, current", [(81, 20), (71, 10)])
def test_nuscenes_prediction_sample_current_step_is_six_seconds_before_the_end(tmp_path, num_steps, current):
    """2 s of keyframes before the sample (fewer near a scene's start) and 6 s after: the sample is log step
    num_steps - 61 (UniTraj reads the full ones with the current step at 20). With less than 1 s of history the
    shared window rule moves the current step to log step 10, as for any log (`current_step_moved`)."""
    (scenario,) = scenarios(convert(tmp_path, nuscenes_prediction_sample(num_steps)))
    sdc = scenario.sdc_index
    np.testing.assert_allclose(scenario.x[sdc, 10], 2 * current * 0.1, atol=1e-5)
    assert scenario.valid[sdc, 10:71].all() and not scenario.valid[:, 71:].any()  # the 6 s future, no more
    assert scenario.metadata[MANIFEST_NOTES]["current_time_index_derived"].startswith(f"{current}: ")
    assert scenario.tracks_to_predict.any()
    other = nuscenes_prediction_sample(num_steps)
    other["metadata"]["dataset"] = "toy"  # the same id from another writer: the default current step 10
    (scenario,) = scenarios(convert(tmp_path, other))
    np.testing.assert_allclose(scenario.x[scenario.sdc_index, 10], 2.0, atol=1e-5)
    assert "current_time_index_derived" not in scenario.metadata.get(MANIFEST_NOTES, {})


def test_nuscenes_lane_lines_left_ego_centred_are_moved_back(tmp_path):
    """ScenarioNet's nuScenes writer of Jan - Feb 2024 shifted each feature's polygon back to map coordinates but
    left the centre line of lanes (which have both) centred on the ego's first position."""
    origin = np.array([1316.4, 1038.6])
    desc = build_description(num_steps=91, step_seconds=0.1, scenario_id="scene-0553")
    desc["metadata"]["dataset"] = "nuscenes"
    desc["tracks"]["ego"]["state"]["position"][:, :2] += origin
    for key, feature in list(desc["map_features"].items()):
        line = np.asarray(feature.get("polyline", feature.get("polygon")), np.float64)[:, :2] + origin
        desc["map_features"][key] = {**feature, **({"polyline": line} if "polyline" in feature else
                                                   {"polygon": line})}
    lane_polygon = np.array([[0.0, -2.0], [100.0, -2.0], [100.0, 2.0], [0.0, 2.0]]) + origin
    (reference,) = scenarios(convert(tmp_path, {**desc, "map_features": {
        **desc["map_features"], "lane-1": {**desc["map_features"]["lane-1"], "polygon": lane_polygon}}}))
    centred = np.asarray(desc["map_features"]["lane-1"]["polyline"]) - origin  # the writer's bug
    buggy = {**desc, "map_features": {**desc["map_features"],
                                      "lane-1": {**desc["map_features"]["lane-1"], "polyline": centred,
                                                 "polygon": lane_polygon}}}
    (scenario,) = scenarios(convert(tmp_path, buggy))
    assert scenario.metadata[MANIFEST_NOTES]["lane_lines_recentred"] == 1
    np.testing.assert_array_equal(scenario.roadgraph_xyz, reference.roadgraph_xyz)
    assert "lane_lines_recentred" not in reference.metadata.get(MANIFEST_NOTES, {})


def test_a_map_feature_that_cannot_be_read_is_counted_not_fatal(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    ragged = np.empty(2, dtype=object)
    ragged[0], ragged[1] = [0.0, 1.0], [2.0, 3.0, 4.0, 5.0]
    desc["map_features"]["lane-3"] = {"type": "LANE_SURFACE_STREET", "polyline": ragged}
    (scenario,) = scenarios(convert(tmp_path, desc))
    assert scenario.metadata[MANIFEST_NOTES]["map_features_unread"] == 1
    assert (scenario.roadgraph_valid & (scenario.roadgraph_type == sch.RG_LANE_SURFACE_STREET)).any()
