"""benchmarks/route_entry.py: which steps count as having an object heading onto the route, and as leaving it out."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from route_entry import entry_shares  # noqa: E402


def test_a_step_leaves_an_entering_object_out_only_when_the_slots_do_not_show_it():
    # 4 steps, 2 objects: step 0 none entering; step 1 object 0 entering and shown; step 2 object 1 entering, not
    # shown; step 3 both entering, object 0 shown only
    entering = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], bool)
    shown = np.array([[1, 1], [1, 0], [1, 0], [1, 0]], bool)
    shares = entry_shares(entering, shown)
    assert shares == {"steps": 4, "entering_share": 3 / 4, "left_out_share": 2 / 4}


def test_no_steps_give_zero_shares():
    shares = entry_shares(np.zeros((0, 3), bool), np.zeros((0, 3), bool))
    assert shares == {"steps": 0, "entering_share": 0.0, "left_out_share": 0.0}
