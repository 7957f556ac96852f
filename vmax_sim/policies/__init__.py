"""Rule-based driving policies: IDM + pure pursuit, PDM-Closed, and uniform random actions.

Each `*_policy(env, config)` returns a `Policy` (vmax_sim.policies.base) whose action_fn drives the SDC of one
unbatched state (the rollout vmaps it); `idm_action` / `pdm_action` are the pure planners.
"""

from vmax_sim.policies.base import ActionFn, Policy
from vmax_sim.policies.idm import IDMConfig, idm_acceleration, idm_action, idm_policy, pure_pursuit_curvature
from vmax_sim.policies.pdm import PDMConfig, pdm_action, pdm_plan, pdm_policy
from vmax_sim.policies.random import random_policy

__all__ = [
    "ActionFn",
    "IDMConfig",
    "PDMConfig",
    "Policy",
    "idm_acceleration",
    "idm_action",
    "idm_policy",
    "pdm_action",
    "pdm_plan",
    "pdm_policy",
    "pure_pursuit_curvature",
    "random_policy",
]
