"""Rewards: the V-Max paper's presets (safety, navigation, behavior) and weighted sums of metric terms."""

from vmax_sim.rewards.config import BEHAVIOR, NAVIGATION, REWARD_PRESETS, SAFETY, RewardConfig
from vmax_sim.rewards.reward import check_reward_config, compute_reward, reward_terms
from vmax_sim.rewards.terms import RewardTermFn, get_term, register_term, term_names

__all__ = ["BEHAVIOR", "NAVIGATION", "REWARD_PRESETS", "SAFETY", "RewardConfig", "RewardTermFn",
           "check_reward_config", "compute_reward", "get_term", "reward_terms", "register_term", "term_names"]
