"""benchmarks/crossing_probe.py: which scenes isolate people crossing in front of an SDC that waits for them."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from crossing_probe import probe_scene, score, training_scene  # noqa: E402

STEPS = 50


def _scene():
    # the SDC (object 0, 4.6 m long, heading +x) stands at the origin for 20 steps, then drives off at 5 m/s; object 1
    # a pedestrian crossing (+y) 6 m ahead of its centre from step 5 to 12; object 2 a vehicle parked 8 m ahead
    x, y, yaw, speed = (np.zeros((3, STEPS)) for _ in range(4))
    valid = np.ones((3, STEPS), bool)
    length = np.full((3, STEPS), 4.6)
    x[0, 20:] = np.arange(1, STEPS - 19) * 0.5
    speed[0, 20:] = 5.0
    valid[1] = False
    valid[1, 5:13] = True
    x[1], y[1, 5:13], yaw[1], speed[1] = 6.0, np.linspace(-3.0, 3.0, 8), np.pi / 2, 1.2
    x[2] = 8.0
    return x, y, yaw, speed, valid, np.array([1, 2, 1]), length


def test_an_sdc_standing_while_someone_crosses_in_front_then_driving_on_is_picked():
    x, y, yaw, speed, valid, types, length = _scene()
    assert probe_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    assert training_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)


def test_a_pedestrian_behind_or_beside_the_corridor_is_not_in_front():
    x, y, yaw, speed, valid, types, length = _scene()
    x[1] = -6.0  # behind the SDC
    assert not probe_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    assert not training_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    x, y, yaw, speed, valid, types, length = _scene()
    y[1, 5:13] = 2.5  # walking along 2.5 m to the side
    assert not probe_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    assert not training_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)


def test_an_sdc_that_moves_at_the_start_or_never_drives_on_is_not_picked():
    x, y, yaw, speed, valid, types, length = _scene()
    speed[0, 0] = 3.0  # rolling at the current step: not a probe scene; still stands 19 of its first 30 steps
    assert not probe_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    assert training_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    x, y, yaw, speed, valid, types, length = _scene()
    x[0], speed[0] = 0.0, 0.0  # stands all along
    assert not probe_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)
    assert not training_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)


def test_the_training_rule_wants_the_person_in_front_while_the_sdc_stands():
    x, y, yaw, speed, valid, types, length = _scene()
    speed[0, 3:14] = 2.0  # it creeps while the person crosses (the pose is unchanged: only the speed says so)
    assert not training_scene(x, y, yaw, speed, valid, types, length, sdc=0, start=0)


def test_score_counts_the_judged_episodes_and_their_at_fault_collisions(tmp_path):
    header = "scenario_id,judged_steps,accurate,vmax_score,at_fault_collision\n"
    rows = ["a,80,1,0.9,0\n", "b,80,0,0.2,1\n", "c,0,0,0,1\n"]  # c is not judged
    (tmp_path / "episodes-run.csv").write_text(header + "".join(rows))
    got = score(str(tmp_path))
    assert (got["episodes"], got["accuracy"], got["at_fault_collisions"]) == (2, 0.5, 1)
    assert abs(got["vmax_score"] - 0.55) < 1e-9
