"""Wrappers: vmap batching, auto-reset from a pre-loaded scenario pool, episode-length limit."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from vmax_sim.datatypes import Action, SimulatorState


class EnvWrapper:
    """Forwards everything to the wrapped environment."""

    def __init__(self, env):
        self.env = env

    def __getattr__(self, name):  # config, dynamics, action_dim, expert_action, ...
        return getattr(self.env, name)

    def reset(self, state: SimulatorState, key: jax.Array | None = None) -> SimulatorState:
        return self.env.reset(state, key)

    def step(self, state: SimulatorState, action: Action) -> SimulatorState:
        return self.env.step(state, action)

    def is_terminated(self, state: SimulatorState) -> jax.Array:
        return self.env.is_terminated(state)

    def is_truncated(self, state: SimulatorState) -> jax.Array:
        return self.env.is_truncated(state)

    def is_done(self, state: SimulatorState) -> jax.Array:
        return self.is_terminated(state) | self.is_truncated(state)


class BatchedEnvironment(EnvWrapper):
    """Maps an unbatched environment over a leading batch axis with `jax.vmap`."""

    def reset(self, state: SimulatorState, key: jax.Array | None = None) -> SimulatorState:
        return jax.vmap(lambda s: self.env.reset(s, None))(state)

    def step(self, state: SimulatorState, action: Action) -> SimulatorState:
        return jax.vmap(self.env.step)(state, action)

    def is_terminated(self, state: SimulatorState) -> jax.Array:
        return jax.vmap(self.env.is_terminated)(state)

    def is_truncated(self, state: SimulatorState) -> jax.Array:
        return jax.vmap(self.env.is_truncated)(state)

    def expert_action(self, state: SimulatorState) -> Action:
        return jax.vmap(self.env.expert_action)(state)


class EpisodeLimit(EnvWrapper):
    """Truncates episodes after `max_steps` policy steps (tighter than EnvConfig.episode_length)."""

    def __init__(self, env, max_steps: int):
        super().__init__(env)
        if max_steps < 1:
            raise ValueError(f"EpisodeLimit.max_steps must be at least 1, got {max_steps}")
        self.max_steps = max_steps

    def is_truncated(self, state: SimulatorState) -> jax.Array:
        steps_taken = state.timestep - self.env.config.first_policy_timestep
        return self.env.is_truncated(state) | (steps_taken >= self.max_steps)


@struct.dataclass
class AutoResetState:
    state: SimulatorState  # (B, ...) the running episodes
    pool: SimulatorState  # (S, ...) scenarios to draw fresh episodes from, in order (cycled)
    next_scenario: jax.Array  # () int32, index in the pool of the next episode to start
    done: jax.Array  # (B,) bool, the last step ended these episodes (state now holds fresh ones)
    terminated: jax.Array  # (B,) bool, ... and ended them by termination (not truncation)


class AutoResetEnvironment:
    """A batch of B episodes; each finished one restarts with the next scenario of the pool.

    `env` is an unbatched environment. The pool rides in the carry (not as a jit constant), so
    the whole loop can be one `lax.scan`. Fresh scenarios are gathered only on steps where some
    episode ended (`lax.cond`).
    """

    def __init__(self, env, batch_size: int):
        self.env = env
        self.batched = BatchedEnvironment(env)
        self.batch_size = batch_size

    def reset(self, pool: SimulatorState, key: jax.Array | None = None) -> AutoResetState:
        """Starts B episodes on pool scenarios 0..B-1 (cycled when the pool is smaller)."""
        del key
        pool_size = pool.timestep.shape[0]
        indices = jnp.arange(self.batch_size) % pool_size
        state = self.batched.reset(jax.tree.map(lambda a: a[indices], pool))
        no = jnp.zeros(self.batch_size, bool)
        return AutoResetState(state=state, pool=pool, next_scenario=jnp.asarray(self.batch_size % pool_size, jnp.int32),
                              done=no, terminated=no)

    def step(self, carry: AutoResetState, action: Action) -> AutoResetState:
        stepped = self.batched.step(carry.state, action)
        terminated = self.batched.is_terminated(stepped)
        done = terminated | self.batched.is_truncated(stepped)
        pool_size = carry.pool.timestep.shape[0]

        def restart(_):
            # The k-th finished episode takes the k-th next scenario of the pool.
            indices = (carry.next_scenario + jnp.cumsum(done) - 1) % pool_size
            fresh = self.batched.reset(jax.tree.map(lambda a: a[indices], carry.pool))

            def mask(a):
                return done.reshape(done.shape + (1,) * (a.ndim - 1))

            return jax.tree.map(lambda f, s: jnp.where(mask(s), f, s), fresh, stepped)

        state = jax.lax.cond(jnp.any(done), restart, lambda _: stepped, None)
        next_scenario = ((carry.next_scenario + jnp.sum(done)) % pool_size).astype(jnp.int32)
        return AutoResetState(state=state, pool=carry.pool, next_scenario=next_scenario, done=done,
                              terminated=terminated)
