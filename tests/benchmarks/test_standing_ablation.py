"""benchmarks/standing_ablation.py: which steps it studies and what each mask hides."""

from __future__ import annotations

import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from standing_ablation import MASKS, held_steps  # noqa: E402

from vmax_sim.observation import Observation  # noqa: E402


def test_held_steps_are_standing_steps_where_the_teacher_goes_and_the_student_does_not():
    accel = np.array([0.0, 0.3, 0.0, 0.0, 0.0])
    teacher = np.array([0.5, 0.5, 0.0, 0.5, 0.5])
    speed = np.array([0.1, 0.1, 0.1, 3.0, 0.1])
    valid = np.array([True, True, True, True, False])
    # held | the student goes | the teacher holds too | moving | not a valid step
    assert held_steps(accel, teacher, speed, valid).tolist() == [True, False, False, False, False]


def test_each_mask_hides_only_its_part():
    ones = lambda *shape: jnp.ones(shape, bool)  # noqa: E731
    observation = Observation(sdc=jnp.zeros((5, 6)), sdc_valid=ones(5), objects=jnp.zeros((8, 5, 12)),
                              objects_valid=ones(8, 5), roadgraph=jnp.zeros((20, 8)), roadgraph_valid=ones(20),
                              lights=jnp.zeros((5, 6)), lights_valid=ones(5), path_targets=jnp.zeros((10, 2)),
                              path_targets_valid=ones(10))
    valid_fields = ("sdc_valid", "objects_valid", "roadgraph_valid", "lights_valid", "path_targets_valid")
    hidden = {name: [field for field in valid_fields if not bool(jnp.all(getattr(mask(observation), field)))]
              for name, mask in MASKS.items()}
    assert hidden == {"nothing": [], "every object": ["objects_valid"], "own history": ["sdc_valid"],
                      "road graph": ["roadgraph_valid"], "path targets": ["path_targets_valid"],
                      "traffic lights": ["lights_valid"]}
    assert bool(MASKS["own history"](observation).sdc_valid[-1])  # the present step stays
