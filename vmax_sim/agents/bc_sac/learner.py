"""BC+SAC learner: the SAC learner with the imitation-augmented actor loss."""

from __future__ import annotations

from vmax_sim.agents.bc_sac.config import BCSACConfig
from vmax_sim.agents.bc_sac.losses import make_actor_loss
from vmax_sim.agents.networks import EncoderFactory
from vmax_sim.agents.sac.learner import SACTrainState, build_learner
from vmax_sim.agents.sac.networks import make_networks
from vmax_sim.agents.types import Learner

BCSACTrainState = SACTrainState  # same state: the imitation term adds no parameters


def make_learner(config: BCSACConfig, encoder_factory: EncoderFactory, action_dim: int) -> Learner:
    """`update(state, batch, key)` reads batch.expert_action on top of SAC's fields."""
    networks = make_networks(config, encoder_factory, action_dim)
    return build_learner(config, networks, lambda losses: make_actor_loss(networks, losses, config))
