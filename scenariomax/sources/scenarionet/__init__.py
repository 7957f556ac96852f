"""ScenarioNet / MetaDrive scenario descriptions (`sd_*.pkl`), read with a restricted unpickler."""

from scenariomax.sources.scenarionet.convert import description_windows, resample_indices, stable_int_ids
from scenariomax.sources.scenarionet.source import ScenarioNetSource
from scenariomax.sources.scenarionet.unpickle import (
    ALLOWED_GLOBALS,
    RefusedGlobalError,
    RestrictedUnpickler,
    load_pickle,
    loads_restricted,
)

__all__ = [
    "ALLOWED_GLOBALS",
    "RefusedGlobalError",
    "RestrictedUnpickler",
    "ScenarioNetSource",
    "description_windows",
    "load_pickle",
    "loads_restricted",
    "resample_indices",
    "stable_int_ids",
]
