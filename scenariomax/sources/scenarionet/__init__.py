"""ScenarioNet / MetaDrive scenario descriptions (`.pkl`), read with a restricted unpickler."""

from scenariomax.sources.scenarionet.convert import description_windows, resample_indices, stable_int_ids
from scenariomax.sources.scenarionet.source import ScenarioNetSource, find_scenario_files
from scenariomax.sources.scenarionet.unpickle import (
    ALLOWED_GLOBALS,
    INDEX_LIMITS,
    SCENARIO_LIMITS,
    PickleLimitError,
    PickleLimits,
    RefusedGlobalError,
    RestrictedUnpickler,
    expanded_size,
    load_pickle,
    loads_restricted,
)

__all__ = [
    "ALLOWED_GLOBALS",
    "INDEX_LIMITS",
    "SCENARIO_LIMITS",
    "PickleLimitError",
    "PickleLimits",
    "RefusedGlobalError",
    "RestrictedUnpickler",
    "ScenarioNetSource",
    "description_windows",
    "expanded_size",
    "find_scenario_files",
    "load_pickle",
    "loads_restricted",
    "resample_indices",
    "stable_int_ids",
]
