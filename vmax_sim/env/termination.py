"""Building one termination function from named metric predicates."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState

TerminationFn = Callable[[SimulatorState], jax.Array]  # state (...) -> (...) bool


def combine_termination_fns(fns_by_name: Mapping[str, TerminationFn], names: Sequence[str]) -> TerminationFn | None:
    """The OR of the named predicates (None when `names` is empty); unknown names raise ValueError."""
    unknown = [name for name in names if name not in fns_by_name]
    if unknown:
        raise ValueError(f"no termination function for {unknown}; known: {sorted(fns_by_name)}")
    if not names:
        return None
    chosen = [fns_by_name[name] for name in names]

    def termination_fn(state: SimulatorState) -> jax.Array:
        result = jnp.zeros(state.batch_shape, bool)
        for fn in chosen:
            result = result | fn(state)
        return result

    return termination_fn
