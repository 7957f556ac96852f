"""`SyntheticSource`: the generator as a pipeline source (units are ranges of scenario indices)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator

from scenariomax.errors import InputError
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure
from scenariomax.sources.synthetic.generator import generate_scenario, scenario_id
from scenariomax.sources.synthetic.knobs import SyntheticKnobs

_UNIT = re.compile(r"^synthetic:(\d+)-(\d+)$")


@dataclasses.dataclass(frozen=True)
class SyntheticSource:
    num_scenarios: int
    seed: int = 0
    sizes: Sizes | None = None
    scenarios_per_unit: int = 10
    name: str = "synthetic"
    knobs: SyntheticKnobs | None = None  # how scenes are randomised (None: the default knobs)

    def __post_init__(self) -> None:
        if self.knobs is not None and not isinstance(self.knobs, SyntheticKnobs):
            raise InputError(f"synthetic: knobs must be a SyntheticKnobs, got {type(self.knobs).__name__}")
        if self.num_scenarios < 0 or self.scenarios_per_unit < 1:
            raise InputError(f"synthetic: need num_scenarios >= 0 and scenarios_per_unit >= 1, got "
                             f"{self.num_scenarios} and {self.scenarios_per_unit}")

    def expected_num_scenarios(self) -> int:
        """The total the progress bar shows (every unit yields its scenarios)."""
        return self.num_scenarios

    def list_units(self) -> list[str]:
        """Ids like "synthetic:00000-00009" (inclusive index ranges), in order."""
        width = max(5, len(str(max(self.num_scenarios - 1, 0))))
        return [f"synthetic:{start:0{width}d}-{min(start + self.scenarios_per_unit, self.num_scenarios) - 1:0{width}d}"
                for start in range(0, self.num_scenarios, self.scenarios_per_unit)]

    def read_unit(self, unit: str) -> Iterator:
        match = _UNIT.match(unit)
        if not match or int(match.group(1)) > int(match.group(2)):
            raise InputError(f"{unit}: not a synthetic unit id (expected synthetic:START-END)")
        if int(match.group(2)) >= self.num_scenarios:
            raise InputError(f"{unit}: beyond this synthetic unit set of {self.num_scenarios} scenarios")
        sizes = self.sizes or Sizes()
        extra = {} if self.knobs is None else {"knobs": self.knobs}
        for index in range(int(match.group(1)), int(match.group(2)) + 1):
            try:
                yield generate_scenario(self.seed, index, sizes, **extra)
            except Exception as error:  # noqa: BLE001 - one bad draw must not stop the run: record it
                yield Failure(unit, scenario_id(self.seed, index), f"{type(error).__name__}: {error}")

    def settings(self) -> dict:
        settings = {"num_scenarios": self.num_scenarios, "seed": self.seed,
                    "scenarios_per_unit": self.scenarios_per_unit,
                    "sizes": (self.sizes or Sizes()).as_dict()}
        if self.knobs is not None and not self.knobs.is_default():  # default knobs: manifests stay as they were
            settings["knobs"] = self.knobs.as_dict()
        return settings
