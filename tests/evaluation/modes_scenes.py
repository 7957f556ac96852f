"""Hand-made scenes for the evaluation modes (straight road of tests.integration_sim) and their shards as
fixtures; the test modules import the fixtures they use."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import scenariomax
from tests.integration_sim.conftest import DT, NUM_STEPS, SMALL_SIZES, road_scenario

PARKED_X = 60.0  # m, centre of the parked car; its rear bumper is at 57.75 m
AGENT_SPEED = 10.0  # m/s, the controllable agent's logged speed (its log drives through the parked car)


def parked_car_scenario(scenario_id: str = "parked", agent_path: bool = True) -> scenariomax.Scenario:
    """The SDC at 5 m/s far behind; a controllable agent at 10 m/s from x = 0 whose log drives straight
    through a parked (not controllable) car at x = 60 m. agent_path: the shard holds the agent's lane
    path (else the loader builds one from its logged positions)."""
    time = np.arange(NUM_STEPS) * DT
    xs = np.stack([-40.0 + 5.0 * time, AGENT_SPEED * time, np.full(NUM_STEPS, PARKED_X)])
    speeds = np.stack([np.full(NUM_STEPS, 5.0), np.full(NUM_STEPS, AGENT_SPEED), np.zeros(NUM_STEPS)])
    scenario = road_scenario(scenario_id, xs, speeds)
    changes = {"is_controllable": np.array([True, True, False])}
    if agent_path:
        path_x = np.arange(0.0, 200.0)
        changes.update(agent_path_object_index=np.array([1]),
                       agent_path_xyz=np.stack([path_x, 0 * path_x, 0 * path_x], 1)[None].astype(np.float32),
                       agent_path_valid=np.ones((1, len(path_x)), bool),
                       agent_path_arc_length=path_x[None].astype(np.float32))
    return dataclasses.replace(scenario, **changes)


def cruise_scenario(scenario_id: str, speed: float = 10.0) -> scenariomax.Scenario:
    """The SDC alone at `speed` along the lane (for perturbed starts)."""
    time = np.arange(NUM_STEPS) * DT
    xs = (speed * time)[None]
    return road_scenario(scenario_id, xs, np.full_like(xs, speed))


PERTURBED_IDS = tuple(f"cruise-{i}" for i in range(8))


@pytest.fixture(scope="session")
def parked_shards(tmp_path_factory) -> Path:
    """parked (agent with a lane path in the shard), parked-nopath (path from its log), in this order."""
    out = tmp_path_factory.mktemp("parked_shards")
    scenarios = [parked_car_scenario("parked"), parked_car_scenario("parked-nopath", agent_path=False)]
    scenariomax.write_shards(scenarios, out, sizes=SMALL_SIZES)
    return out


@pytest.fixture(scope="session")
def cruise_shards(tmp_path_factory) -> tuple[Path, Path]:
    """Eight SDC-only cruising scenarios, in order and reversed (two directories)."""
    root = tmp_path_factory.mktemp("cruise_shards")
    scenarios = [cruise_scenario(i) for i in PERTURBED_IDS]
    scenariomax.write_shards(scenarios, root / "forward", sizes=SMALL_SIZES)
    scenariomax.write_shards(scenarios[::-1], root / "reversed", sizes=SMALL_SIZES)
    return root / "forward", root / "reversed"
