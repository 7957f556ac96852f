"""Closed-loop evaluation of driving policies: episodes, episode metrics, nuPlan / V-Max scores."""

from vmax_sim.evaluation.evaluate import MODES, SCORE_KEYS, EvaluationResult, evaluate, format_summary
from vmax_sim.evaluation.policies import (
    POLICY_NAMES,
    Policy,
    callable_policy,
    constant_policy,
    expert_policy,
    make_policy,
)
from vmax_sim.evaluation.rollout import Rollout, make_rollout_fn, run_episode

__all__ = [
    "MODES",
    "POLICY_NAMES",
    "SCORE_KEYS",
    "EvaluationResult",
    "Policy",
    "Rollout",
    "callable_policy",
    "constant_policy",
    "evaluate",
    "expert_policy",
    "format_summary",
    "make_policy",
    "make_rollout_fn",
    "run_episode",
]
