"""Environments over `SimulatorState`: single/multi-agent, wrappers, expert actions, gym adapter."""

from vmax_sim.env.config import EnvConfig
from vmax_sim.env.environment import Environment, controlled_mask, merge_next_state, sdc_log_ended
from vmax_sim.env.expert import expert_actions, log_actions
from vmax_sim.env.factory import make_environment
from vmax_sim.env.gym_adapter import Box, GymEnv, sdc_frame_features, zero_reward
from vmax_sim.env.metrics_adapter import make_termination_fn, termination_fns
from vmax_sim.env.multi_agent import MultiAgentEnvironment, merge_actions, sdc_and_agents_action
from vmax_sim.env.termination import TerminationFn, combine_termination_fns
from vmax_sim.env.wrappers import (
    AutoResetEnvironment,
    AutoResetState,
    BatchedEnvironment,
    EnvWrapper,
    EpisodeLimit,
)

__all__ = [
    "AutoResetEnvironment",
    "AutoResetState",
    "BatchedEnvironment",
    "Box",
    "EnvConfig",
    "EnvWrapper",
    "Environment",
    "EpisodeLimit",
    "GymEnv",
    "MultiAgentEnvironment",
    "TerminationFn",
    "combine_termination_fns",
    "controlled_mask",
    "expert_actions",
    "log_actions",
    "make_environment",
    "make_termination_fn",
    "merge_actions",
    "merge_next_state",
    "sdc_and_agents_action",
    "sdc_frame_features",
    "sdc_log_ended",
    "termination_fns",
    "zero_reward",
]
