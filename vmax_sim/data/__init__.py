"""Loading scenariomax shards into fixed-shape, batched `SimulatorState`s."""

from vmax_sim.data.config import DataConfig, cache_dir
from vmax_sim.data.convert import (
    build_map_index_for,
    object_slots,
    roadgraph_selection,
    scenario_to_numpy_state,
    scenario_to_state,
    scenarios_to_batch,
    stack_states,
)
from vmax_sim.data.loader import (
    PrefetchIterator,
    indexed_to_numpy_state,
    iter_indexed_scenarios,
    iter_numpy_batches,
    iter_numpy_states,
    iter_scenarios,
    load_batch,
    make_data_iterator,
)

__all__ = [
    "DataConfig",
    "PrefetchIterator",
    "build_map_index_for",
    "cache_dir",
    "indexed_to_numpy_state",
    "iter_indexed_scenarios",
    "iter_numpy_batches",
    "iter_numpy_states",
    "iter_scenarios",
    "load_batch",
    "make_data_iterator",
    "object_slots",
    "roadgraph_selection",
    "scenario_to_numpy_state",
    "scenario_to_state",
    "scenarios_to_batch",
    "stack_states",
]
