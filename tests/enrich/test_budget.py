"""Object budget: with more objects than slots, the SDC, tracks_to_predict and objects_of_interest
are kept before the nearest others."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from scenariomax.enrich.budget import fit_to_budget, objects_to_keep
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from tests.enrich.scenes import NUM_STEPS, straight_xy

NUM_OBJECTS = 140
SDC = 3
TO_PREDICT = (130, 135)
OF_INTEREST = (131, 135, 136)


def crowded_scenario(num_lights: int = 0) -> Scenario:
    """140 cars on parallel lanes, all driving east at 10 m/s; car i is 10 + i metres to the side
    of the SDC (car 3), so closeness follows the index. The labelled cars are among the farthest."""
    lateral = np.array([0.0 if i == SDC else 10.0 + i for i in range(NUM_OBJECTS)])
    xy = np.stack([straight_xy(0.0, 10.0, y) for y in lateral])
    ones = np.ones((NUM_OBJECTS, NUM_STEPS))
    lights = {}
    if num_lights:
        light_ones = np.ones((num_lights, NUM_STEPS))
        valid = light_ones > 0
        valid[-1] = False  # a light never seen
        lights = dict(tl_state=4 * light_ones, tl_valid=valid, tl_lane_id=light_ones,
                      tl_x=np.arange(num_lights)[:, None] * 10.0 * light_ones, tl_y=0 * light_ones,
                      tl_z=0 * light_ones)
    return Scenario(
        scenario_id="crowd", object_id=np.arange(NUM_OBJECTS) + 1000, object_type=np.ones(NUM_OBJECTS),
        is_sdc=np.arange(NUM_OBJECTS) == SDC, x=xy[..., 0], y=xy[..., 1], z=0 * ones, bbox_yaw=0 * ones,
        length=4.5 * ones, width=2.0 * ones, height=1.5 * ones, velocity_x=10 * ones, velocity_y=0 * ones,
        valid=ones > 0, tracks_to_predict=np.isin(np.arange(NUM_OBJECTS), TO_PREDICT),
        objects_of_interest=np.isin(np.arange(NUM_OBJECTS), OF_INTEREST), **lights,
    )


def indices(scenario: Scenario) -> list[int]:
    return (scenario.object_id - 1000).tolist()


def test_labelled_objects_are_kept_over_budget():
    fitted = fit_to_budget(crowded_scenario(), Sizes())
    kept = indices(fitted)
    assert len(kept) == 128 and kept[0] == SDC and fitted.is_sdc.tolist() == [True] + [False] * 127
    assert set(TO_PREDICT) | set(OF_INTEREST) <= set(kept)
    # The other 123 slots go to the nearest cars; everything stays in closeness order.
    nearest = [i for i in range(NUM_OBJECTS) if i != SDC and i not in TO_PREDICT + OF_INTEREST][:123]
    assert kept == [SDC] + sorted(nearest + sorted(set(TO_PREDICT) | set(OF_INTEREST)))
    assert fitted.tracks_to_predict.sum() == 2 and fitted.objects_of_interest.sum() == 3
    assert fitted.validate() == []


@pytest.mark.parametrize("slots, expected", [
    (1, [SDC]),
    (3, [SDC, 130, 135]),  # tracks_to_predict first
    (4, [SDC, 130, 131, 135]),  # then objects_of_interest, the nearest first
    (5, [SDC, 130, 131, 135, 136]),
    (6, [SDC, 0, 130, 131, 135, 136]),  # then the nearest other car
])
def test_priority_order_with_few_slots(slots, expected):
    assert indices(fit_to_budget(crowded_scenario(), Sizes(num_objects=slots))) == expected


def test_within_budget_labels_do_not_reorder():
    order = objects_to_keep(crowded_scenario(), 200).tolist()
    assert order == [SDC] + [i for i in range(NUM_OBJECTS) if i != SDC]


def test_fitting_twice_changes_nothing():
    once = fit_to_budget(crowded_scenario(), Sizes())
    assert fit_to_budget(once, Sizes()) is once


def test_lights_over_budget_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fitted = fit_to_budget(crowded_scenario(num_lights=20), Sizes())
    assert fitted.tl_state.shape[0] == 16 and fitted.tl_valid.any(axis=1).all()  # the unseen light is dropped
