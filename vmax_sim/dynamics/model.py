"""`DynamicsModel`: a named pair of pure functions (forward, inverse) plus action bounds.

Registry names: "bicycle", "bicycle_no_reverse" (its brake stops the car), "delta_local", "delta_global", "state".
Action normalisation maps the documented bounds linearly onto [-1, 1] (policies output [-1, 1]).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes.trajectory import Trajectory, select_timestep
from vmax_sim.dynamics import bicycle, delta, state

ForwardFn = Callable[[jax.Array, Trajectory, float], Trajectory]  # (action, current, dt) -> next
InverseStepFn = Callable[[Trajectory, Trajectory, float], jax.Array]  # (current, target, dt) -> action


@dataclasses.dataclass(frozen=True)
class DynamicsModel:
    name: str
    action_dim: int
    forward_fn: ForwardFn
    inverse_step_fn: InverseStepFn
    bounds: tuple[tuple[float, float], ...] | None  # (low, high) per action dim; None: no normalisation
    dt: float = bicycle.DT
    # Log-following controller for expert replay (closed loop on the simulated state); None: inverse_step.
    expert_step_fn: InverseStepFn | None = None

    def forward(self, action: jax.Array, current: Trajectory) -> Trajectory:
        """action (..., N, action_dim); current (..., N, 1) -> next state (..., N, 1)."""
        return self.forward_fn(action, current, self.dt)

    def inverse_step(self, current: Trajectory, target: Trajectory) -> jax.Array:
        """current, target (..., N, 1) -> action (..., N, action_dim) taking current towards target."""
        return self.inverse_step_fn(current, target, self.dt)

    def expert_step(self, current: Trajectory, target: Trajectory) -> jax.Array:
        """Action steering `current` onto `target`, correcting drift. (..., N, action_dim)"""
        return (self.expert_step_fn or self.inverse_step_fn)(current, target, self.dt)

    def inverse(self, trajectory: Trajectory, timestep: jax.Array) -> jax.Array:
        """Action reproducing the step timestep -> timestep + 1 of a log. (..., N, action_dim)"""
        current = select_timestep(trajectory, timestep)
        target = select_timestep(trajectory, jnp.asarray(timestep) + 1)
        return self.inverse_step(current, target)

    @property
    def action_low(self) -> jax.Array:
        return jnp.array([low for low, _ in self._require_bounds()], jnp.float32)

    @property
    def action_high(self) -> jax.Array:
        return jnp.array([high for _, high in self._require_bounds()], jnp.float32)

    def _require_bounds(self) -> tuple[tuple[float, float], ...]:
        if self.bounds is None:
            raise ValueError(f"dynamics {self.name!r} has no action bounds, so actions cannot be normalised")
        return self.bounds

    def normalize(self, action: jax.Array) -> jax.Array:
        """Physical action -> [-1, 1] (clipped). (..., action_dim)"""
        low, high = self.action_low, self.action_high
        return jnp.clip(2 * (action - low) / (high - low) - 1, -1.0, 1.0)

    def denormalize(self, action: jax.Array) -> jax.Array:
        """[-1, 1] action (clipped first) -> physical units. (..., action_dim)"""
        low, high = self.action_low, self.action_high
        return low + (jnp.clip(action, -1.0, 1.0) + 1) * (high - low) / 2


BICYCLE = DynamicsModel("bicycle", 2, bicycle.bicycle_forward, bicycle.bicycle_inverse_step,
                        (bicycle.ACCEL_BOUNDS, bicycle.CURVATURE_BOUNDS),
                        expert_step_fn=bicycle.bicycle_tracking_inverse_step)
BICYCLE_NO_REVERSE = dataclasses.replace(BICYCLE, name="bicycle_no_reverse",
                                         forward_fn=bicycle.bicycle_forward_no_reverse)
# models whose actions are (acceleration, curvature): what the planners and the constant policy drive with
BICYCLE_NAMES = (BICYCLE.name, BICYCLE_NO_REVERSE.name)
DELTA_LOCAL = DynamicsModel("delta_local", 3, delta.delta_local_forward, delta.delta_local_inverse_step,
                            delta.DELTA_LOCAL_BOUNDS)
DELTA_GLOBAL = DynamicsModel("delta_global", 3, delta.delta_global_forward, delta.delta_global_inverse_step,
                             delta.DELTA_GLOBAL_BOUNDS)
STATE = DynamicsModel("state", 5, state.state_forward, state.state_inverse_step, None)

_REGISTRY = {model.name: model for model in (BICYCLE, BICYCLE_NO_REVERSE, DELTA_LOCAL, DELTA_GLOBAL, STATE)}


def get_dynamics(name: str) -> DynamicsModel:
    """The dynamics model registered under `name`."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown dynamics {name!r}; choose one of {sorted(_REGISTRY)}")
    return _REGISTRY[name]


def dynamics_names() -> tuple[str, ...]:
    return tuple(sorted(_REGISTRY))
