"""Shards of hand-made scenarios shared by the policy tests (one compilation per policy and shape)."""

from __future__ import annotations

from pathlib import Path

import pytest

import scenariomax
from tests.integration_sim.conftest import SMALL_SIZES, braking_scenario, cruising_scenario
from tests.policies.scenes import lead_car_scenario, red_light_scenario


@pytest.fixture(scope="session")
def policy_shards(tmp_path_factory) -> Path:
    """cruise, brake (a stopped car ahead), lead (a slower car ahead), red (a red light), in this order."""
    out = tmp_path_factory.mktemp("policy_shards")
    scenarios = [cruising_scenario("cruise"), braking_scenario("brake"), lead_car_scenario("lead"),
                 red_light_scenario("red")]
    scenariomax.write_shards(scenarios, out, sizes=SMALL_SIZES)
    return out
