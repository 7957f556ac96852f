"""Closed-loop evaluation of driving policies: episodes, episode metrics, nuPlan / V-Max scores."""

from vmax_sim.evaluation.difficulty import DifficultyCollector, DifficultySignals, scenario_difficulty
from vmax_sim.evaluation.evaluate import MODES, SCORE_KEYS, EvaluationResult, evaluate, format_summary
from vmax_sim.evaluation.gallery import GalleryCollector
from vmax_sim.evaluation.modes import MODE_NAMES, EvalMode, PerturbConfig, parse_mode
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
    "MODE_NAMES",
    "POLICY_NAMES",
    "SCORE_KEYS",
    "DifficultyCollector",
    "DifficultySignals",
    "EvalMode",
    "EvaluationResult",
    "GalleryCollector",
    "PerturbConfig",
    "Policy",
    "Rollout",
    "callable_policy",
    "constant_policy",
    "evaluate",
    "expert_policy",
    "format_summary",
    "make_policy",
    "make_rollout_fn",
    "parse_mode",
    "run_episode",
    "scenario_difficulty",
]
