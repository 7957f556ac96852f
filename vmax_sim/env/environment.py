"""`Environment`: pure reset/step over `SimulatorState`, with injected dynamics and termination.

Controlled objects move by the dynamics model; every other object replays the log
(non-reactive). The environment holds only static configuration, so its methods can be jitted,
vmapped and scanned freely. reset/step/is_* accept any leading batch dims; `BatchedEnvironment`
gives the same results through `vmap`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action, SimulatorState, Trajectory, fill_invalid, select_timestep, update_timestep
from vmax_sim.dynamics import DynamicsModel, get_dynamics
from vmax_sim.env.config import EnvConfig
from vmax_sim.env.termination import TerminationFn


def controlled_mask(config: EnvConfig, state: SimulatorState) -> jax.Array:
    """Which objects the policy drives under `config.controlled`. (..., num_objects) bool"""
    meta = state.object_metadata
    if config.controlled == "sdc":
        return meta.is_sdc
    if config.controlled == "controllable":
        return meta.is_sdc | meta.is_controllable
    return jnp.broadcast_to(jnp.asarray(config.controlled, bool), meta.is_sdc.shape)


def _check_shapes(config: EnvConfig, state: SimulatorState) -> None:
    if state.num_objects != config.max_num_objects:
        raise ValueError(f"state has {state.num_objects} objects but EnvConfig.max_num_objects is "
                         f"{config.max_num_objects}; load with DataConfig(num_objects={config.max_num_objects})")
    if config.last_timestep > state.num_timesteps - 1:
        raise ValueError(f"init_steps + episode_length = {config.init_steps + config.episode_length} exceeds the "
                         f"log's {state.num_timesteps} steps")


def controlled_bound(config: EnvConfig) -> int | None:
    """`ObjectMetadata.max_controlled` under `config.controlled`: 1 for "sdc", else no bound."""
    return 1 if config.controlled == "sdc" else None  # a mask (tuple) never equals "sdc"


def first_controlled_rows(is_controlled: jax.Array, count: int) -> jax.Array:
    """Slots of the first `count` controlled objects, in slot order (uncontrolled slots fill the rest).
    is_controlled (..., N) -> (..., count) int32"""
    n = is_controlled.shape[-1]
    rank = jnp.where(is_controlled, n - jnp.arange(n), 0)  # controlled first, lower slots first
    return jax.lax.top_k(rank, count)[1].astype(jnp.int32)


def forward_controlled(dynamics: DynamicsModel, action: jax.Array, current: Trajectory, is_controlled: jax.Array,
                       bound: int | None) -> tuple[Trajectory, jax.Array]:
    """The dynamics' next state and which objects it drives. action (..., N, A); current (..., N, 1);
    is_controlled (..., N) -> predicted (..., N, 1) (rows the model did not run on hold `current`), (..., N) bool.

    With a bound smaller than N the model runs only on the first `bound` controlled rows: under controlled="sdc"
    on one row instead of every object (its sines and cosines over 64 objects were ~40% of the physics step at
    batch 32, since XLA repeats them in each field it writes). Controlled objects past the bound are not driven.
    """
    n = is_controlled.shape[-1]
    if bound is None or bound >= n:
        return dynamics.forward(action, current), is_controlled
    rows = first_controlled_rows(is_controlled, bound)  # (..., k)

    def take(a):  # (..., N, c) -> (..., k, c)
        return jnp.take_along_axis(a, rows[..., None], axis=-2)

    driven = dynamics.forward(take(action), jax.tree.map(take, current))  # (..., k, 1)
    hit = rows[..., None, :] == jnp.arange(n)[:, None]  # (..., N, k): slot n is the k-th driven row
    in_rows = jnp.any(hit, axis=-1)

    def scatter(full, part):  # (..., N, 1), (..., k, 1) -> (..., N, 1)
        value = jnp.sum(jnp.where(hit, jnp.swapaxes(part, -1, -2), jnp.zeros((), part.dtype)), axis=-1)
        return jnp.where(in_rows[..., None], value[..., None].astype(full.dtype), full)

    return jax.tree.map(scatter, current, driven), is_controlled & in_rows


def merge_next_state(current: Trajectory, predicted: Trajectory, next_log: Trajectory, is_controlled: jax.Array,
                     action_valid: jax.Array) -> Trajectory:
    """Next object states: dynamics for controlled objects present now, the log for everyone else.

    current, predicted, next_log (..., N, 1); is_controlled (..., N); action_valid (..., N, 1).
    A controlled object given an invalid action becomes invalid; a controlled object not yet
    present follows the log until it appears.
    """
    is_driven = is_controlled[..., None] & current.valid
    predicted = predicted.replace(valid=current.valid & action_valid)
    return jax.tree.map(lambda p, log: jnp.where(is_driven, p, log), predicted, next_log)


def sdc_log_ended(state: SimulatorState) -> jax.Array:
    """The logged SDC has no valid step after the current timestep: its log ended (e.g. a test-split
    scenario whose future is padded invalid). False for a state without an SDC. (...) bool"""
    meta = state.object_metadata
    later = jnp.arange(state.num_timesteps) > state.timestep[..., None, None]  # (..., 1, T)
    has_future = jnp.any(state.log_trajectory.valid & later & meta.is_sdc[..., None], axis=(-2, -1))
    return jnp.any(meta.is_sdc, axis=-1) & ~has_future


class Environment:
    """Single-scenario environment (any leading batch dims work; see BatchedEnvironment for vmap)."""

    def __init__(self, config: EnvConfig | None = None, termination_fn: TerminationFn | None = None,
                 dynamics: DynamicsModel | None = None):
        self.config = config or EnvConfig()
        self.dynamics = dynamics or get_dynamics(self.config.dynamics)
        self.termination_fn = termination_fn

    @property
    def action_dim(self) -> int:
        return self.dynamics.action_dim

    def reset(self, state: SimulatorState, key: jax.Array | None = None) -> SimulatorState:
        """Starts an episode: the first init_steps come from the log, timestep = init_steps - 1.

        `key` is accepted for API symmetry (reset is deterministic).
        """
        del key
        _check_shapes(self.config, state)
        first = self.config.first_policy_timestep
        timestep = jnp.full(state.batch_shape, first, jnp.int32)
        is_past = jnp.arange(state.num_timesteps) <= timestep[..., None, None]  # (..., 1, T)
        sim_trajectory = fill_invalid(state.log_trajectory, is_past)
        return state.replace(
            sim_trajectory=sim_trajectory,
            object_metadata=state.object_metadata.replace(is_controlled=controlled_mask(self.config, state),
                                                          max_controlled=controlled_bound(self.config)),
            timestep=timestep,
            current_sim=select_timestep(sim_trajectory, timestep),
        )

    def step(self, state: SimulatorState, action: Action) -> SimulatorState:
        """Advances one step. action.data (..., N, action_dim) in the env's convention (see normalize_actions)."""
        data = action.data.astype(jnp.float32)
        if self.config.normalize_actions:
            data = self.dynamics.denormalize(data)
        current = state.current_sim_trajectory
        meta = state.object_metadata
        predicted, driven = forward_controlled(self.dynamics, data, current, meta.is_controlled,
                                               meta.max_controlled)
        new = merge_next_state(current, predicted, state.next_log_trajectory, driven, action.valid)
        next_timestep = jnp.minimum(state.timestep + 1, state.num_timesteps - 1).astype(jnp.int32)
        new = jax.tree.map(lambda a, v: v.astype(a.dtype), state.sim_trajectory, new)  # as written
        return state.replace(sim_trajectory=update_timestep(state.sim_trajectory, next_timestep, new),
                             timestep=next_timestep, current_sim=new)

    def is_terminated(self, state: SimulatorState) -> jax.Array:
        """The injected termination predicate (False without one). (...) bool"""
        if self.termination_fn is None:
            return jnp.zeros(state.batch_shape, bool)
        return jnp.asarray(self.termination_fn(state), bool)

    def is_truncated(self, state: SimulatorState) -> jax.Array:
        """The episode reached its length, the end of the log, or the end of the SDC's log (nothing logged
        to follow or to compare with after it). (...) bool"""
        return (state.timestep >= self.config.last_timestep) | state.is_done | sdc_log_ended(state)

    def is_done(self, state: SimulatorState) -> jax.Array:
        """(...) bool"""
        return self.is_terminated(state) | self.is_truncated(state)

    def expert_action(self, state: SimulatorState) -> Action:
        """Log-following action in this env's convention (normalised when normalize_actions)."""
        from vmax_sim.env.expert import expert_actions

        action = expert_actions(state, self.dynamics)
        if self.config.normalize_actions:
            action = action.replace(data=self.dynamics.normalize(action.data))
        return action
