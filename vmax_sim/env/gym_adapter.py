"""`GymEnv`: a gymnasium-style, single-episode adapter (duck-typed; gymnasium is not needed).

reset(seed) -> (obs, info); step(action) -> (obs, reward, terminated, truncated, info), with numpy
in and out. Each reset takes the next scenario of a pre-loaded pool (or a seeded random one).
The step, observation and reward run as one jitted function.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from vmax_sim.datatypes import Action, SimulatorState
from vmax_sim.env.environment import Environment
from vmax_sim.env.metrics_adapter import sdc_index

ObservationFn = Callable[[SimulatorState], jax.Array]  # unbatched state -> (obs_dim...) float32
RewardFn = Callable[[SimulatorState, Action, SimulatorState], jax.Array]  # (state, action, next) -> () float32


@dataclasses.dataclass(frozen=True)
class Box:
    """The fields of gymnasium.spaces.Box that agents read."""

    low: np.ndarray
    high: np.ndarray
    shape: tuple[int, ...]
    dtype: type = np.float32

    def contains(self, value) -> bool:
        value = np.asarray(value)
        return value.shape == self.shape and bool(np.all(value >= self.low) and np.all(value <= self.high))


def sdc_frame_features(state: SimulatorState) -> jax.Array:
    """Every object at the current step in the SDC's frame, flattened. (num_objects * 9,) float32

    Per object: x, y, vel_x, vel_y (rotated into the SDC frame), cos and sin of the relative yaw,
    length, width, valid. Invalid objects are zeros.
    """
    current = state.current_sim_trajectory  # (N, 1)
    sdc = sdc_index(state)
    origin_x, origin_y, origin_yaw = current.x[sdc, 0], current.y[sdc, 0], current.yaw[sdc, 0]
    cos, sin = jnp.cos(origin_yaw), jnp.sin(origin_yaw)
    dx, dy = current.x[:, 0] - origin_x, current.y[:, 0] - origin_y
    vx, vy = current.vel_x[:, 0], current.vel_y[:, 0]
    relative_yaw = current.yaw[:, 0] - origin_yaw
    features = jnp.stack([
        dx * cos + dy * sin, -dx * sin + dy * cos, vx * cos + vy * sin, -vx * sin + vy * cos,
        jnp.cos(relative_yaw), jnp.sin(relative_yaw), current.length[:, 0], current.width[:, 0],
        jnp.ones_like(dx),
    ], axis=-1)
    return jnp.where(current.valid, features, 0.0).reshape(-1).astype(jnp.float32)


def zero_reward(state: SimulatorState, action: Action, next_state: SimulatorState) -> jax.Array:
    del state, action, next_state
    return jnp.zeros((), jnp.float32)


class GymEnv:
    """Single-episode, numpy-facing adapter around an (unbatched) `Environment`.

    `scenarios` is a batch of states (leading axis = pool size), e.g. from `load_batch`. The
    action is (action_dim,) for the SDC, or (num_objects, action_dim) for every controlled object.
    """

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(self, env: Environment, scenarios: SimulatorState, observation_fn: ObservationFn | None = None,
                 reward_fn: RewardFn | None = None, shuffle: bool = False):
        self.env = env
        self.scenarios = scenarios
        self.num_scenarios = int(scenarios.timestep.shape[0])
        self.observation_fn = observation_fn or sdc_frame_features
        self.reward_fn = reward_fn or zero_reward
        self.shuffle = shuffle
        self._rng = np.random.default_rng()
        self._next_scenario = 0
        self._state: SimulatorState | None = None
        self._reset_fn = jax.jit(self._reset_pure)
        self._step_fn = jax.jit(self._step_pure)
        obs_shape = jax.eval_shape(self._reset_pure, scenarios, 0)[1].shape
        self.observation_space = Box(np.full(obs_shape, -np.inf, np.float32), np.full(obs_shape, np.inf, np.float32),
                                     tuple(obs_shape))
        dim = env.dynamics.action_dim
        if env.config.normalize_actions:
            low, high = -np.ones(dim, np.float32), np.ones(dim, np.float32)
        elif env.dynamics.bounds is not None:
            low, high = np.asarray(env.dynamics.action_low), np.asarray(env.dynamics.action_high)
        else:
            low, high = np.full(dim, -np.inf, np.float32), np.full(dim, np.inf, np.float32)
        self.action_space = Box(low, high, (dim,))

    # Pure parts (jitted once) ---------------------------------------------------------------------
    def _reset_pure(self, scenarios: SimulatorState, index):
        state = self.env.reset(jax.tree.map(lambda a: a[index], scenarios))
        return state, self.observation_fn(state)

    def _step_pure(self, state: SimulatorState, action_data: jax.Array):
        num_objects, dim = state.num_objects, self.env.dynamics.action_dim
        is_controlled = state.object_metadata.is_controlled
        data = jnp.broadcast_to(action_data.reshape(-1, dim), (num_objects, dim)).astype(jnp.float32)
        action = Action(data=data, valid=is_controlled[:, None])
        next_state = self.env.step(state, action)
        reward = self.reward_fn(state, action, next_state)
        return (next_state, self.observation_fn(next_state), reward, self.env.is_terminated(next_state),
                self.env.is_truncated(next_state))

    # Gymnasium-style API ----------------------------------------------------------------------------
    def reset(self, seed: int | None = None, options: dict | None = None):
        """Starts an episode on the next pool scenario (a random one when seeded or shuffle=True)."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        if seed is not None or self.shuffle:
            index = int(self._rng.integers(self.num_scenarios))
        else:
            index = self._next_scenario
            self._next_scenario = (self._next_scenario + 1) % self.num_scenarios
        if options and "scenario_index" in options:
            index = int(options["scenario_index"]) % self.num_scenarios
        self._state, obs = self._reset_fn(self.scenarios, jnp.asarray(index, jnp.int32))
        return np.asarray(obs), {"scenario_index": index, "timestep": int(self._state.timestep)}

    def step(self, action):
        if self._state is None:
            raise RuntimeError("GymEnv.step called before reset")
        action = np.asarray(action, np.float32)
        dim = self.env.dynamics.action_dim
        if action.shape not in ((dim,), (self._state.num_objects, dim)):
            raise ValueError(f"action has shape {action.shape}, expected ({dim},) or "
                             f"({self._state.num_objects}, {dim})")
        self._state, obs, reward, terminated, truncated = self._step_fn(self._state, jnp.asarray(action))
        info = {"timestep": int(self._state.timestep)}
        return np.asarray(obs), float(reward), bool(terminated), bool(truncated), info

    @property
    def state(self) -> SimulatorState | None:
        """The current simulator state (for rendering or metrics)."""
        return self._state

    def close(self) -> None:
        self._state = None
