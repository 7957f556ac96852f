"""A small deterministic Source for pipeline tests (importable, so worker processes can unpickle it)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from scenariomax.errors import InputError
from scenariomax.sources.base import Failure
from tests.conftest import straight_road_scenario


@dataclasses.dataclass(frozen=True)
class ToySource:
    num_units: int = 6
    per_unit: int = 4
    delay_s: float = 0.0
    broken_units: tuple = ()  # units whose whole file is unreadable
    bad_scenarios: tuple = ()  # (unit index, position) that fail validation
    name: str = "toy"

    def list_units(self) -> list[str]:
        return [f"toy:{i:03d}" for i in range(self.num_units)]

    def read_unit(self, unit: str):
        index = int(unit.split(":")[1])
        if index in self.broken_units:
            raise InputError(f"{unit}: not a toy file (bad magic)")
        for position in range(self.per_unit):
            time.sleep(self.delay_s)
            scenario = straight_road_scenario(f"toy-{index:03d}-{position}", speed=5.0 + index + 0.1 * position)
            if (index, position) in self.bad_scenarios:
                scenario.x[0, 3] = np.nan
            if (index, position) == (1, 1):
                yield Failure(unit, "toy-001-1", "source could not build it")
                continue
            yield scenario

    def settings(self) -> dict:
        return {"num_units": self.num_units, "per_unit": self.per_unit}


@dataclasses.dataclass(frozen=True)
class CountedToySource(ToySource):
    """A ToySource that announces its total, as the synthetic and records sources do: progress in scenarios."""

    def expected_num_scenarios(self) -> int:
        return self.num_units * self.per_unit
