"""Traffic lights in every layout the MetaDrive / ScenarioNet writers used: converted, or counted in the
manifest note `lights_unread` when a light reports states none of which can be used (never dropped silently)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from scenariomax import schema as sch
from scenariomax.sources.base import MANIFEST_NOTES, Failure
from scenariomax.sources.scenarionet import ScenarioNetSource
from tests.sources.scenarionet.fixtures import (
    build_description,
    early_metadrive_description,
    metadrive_2021_description,
    pickle_from_main,
    write_pickle,
    writer_enums,
)

ENUMS = writer_enums()


def _one(tmp_path, desc, data: bytes | None = None):
    path = tmp_path / "sd_lights.pkl"
    if data is None:
        write_pickle(path, desc)
    else:
        path.write_bytes(data)
    items = list(ScenarioNetSource(str(path)).read_unit(str(path)))
    assert len(items) == 1 and not isinstance(items[0], Failure), items
    return items[0]


def _notes(scenario) -> dict:
    return scenario.metadata.get(MANIFEST_NOTES, {})


def _row(scenario, x: float) -> int:
    """The light whose stop point is at `x` (valid somewhere)."""
    rows = [row for row in range(len(scenario.tl_x)) if np.any(scenario.tl_valid[row] & (scenario.tl_x[row] == x))]
    assert len(rows) == 1, rows
    return rows[0]


def test_2021_list_of_one_step_is_the_logs_last_step(tmp_path):
    """MetaDrive 2021-2022's converter appended one dict keyed by lane after its loop over the steps: the
    states of the last step only."""
    scenario = _one(tmp_path, None, pickle_from_main(metadrive_2021_description(ENUMS), ENUMS, 4))
    assert not scenario.tl_valid[:, :90].any()
    row = _row(scenario, 50.0)
    assert scenario.tl_valid[row, 90] and scenario.tl_state[row, 90] == sch.TL_GO
    assert scenario.tl_lane_id[row, 90] == 1 and scenario.tl_y[row, 90] == 0.0
    assert "lights_unread" not in _notes(scenario)


def test_2021_list_of_one_dict_per_step(tmp_path):
    desc = metadrive_2021_description(ENUMS)
    desc["dynamic_map_states"] = [{1: {"state": 4 if step < 50 else 6, "stop_point": [50.0, 0.0, 0.0]}}
                                  if step >= 20 else {} for step in range(91)]
    scenario = _one(tmp_path, None, pickle_from_main(desc, ENUMS, 4))
    row = _row(scenario, 50.0)
    np.testing.assert_array_equal(scenario.tl_valid[row], np.arange(91) >= 20)
    assert scenario.tl_state[row, 30] == sch.TL_STOP and scenario.tl_state[row, 60] == sch.TL_GO
    assert "lights_unread" not in _notes(scenario)


def test_march_2023_list_per_step_of_lane_states(tmp_path):
    """MetaDrive, March 2023: `dynamic_map_states` one list per step of {lane, state (LANE_STATE_*),
    stop_point}; lane-1 reported from step 10, a second light on lane-2 only at steps 40-49."""
    desc = build_description(num_steps=91, step_seconds=0.1)
    steps = []
    for step in range(91):
        states = []
        if step >= 10:
            states.append({"lane": "lane-1", "state": "LANE_STATE_STOP" if step < 50 else "LANE_STATE_GO",
                           "stop_point": np.array([50.0, 0.0, 0.0], np.float32)})
        if 40 <= step < 50:
            states.append({"lane": "lane-2", "state": "LANE_STATE_CAUTION", "stop_point": np.array([120.0, 0.0, 0.0])})
        steps.append(states)
    desc["dynamic_map_states"] = steps
    scenario = _one(tmp_path, desc)
    first, second = _row(scenario, 50.0), _row(scenario, 120.0)
    np.testing.assert_array_equal(scenario.tl_valid[first], np.arange(91) >= 10)
    assert scenario.tl_state[first, 20] == sch.TL_STOP and scenario.tl_state[first, 70] == sch.TL_GO
    np.testing.assert_array_equal(scenario.tl_valid[second], (np.arange(91) >= 40) & (np.arange(91) < 50))
    assert scenario.tl_state[second, 45] == sch.TL_CAUTION
    assert "lights_unread" not in _notes(scenario)


@pytest.mark.parametrize("states", [[[{}]], [{}], [], {}, None])
def test_layouts_without_lights_have_no_note(tmp_path, states):
    """The "old format" wrote [[{}]], the 2021-2022 converter [{}] for a log without lights."""
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["dynamic_map_states"] = states
    scenario = _one(tmp_path, desc)
    assert not scenario.tl_valid.any() and "lights_unread" not in _notes(scenario)


def test_early_metadrive_filler_steps_are_not_unread(tmp_path):
    scenario = _one(tmp_path, early_metadrive_description())
    assert scenario.tl_valid.any() and "lights_unread" not in _notes(scenario)


@pytest.mark.parametrize("states, count", [
    # a list per step of another length than the log: the steps cannot be placed
    ([[{"lane": "lane-1", "state": "LANE_STATE_GO", "stop_point": [50.0, 0, 0]}]] * 5, 5),
    # a light on a lane the map does not have
    ({"tl-9": {"lane": "lane-9", "stop_point": [50.0, 0, 0],
               "state": {"object_state": ["TRAFFIC_LIGHT_RED"] * 91}}}, 1),
    # a light without a stop point
    ({"tl-1": {"lane": "lane-1", "state": {"object_state": ["TRAFFIC_LIGHT_RED"] * 91}}}, 1),
    # a light that is not a dict
    ({"tl-1": ["TRAFFIC_LIGHT_RED"] * 91}, 1),
    # per-step items without a lane
    ([[{"state": "LANE_STATE_GO", "stop_point": [50.0, 0, 0]}]] * 91, 91),
])
def test_lights_that_cannot_be_read_are_counted(tmp_path, states, count):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["dynamic_map_states"] = states
    scenario = _one(tmp_path, desc)
    assert not scenario.tl_valid.any()
    assert _notes(scenario)["lights_unread"] == count


def test_unread_lights_are_in_the_convert_summary(tmp_path):
    from vmax_cli.scenariomax_cli import main

    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["dynamic_map_states"]["tl-1"]["lane"] = "lane-9"
    write_pickle(tmp_path / "src" / "sd_a.pkl", desc)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["convert", "--dataset", "scenarionet", "--src", str(tmp_path / "src"),
                                       "--out", str(out), "--workers", "1", "--no-enrich"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert "lights_unread" in result.output
