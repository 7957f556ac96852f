"""scenariomax: convert driving datasets into one sharded TFRecord schema (numpy + protobuf only).

The public API is what this module exports (`__all__`) plus the public modules in `PUBLIC_MODULES`
(each exports its public names: those without a leading underscore). Everything else — the enrichment
steps, the source datasets' parsers, the pipeline's plumbing — is internal and may change; `vmax_sim`
uses only the public API (tests/foundation/test_public_api.py checks it).

`import scenariomax` stays light (numpy + protobuf; never jax or tensorflow): the reader, the schema and
the errors are imported now, the conversion, enrichment, synthetic source, rendering and inspection
entry points on first use.
"""

from __future__ import annotations

import importlib

from scenariomax import schema
from scenariomax.codec import BudgetError, SchemaError, decode_scenario, encode_scenario
from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.schema import ShardSchema, Sizes, default_sizes, load_schema
from scenariomax.shards import (
    ShardReadError,
    ShardRecord,
    iter_shard_records,
    list_shard_files,
    read_shards,
    write_shards,
)

__version__ = "0.1.0"

# Modules other packages may import from: the shard format's constants and sizes, the shared errors and
# progress display, TFRecord framing, picture rendering, shard inspection and the web viewer.
PUBLIC_MODULES = (
    "scenariomax",
    "scenariomax.crop",
    "scenariomax.errors",
    "scenariomax.locks",
    "scenariomax.progress",
    "scenariomax.schema",
    "scenariomax.io",
    "scenariomax.render",
    "scenariomax.inspect",
    "scenariomax.view",
    "scenariomax.validate",  # record and shard checks: train / evaluate run them before starting
)

# Entry points imported on first use (name -> module): they pull in scipy, shapely or matplotlib.
_LAZY = {
    "ConvertSettings": "scenariomax.pipeline",
    "ConversionError": "scenariomax.pipeline",
    "convert": "scenariomax.pipeline",
    "make_transform": "scenariomax.enrich.transform",
    "fit_to_budget": "scenariomax.enrich.budget",
    "SyntheticSource": "scenariomax.sources.synthetic",
    "SyntheticKnobs": "scenariomax.sources.synthetic",
    "draw_scenario": "scenariomax.render",
    "render_scenario": "scenariomax.render",
    "format_report": "scenariomax.inspect",
    "inspect_shards": "scenariomax.inspect",
    "load_scenario": "scenariomax.inspect",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # later look-ups skip this function
        return value
    raise AttributeError(f"module 'scenariomax' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    # shards: read, write, list, and the in-memory scenario
    "Scenario", "read_shards", "write_shards", "list_shard_files", "encode_scenario", "decode_scenario",
    "iter_shard_records", "ShardRecord",
    # the schema (module and sizes)
    "schema", "Sizes", "ShardSchema", "load_schema", "default_sizes",
    # conversion, enrichment and the synthetic source
    "convert", "ConvertSettings", "make_transform", "fit_to_budget", "SyntheticSource", "SyntheticKnobs",
    # pictures and inspection
    "render_scenario", "draw_scenario", "inspect_shards", "format_report", "load_scenario",
    # errors a user can cause
    "InputError", "BudgetError", "SchemaError", "ShardReadError", "ConversionError",
    "PUBLIC_MODULES", "__version__",
]
