"""The physical-sanity repairs (scenariomax/sources/sanity.py) on hand-made arrays and scenarios."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenariomax.pipeline import ConvertSettings, convert
from scenariomax.sources import sanity
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.gpudrive import tracks
from tests.conftest import straight_road_scenario

VEHICLE, PEDESTRIAN, CYCLIST, OTHER = 1, 2, 3, 4


# --- yaw ------------------------------------------------------------------------------------------------
def test_two_step_yaw_flip_is_turned_back():
    yaw = np.full((1, 12), 0.3)
    yaw[0, 5:7] = 0.3 - np.pi  # the tracker turned the box round for two steps
    fixed, count = sanity.fix_yaw_flips(yaw, np.ones((1, 12), bool), np.array([VEHICLE]))
    assert count == 2
    np.testing.assert_allclose(fixed, 0.3, atol=1e-12)


def test_pedestrian_turning_on_the_spot_is_left_alone():
    yaw = np.zeros((2, 12))
    yaw[:, 5:7] = np.pi  # a pedestrian does turn round and back; the same on a cyclist is a flip
    fixed, count = sanity.fix_yaw_flips(yaw, np.ones((2, 12), bool), np.array([PEDESTRIAN, CYCLIST]))
    assert count == 2
    np.testing.assert_array_equal(fixed[0], yaw[0])
    np.testing.assert_allclose(fixed[1], 0.0, atol=1e-12)


def test_a_heading_glitch_short_of_a_half_turn_is_not_a_flip():
    # The real WOMD tf.Example's parked truck (object 81): one step 2.7 rad off after a gap. Adding pi would leave
    # it 0.44 rad wrong, so it is no flip (FLIP_TOL_RAD); a half turn give or take 0.1 rad is.
    yaw = np.full(14, -0.67)
    yaw[7] = 2.03
    assert not sanity.flipped_steps(yaw, np.ones(14, bool)).any()
    yaw[7] = -0.67 + np.pi - 0.1
    assert sanity.flipped_steps(yaw, np.ones(14, bool)).tolist() == [i == 7 for i in range(14)]


def test_a_u_turn_is_not_a_flip():
    yaw = np.linspace(0, np.pi, 30)[None]  # 6 degrees per step
    assert sanity.fix_yaw_flips(yaw, np.ones((1, 30), bool), np.array([VEHICLE]))[1] == 0


# --- velocity -------------------------------------------------------------------------------------------
def straight_track(speed: float = 10.0, steps: int = 8) -> np.ndarray:
    xy = np.zeros((1, steps, 2))
    xy[0, :, 0] = speed * 0.1 * np.arange(steps)
    return xy


def test_velocity_garbage_step_is_derived_and_a_consistent_one_kept():
    xy = straight_track()
    velocity = np.tile([10.0, 0.0], (1, 8, 1))
    velocity[0, 2] = [10.8, 0.5]  # tracker noise: kept
    velocity[0, 5] = [80.0, -40.0]  # garbage
    out, derived = sanity.consistent_velocity(xy, velocity, np.ones((1, 8), bool))
    assert np.flatnonzero(derived[0]).tolist() == [5]
    np.testing.assert_allclose(out[0, 5], [10.0, 0.0])
    np.testing.assert_allclose(out[0, 2], [10.8, 0.5])


def test_first_step_after_a_gap_is_judged_with_the_track_noise():
    # A jittery pedestrian (positions +-5 cm, so its 0.1 s differences swing by 2 m/s) seen again after a gap:
    # its logged velocity reaches back to a position the log does not hold; 3 m/s off the next step's motion
    # is within its noise. The same 3 m/s on a smooth track is inconsistent.
    steps = 12
    xy = np.zeros((2, steps, 2))
    xy[:, :, 0] = -1.2 * 0.1 * np.arange(steps)
    xy[0, :, 0] += 0.05 * (-1.0) ** np.arange(steps)
    usable = np.ones((2, steps), bool)
    usable[:, 3:5] = False  # step 5 has no logged predecessor
    velocity = np.diff(xy, axis=1, prepend=xy[:, :1]) / 0.1  # WOMD's convention: the backward difference
    velocity[:, 0] = velocity[:, 1]
    velocity[:, 5] = velocity[:, 6] + [3.0, 0.0]  # 3 m/s off the forward difference (the next step's motion)
    _, derived = sanity.consistent_velocity(xy, velocity, usable)
    assert not derived[0].any()
    assert np.flatnonzero(derived[1]).tolist() == [5]


def test_gpudrive_keeps_using_the_shared_repairs():
    assert tracks.fix_yaw_flips is sanity.fix_yaw_flips
    assert tracks.consistent_velocity is sanity.consistent_velocity
    assert tracks.wider_than_long is sanity.wider_than_long


# --- boxes ----------------------------------------------------------------------------------------------
def test_box_wider_than_long_is_swapped_a_truck_is_not():
    length = np.array([[1.7] * 3, [12.0] * 3, [0.6] * 3])  # (N, T): a sideways car, a truck, a pedestrian
    width = np.array([[4.1] * 3, [2.5] * 3, [0.8] * 3])
    wide = sanity.wider_than_long(length, width, np.array([VEHICLE, VEHICLE, PEDESTRIAN]), np.ones((3, 3), bool))
    assert wide.tolist() == [True, False, False]
    length, width = sanity.swap_rows(length, width, wide)
    np.testing.assert_allclose(length[:, 0], [4.1, 12.0, 0.6])
    np.testing.assert_allclose(width[:, 0], [1.7, 2.5, 0.8])


# --- z --------------------------------------------------------------------------------------------------
def test_z_spike_is_flattened_and_a_long_ramp_left_alone():
    steps = 91
    z = np.zeros((2, steps))
    z[0, 40] = 30.0  # a glitch
    z[1] = np.linspace(0.0, 14.0, steps)  # 250 m of 6 % climb in 9 s: real, though 7 m from the track's median
    fixed, replaced = sanity.z_outliers(z, np.ones((2, steps), bool))
    assert np.flatnonzero(replaced[0]).tolist() == [40] and not replaced[1].any()
    assert fixed[0, 40] == 0.0
    np.testing.assert_array_equal(fixed[1], z[1])


# --- time -----------------------------------------------------------------------------------------------
def test_ten_hz_up_to_womd_jitter():
    assert sanity.nominal_steps(np.array([0.1, 0.0995, 0.1003, 0.0894, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]))
    assert sanity.nominal_steps(np.array([0.102, 0.099, 0.099] * 30))  # jitter cancels (a median would say 99 ms)
    assert not sanity.nominal_steps(np.full(5, 0.2))  # 5 Hz
    assert not sanity.nominal_steps(np.array([0.1, 0.1, 0.2, 0.1]))  # a dropped frame
    assert sanity.is_nominal_10hz(np.arange(91) * 0.1)


def test_nuplan_sweeps_taken_two_by_two_are_10hz(tmp_path):
    from scenariomax.sources.nuplan import NuplanSource
    from tests.sources.nuplan.builders import write_fixture

    files = write_fixture(tmp_path)  # sweeps 50 ms +- 1 ms apart: steps of 102, 99, 99 ms
    scenarios = list(NuplanSource(str(files.db_path), str(files.maps_root)).read_unit(str(files.db_path)))
    assert len(scenarios) == 2 and all(sanity.sanity_repairs(s) == ({}, {}) for s in scenarios)


# --- one scenario ---------------------------------------------------------------------------------------
def broken_scenario(**changes):
    """The straight-road toy with one of each fault: a flipped SDC box, a sideways car, a garbage velocity, a z
    spike."""
    clean = straight_road_scenario()
    yaw, length, width = clean.bbox_yaw.copy(), clean.length.copy(), clean.width.copy()
    vx, z = clean.velocity_x.copy(), clean.z.copy()
    yaw[0, 30:32] = -np.pi
    length[1], width[1] = 1.7, 4.1
    vx[2, 50] = 70.0
    z[2, 60] = 12.0
    return clean.replace(bbox_yaw=yaw, length=length, width=width, velocity_x=vx, speed=None, vel_yaw=None, z=z,
                         **changes)


def test_clean_scenario_is_returned_unchanged():
    clean = straight_road_scenario()
    assert sanity.sanitize_scenario(clean) is clean


def test_sanitize_scenario_repairs_and_notes():
    scenario = broken_scenario(metadata={MANIFEST_NOTES: {"boxes_swapped": ["ego"], "velocity_derived_steps": 2,
                                                          "layout": "x"}})
    fixed = sanity.sanitize_scenario(scenario)
    assert fixed.metadata[MANIFEST_NOTES] == {"boxes_swapped": ["ego", 101], "velocity_derived_steps": 3,
                                              "layout": "x", "yaw_flips_fixed": 2, "z_replaced_steps": 1}
    np.testing.assert_allclose(fixed.bbox_yaw[0], 0.0, atol=1e-6)
    assert (fixed.length[1, 0], fixed.width[1, 0]) == pytest.approx((4.1, 1.7))
    assert fixed.velocity_x[2, 50] == pytest.approx(10.0, abs=1e-3) and fixed.speed[2, 50] == pytest.approx(10.0)
    assert fixed.z[2, 60] == 0.0
    assert fixed.validate() == []
    assert scenario.velocity_x[2, 50] == 70.0  # the input is not modified
    assert sanity.sanitize_scenario(fixed) is fixed  # nothing left to repair


def test_steps_not_10hz_are_noted_and_the_velocity_check_skipped():
    scenario = broken_scenario(timestamp_micros=np.tile(np.arange(91) * 200_000, (3, 1)))
    notes = sanity.sanitize_scenario(scenario).metadata[MANIFEST_NOTES]
    assert notes["timestamps_not_10hz"] == {"mean_step_s": 0.2, "min_step_s": 0.2, "max_step_s": 0.2}
    assert "velocity_derived_steps" not in notes  # its position differences assume 0.1 s


def test_merge_notes():
    merged = sanity.merge_notes({"a": 1, "ids": [1, 2], "big": list(range(20)), "rule": "named"},
                                {"a": 2, "ids": [2, 3], "big": [99], "new": 4})
    assert merged == {"a": 3, "ids": [1, 2, 3], "big": 21, "rule": "named", "new": 4}


# --- through the pipeline -------------------------------------------------------------------------------
class ToySource:
    """One broken scenario under a source name (picklable for the pipeline)."""

    def __init__(self, name: str):
        self.name = name

    def list_units(self) -> list[str]:
        return ["toy"]

    def read_unit(self, unit: str):
        yield broken_scenario()

    def settings(self) -> dict:
        return {}


@pytest.mark.parametrize("name, sanitized", [("womd", True), ("synthetic", False), ("records", False)])
def test_pipeline_sanitizes_real_sources_only(tmp_path, name, sanitized):
    result = convert(ToySource(name), ConvertSettings(out=tmp_path / name, workers=1, progress=False))
    assert result.ok
    notes = json.loads((tmp_path / name / "manifest.json").read_text())["notes"]
    if sanitized:
        assert notes == [{"unit": "toy", "scenario": "toy-0", "notes": {
            "yaw_flips_fixed": 2, "boxes_swapped": [101], "velocity_derived_steps": 1, "z_replaced_steps": 1}}]
    else:
        assert notes == []
