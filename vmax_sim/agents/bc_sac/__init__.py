"""BC+SAC: SAC whose actor loss adds a behaviour-cloning term every `bc_every` updates."""

from vmax_sim.agents.bc_sac.config import PRESETS, BCSACConfig, get_config
from vmax_sim.agents.bc_sac.learner import BCSACTrainState, make_learner

__all__ = ["PRESETS", "BCSACConfig", "BCSACTrainState", "get_config", "make_learner"]
