"""What the physical-sanity repairs change on every real sample (../shared/realdata): nothing on clean WOMD, and
exactly the faults found by hand elsewhere (docs/datasets.md, "Sanity of physical quantities")."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenariomax.pipeline import ConvertSettings, convert
from scenariomax.scenario import Scenario
from scenariomax.sources.registry import make_source
from scenariomax.sources.sanity import sanitize_scenario, sanity_repairs
from tests.conftest import realdata_file


def repairs(dataset: str, relative: str) -> dict[str, tuple[Scenario, dict, dict]]:
    """{scenario id: (source scenario, changed fields, notes)} of every scenario of a real sample."""
    source = make_source(dataset, src=str(realdata_file(relative)))
    out = {}
    for unit in source.list_units():
        for item in source.read_unit(unit):
            assert isinstance(item, Scenario), item
            out[item.scenario_id] = (item, *sanity_repairs(item))
    return out


def noted(found: dict) -> dict[str, dict]:
    return {sid: notes for sid, (_, _, notes) in found.items() if notes}


@pytest.mark.parametrize("relative", ["womd/motion_data_one_scenario.tfrecord",
                                      "womd/motion_data_one_example.tfrecord"])
def test_clean_womd_is_not_repaired(relative):
    # Before FLIP_TOL_RAD the tf.Example's parked truck (a one-step 2.7 rad glitch after a gap) was "flipped", and
    # before NOISE_FACTOR three first-after-a-gap velocities of a jittery pedestrian of the Scenario record were
    # "derived"; neither was a fault the rules could repair.
    found = repairs("womd", relative)
    assert len(found) == 1 and noted(found) == {}


def test_womd_through_the_pipeline_needs_no_repair(tmp_path):
    """Clean WOMD logs get no sanity repair; the only note is the tf.Example's cut map (its 20,000-point
    roadgraph is full), not a repair."""
    realdata_file("womd/motion_data_one_scenario.tfrecord")
    source = make_source("womd", src=str(realdata_file("womd")))
    result = convert(source, ConvertSettings(out=tmp_path / "womd", workers=1, progress=False))
    assert result.ok and result.num_scenarios == 2
    notes = json.loads((tmp_path / "womd" / "manifest.json").read_text())["notes"]
    assert [entry["notes"] for entry in notes] == [{"tf_example_roadgraph_full_points": 20000}]


def test_av2_velocities_that_lag_the_positions_are_derived():
    found = repairs("av2", "av2")
    assert noted(found) == {"0a1e6f0a-1817-4a98-b02e-db8c9327d151": {"velocity_derived_steps": 41}}
    scenario, changes, _ = next(iter(found.values()))
    assert set(changes) == {"velocity_x", "velocity_y", "speed", "vel_yaw"}
    changed = changes["velocity_x"] != scenario.velocity_x
    # e.g. track 139310, whose tracker velocity is still 0 while it moves 3.5-5 m/s
    row = int(np.flatnonzero(scenario.object_id == 139310)[0])
    xy = np.stack([scenario.x[row], scenario.y[row]], axis=-1).astype(np.float64)
    step = np.diff(xy, axis=0) / 0.1  # (T-1, 2) m/s
    assert (scenario.speed[row, :4] < 0.01).all() and (np.linalg.norm(step[:4], axis=-1) > 3).all()
    assert changed[row, :4].all()
    np.testing.assert_allclose(changes["speed"][row, 1:4], np.linalg.norm(step[:3] + step[1:4], axis=-1) / 2,
                               rtol=1e-5)  # the central difference
    fixed = sanitize_scenario(scenario)
    assert fixed.validate() == [] and sanitize_scenario(fixed) is fixed


def test_scenarionet_nuscenes_end_of_track_velocities_and_womd_flips():
    found = repairs("scenarionet", "scenarionet/nuscenes")
    assert {sid: notes["velocity_derived_steps"] for sid, notes in noted(found).items()} == {
        "scene-0103_t000": 5, "scene-0103_t080": 1, "scene-0553_t000": 2, "scene-0553_t080": 6,
        "scene-0655_t000": 3, "scene-0655_t080": 1, "scene-0757_t000": 1, "scene-0757_t080": 7}
    assert all(set(notes) == {"velocity_derived_steps"} for notes in noted(found).values())
    flips = {**noted(repairs("scenarionet", "scenarionet/womd_20s")),
             **noted(repairs("scenarionet", "scenarionet/womd_91steps"))}
    # Two short, almost parked WOMD vehicle tracks whose first / last step points the other way (pi +- 0.1 rad).
    assert flips == {"b36a6d0bc9e525bc_t080": {"yaw_flips_fixed": 1}, "2a1e44d405a6833f": {"yaw_flips_fixed": 1}}


def test_gpudrive_repairs_are_not_repeated():
    for relative in ("gpudrive", "nocturne"):
        assert noted(repairs("gpudrive", relative)) == {}, relative
