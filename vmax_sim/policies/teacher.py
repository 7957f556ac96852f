"""Rule-based teachers for behaviour cloning (`train.teacher`): a planner's SDC action as the label.

The logged driver's next action is not a function of what the SDC can observe (it follows the driver's
intentions and the other drivers' future), so a policy that imitates the log learns an average over
situations it cannot tell apart, and nothing at the states off the log it drives into. A planner's action
is a function of the current state (PDM-Closed forecasts the others from it), so it can be imitated
closed loop, at every state the student visits (DART / DAgger-style), and it is the same driver the
student is measured against on real roads.

`LearningEnv(teacher=pdm_teacher)` calls the factory with its core Environment (normalised actions) and
labels every step with the returned function's action. The teachers are the evaluation's own rule policies
(`idm_policy`, `pdm_policy`), read at the SDC's slot. Jittable, one unbatched state.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.metrics_adapter import sdc_index
from vmax_sim.policies.base import Policy

TeacherFn = Callable[[SimulatorState], jax.Array]  # one unbatched state -> the SDC's action (A,) in [-1, 1]


def policy_teacher(policy: Policy) -> TeacherFn:
    """The SDC's action of a rule-based policy (no parameters, no observation, no randomness), clipped to [-1, 1]
    (the env the policy was built for must normalise its actions, as LearningEnv's core does)."""

    def teach(state: SimulatorState) -> jax.Array:
        action = policy.action_fn(None, state, None, None).data[sdc_index(state)]
        return jnp.clip(action, -1.0, 1.0).astype(jnp.float32)

    return teach


def idm_teacher(env, speed_factor: float = 1.0, max_accel: float | None = None,
                bend_lateral_accel: float | None = None) -> TeacherFn:
    """IDM + pure pursuit along the SDC's route, at `speed_factor` x the lane's speed limit, accelerating at up to
    `max_accel` and taking bends at up to `bend_lateral_accel` (m/s^2; None: IDMConfig's). The defaults are the
    evaluation's IDM."""
    from vmax_sim.policies.idm import IDMConfig, idm_policy

    given = {"max_accel": max_accel, "bend_lateral_accel": bend_lateral_accel}
    config = IDMConfig(speed_factor=speed_factor, **{name: value for name, value in given.items() if value is not None})
    return policy_teacher(idm_policy(env, config))


def pdm_teacher(env) -> TeacherFn:
    """PDM-Closed (the evaluation's): 15 IDM proposals scored by a forecast of the others."""
    from vmax_sim.policies.pdm import pdm_policy

    return policy_teacher(pdm_policy(env))


def pdm_state_teacher(env) -> TeacherFn:
    """PDM-Closed without its jerk limit: the label is a function of the current state alone.

    The evaluation's PDM-Closed starts every proposal from the acceleration executed last and may change it by
    0.4 m/s^2 per step, so its label is mostly the SDC's last action. A student imitating it learns to repeat its
    own last action plus a correction smaller than its error (normalised accel MAE 0.035 against 0.067 per step
    allowed), and on its own its acceleration drifts like a random walk: on an empty road it slowed from 16.5 to
    5 m/s while the teacher, labelling those states, could only ease off its braking at the jerk limit."""
    from vmax_sim.policies.pdm import PDMConfig, pdm_policy

    return policy_teacher(pdm_policy(env, PDMConfig(max_jerk=0.0, first_step_comfort=False)))


__all__ = ["TeacherFn", "idm_teacher", "pdm_state_teacher", "pdm_teacher", "policy_teacher"]
