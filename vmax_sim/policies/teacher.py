"""Rule-based teachers for behaviour cloning (`train.teacher`): a planner's SDC action as the label.

The logged driver's next action is not a function of what the SDC can observe (it follows the driver's
intentions and the other drivers' future), so a policy that imitates the log learns an average over
situations it cannot tell apart, and nothing at the states off the log it drives into. A planner's action
is a function of the current state (PDM-Closed forecasts the others from it), so it can be imitated
closed loop, at every state the student visits (DART / DAgger-style), and it is the same driver the
student is measured against on real roads.

`LearningEnv(teacher=pdm_teacher)` calls the factory with its core Environment (normalised actions) and
labels every step with the returned function's action. Jittable, one unbatched state.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState

TeacherFn = Callable[[SimulatorState], jax.Array]  # one unbatched state -> the SDC's action (A,) in [-1, 1]


def planner_teacher(env, name: str, plan_fn: Callable[[SimulatorState, int], jax.Array]) -> TeacherFn:
    """A teacher from plan_fn(state, first_timestep) -> the SDC's physical (2,) bicycle action."""
    from vmax_sim.policies.idm import check_bicycle

    check_bicycle(env, f"{name} teacher's")
    first = env.config.first_policy_timestep

    def teach(state: SimulatorState) -> jax.Array:
        action = env.dynamics.normalize(plan_fn(state, first))
        return jnp.clip(action, -1.0, 1.0).astype(jnp.float32)

    return teach


def idm_teacher(env) -> TeacherFn:
    """IDM + pure pursuit along the SDC's route, at the lane's speed limit (the evaluation's IDM)."""
    from vmax_sim.policies.idm import IDMConfig, idm_action

    config = IDMConfig()
    return planner_teacher(env, "idm", lambda state, first: idm_action(state, config, first))


def pdm_teacher(env) -> TeacherFn:
    """PDM-Closed (the evaluation's): 15 IDM proposals scored by a forecast of the others."""
    from vmax_sim.policies.pdm import PDMConfig, pdm_action

    config = PDMConfig()
    return planner_teacher(env, "pdm", lambda state, first: pdm_action(state, config, first))


__all__ = ["TeacherFn", "idm_teacher", "pdm_teacher", "planner_teacher"]
