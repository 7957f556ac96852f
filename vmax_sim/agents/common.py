"""Small pieces every learner shares: optimiser, Polyak averaging, config presets and overrides."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

import jax
import jax.numpy as jnp
import optax

from vmax_sim.agents.types import Params

ConfigT = TypeVar("ConfigT")


def make_optimizer(learning_rate: float, max_grad_norm: float | None = None) -> optax.GradientTransformation:
    """Adam, preceded by clipping of the global gradient norm when `max_grad_norm` is set."""
    adam = optax.adam(learning_rate)
    if max_grad_norm is None:
        return adam
    return optax.chain(optax.clip_by_global_norm(max_grad_norm), adam)


def polyak_update(params: Params, target_params: Params, tau: float) -> Params:
    """target <- tau * params + (1 - tau) * target, leaf by leaf."""
    return optax.incremental_update(params, target_params, tau)


def ema_weight(step: jax.Array, decay: float) -> jax.Array:
    """The share of the new parameters in the average after update `step` (0-based): 1 - decay, but larger for
    the first updates (1 - (1 + step) / (10 + step) while that is larger) so the average soon leaves the random
    initialisation instead of carrying it for 1 / (1 - decay) updates."""
    warm = 1.0 - (1.0 + step) / (10.0 + step)
    return jnp.maximum(1.0 - decay, warm.astype(jnp.float32))


def learning_rate_scale(progress: float, decay_start: float, end_fraction: float) -> float:
    """The learning rate's share at `progress` (0..1) of a run: 1 until `decay_start`, then linear down to
    `end_fraction` at 1 (and held there past it)."""
    share = min(max((progress - decay_start) / (1.0 - decay_start), 0.0), 1.0)
    return 1.0 - share * (1.0 - end_fraction)


def apply_gradients(optimizer: optax.GradientTransformation, grads: Params, opt_state, params: Params):
    """One optimiser step: (params, opt_state) after applying `grads`."""
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state


def global_norm(tree: Params) -> jax.Array:
    """() L2 norm of all leaves together."""
    return jnp.sqrt(sum(jnp.sum(jnp.square(x)) for x in jax.tree.leaves(tree)))


def row_mean(values: jax.Array, weights: jax.Array | None) -> jax.Array:
    """values (..., B) -> (...) their mean over the batch rows B, weighted by weights (B,) when given (self-play's
    empty and finished agent slots weigh 0; a batch of such rows only has no mean: 0, not nan)."""
    if weights is None:
        return jnp.mean(values, axis=-1)
    return jnp.sum(weights * values, axis=-1) / jnp.maximum(jnp.sum(weights), 1e-6)


def scalar(x) -> jax.Array:
    """A () float32 metric."""
    return jnp.asarray(x, jnp.float32).reshape(())


def with_overrides(config: ConfigT, **overrides: Any) -> ConfigT:
    """`dataclasses.replace` that names unknown fields and turns lists into tuples (configs stay hashable)."""
    fields = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise ValueError(f"{type(config).__name__} has no field(s) {unknown}; fields are {sorted(fields)}")
    overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in overrides.items()}
    return dataclasses.replace(config, **overrides)


def preset(presets: Mapping[str, ConfigT], name: str, **overrides: Any) -> ConfigT:
    """The named preset with field overrides applied."""
    if name not in presets:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(presets)}")
    return with_overrides(presets[name], **overrides)


def check_positive(config, *names: str) -> None:
    for name in names:
        if not getattr(config, name) > 0:
            raise ValueError(f"{type(config).__name__}.{name} must be > 0, got {getattr(config, name)!r}")


def check_unit_interval(config, *names: str) -> None:
    for name in names:
        if not 0.0 <= getattr(config, name) <= 1.0:
            raise ValueError(f"{type(config).__name__}.{name} must be in [0, 1], got {getattr(config, name)!r}")
