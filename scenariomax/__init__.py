"""scenariomax: convert driving datasets into one sharded TFRecord schema (numpy + protobuf only)."""

from scenariomax.codec import BudgetError, SchemaError, decode_scenario, encode_scenario
from scenariomax.scenario import Scenario
from scenariomax.schema import ShardSchema, Sizes, default_sizes, load_schema
from scenariomax.shards import ShardReadError, read_shards, write_shards

__version__ = "0.1.0"

__all__ = [
    "Scenario", "Sizes", "ShardSchema", "load_schema", "default_sizes", "read_shards", "write_shards",
    "encode_scenario", "decode_scenario", "BudgetError", "SchemaError", "ShardReadError", "__version__",
]
