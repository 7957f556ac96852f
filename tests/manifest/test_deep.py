"""`validate --deep`: values no real log holds are named with where they are; real and hand-made data pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from click.testing import CliRunner

from scenariomax import read_shards, write_shards
from scenariomax.validate import PLAUSIBLE_BOUNDS, plausibility_problems, validate_shards
from tests.conftest import realdata_file
from tests.inspect.scenes import SIZES, make_scenario
from tests.manifest.outputs import convert_output
from vmax_cli.scenariomax_cli import main

DOC = Path(__file__).resolve().parents[2] / "docs" / "validate.md"


def _absurd():
    scenario = make_scenario("absurd")
    scenario.length[0, 5] = 9.6e16
    scenario.z[1, 3] = 2e23
    scenario.velocity_x[0, 7] = -4.3e9
    scenario.speed[0, 7] = 4.3e9  # consistent with the velocity: only --deep objects
    return scenario


def test_what_the_tester_saw_is_named_with_its_place(tmp_path):
    write_shards([_absurd()], tmp_path, sizes=SIZES)
    assert validate_shards(tmp_path).ok  # finite and positive: the schema alone cannot object
    (entry,) = validate_shards(tmp_path, deep=True).bad
    reasons = entry.reason.split("; ")
    assert reasons == [
        "position z 2e+23 m at object 1, step 3 is outside the plausible range [-10000, 10000] m",
        "length 9.6e+16 m at object 0, step 5 is outside the plausible range [0.05, 30] m",
        "speed 4.3e+09 m/s at object 0, step 7 is outside the plausible range [0, 100] m/s",
        "velocity_x -4.3e+09 m/s at object 0, step 7 is outside the plausible range [-100, 100] m/s",
    ]
    result = CliRunner().invoke(main, ["validate", "--deep", str(tmp_path)])
    assert result.exit_code == 1 and "length 9.6e+16 m at object 0, step 5" in result.output


def test_timestamps_in_the_wrong_unit_and_teleports():
    scenario = make_scenario("odd")
    scenario.timestamp_micros[0] = np.arange(91) * 100  # milliseconds written as microseconds
    scenario.x[1, 50] += 500.0  # one step 500 m away
    assert plausibility_problems(scenario) == [
        "timestamps advance 100 us per step at object 0, step 1, outside the plausible [10000, 1000000] us "
        "(90 entries)",
        "object 1 jumps 500.5 m between steps 49 and 50 (5005 m/s, plausible up to 150) (2 entries)",
    ]


def test_nan_in_a_light_stop_point_is_outside_every_range():
    scenario = make_scenario("nan")
    light, step = np.argwhere(scenario.tl_valid)[0]
    scenario.tl_x[light, step] = np.nan
    (problem,) = plausibility_problems(scenario)
    assert problem.startswith(f"traffic light stop point x nan m at light {light}, step {step} is outside")


def test_hand_made_and_converted_scenes_are_plausible(tmp_path):
    scenes = [make_scenario("a"), make_scenario("b", with_lights=False, with_paths=False)]
    assert [plausibility_problems(scene) for scene in scenes] == [[], []]
    out = convert_output(tmp_path / "toy")
    assert validate_shards(out, deep=True).bad == ()


def test_the_real_womd_record_is_plausible():
    record = realdata_file("womd/motion_data_one_example.tfrecord")
    (scenario,) = read_shards(record)
    assert plausibility_problems(scenario) == []


def test_every_bound_is_documented_with_its_range():
    text = DOC.read_text()
    for bound in PLAUSIBLE_BOUNDS:
        assert f"| {bound.name} | {bound.low:g} .. {bound.high:g} {bound.unit} |" in text, bound.name
