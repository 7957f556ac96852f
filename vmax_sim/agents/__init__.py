"""Learning algorithms: SAC, PPO, BC and BC+SAC as pure `(init, update, act)` learners.

    config = get_config("sac", "paper", batch_size=256)
    learner = make_learner("sac", config, encoder_factory, action_dim)
    state = learner.init(key, obs_example)              # batched example observation
    state, metrics = learner.update(state, batch, key)   # jittable
    action = learner.act(learner.policy_params(state), obs, key, deterministic=True)

See docs/agents.md for the losses, presets and design choices.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

from vmax_sim.agents import bc, bc_sac, distributions, ppo, sac
from vmax_sim.agents.bc import BCConfig
from vmax_sim.agents.bc_sac import BCSACConfig
from vmax_sim.agents.common import make_optimizer, polyak_update
from vmax_sim.agents.common import preset as _preset
from vmax_sim.agents.distributions import TanhGaussian
from vmax_sim.agents.networks import MLP, Actor, Critic, EncoderFactory, ValueNet
from vmax_sim.agents.ppo import PPOConfig
from vmax_sim.agents.sac import SACConfig
from vmax_sim.agents.types import Learner, Transition


class Algorithm(NamedTuple):
    name: str
    config_class: type
    presets: Mapping[str, Any]
    make_learner: Callable[[Any, EncoderFactory, int], Learner]
    on_policy: bool  # ppo: update takes (T, B) rollouts; the others sample replay batches


ALGORITHMS: Mapping[str, Algorithm] = {
    "sac": Algorithm("sac", SACConfig, sac.PRESETS, sac.make_learner, on_policy=False),
    "ppo": Algorithm("ppo", PPOConfig, ppo.PRESETS, ppo.make_learner, on_policy=True),
    "bc": Algorithm("bc", BCConfig, bc.PRESETS, bc.make_learner, on_policy=False),
    "bc_sac": Algorithm("bc_sac", BCSACConfig, bc_sac.PRESETS, bc_sac.make_learner, on_policy=False),
}


def _algorithm(name: str) -> Algorithm:
    if name not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {name!r}; choose one of {sorted(ALGORITHMS)}")
    return ALGORITHMS[name]


def get_config(algo: str, preset: str = "default", **overrides: Any):
    """The named preset of `algo` with field overrides, e.g. get_config("ppo", "paper", num_epochs=8)."""
    return _preset(_algorithm(algo).presets, preset, **overrides)


def make_learner(algo_name: str, config: Any, encoder_factory: EncoderFactory, action_dim: int) -> Learner:
    """The learner of `algo_name`; `config` None means its "default" preset."""
    algorithm = _algorithm(algo_name)
    if config is None:
        config = get_config(algo_name)
    if type(config) is not algorithm.config_class:
        raise TypeError(f"{algo_name} needs a {algorithm.config_class.__name__}, got {type(config).__name__}")
    return algorithm.make_learner(config, encoder_factory, action_dim)


__all__ = [
    "ALGORITHMS",
    "MLP",
    "Actor",
    "Algorithm",
    "BCConfig",
    "BCSACConfig",
    "Critic",
    "EncoderFactory",
    "Learner",
    "PPOConfig",
    "SACConfig",
    "TanhGaussian",
    "Transition",
    "ValueNet",
    "bc",
    "bc_sac",
    "distributions",
    "get_config",
    "make_learner",
    "make_optimizer",
    "polyak_update",
    "ppo",
    "sac",
]
