"""BC+SAC settings: every SAC field plus the imitation term's schedule and weight.

"paper" follows the released V-Max BC+SAC configuration: SAC with lr 1e-4, gamma 0.99, tau 0.005,
alpha 0.2, batch 64, 4 updates per env step, 500k buffer, 50k learning starts, and an imitation term
every 8 updates. (The release steps a separate imitation optimiser with lr 5e-5; here the term is added
to the actor loss, weighted by `bc_weight`, so one Adam state serves both.) "default" sizes the buffer and
warm-up for one machine; "debug" is tiny and fast.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vmax_sim.agents.common import check_positive, preset
from vmax_sim.agents.sac.config import PRESETS as SAC_PRESETS
from vmax_sim.agents.sac.config import SACConfig


@dataclasses.dataclass(frozen=True)
class BCSACConfig(SACConfig):
    bc_every: int = 8  # the imitation term is added on updates whose index is a multiple of this
    bc_weight: float = 1.0  # weight of the imitation term in the actor loss on those updates
    bc_mse_weight: float = 0.0  # inside the imitation term: nll + bc_mse_weight * mode MSE
    expert_action_eps: float = 1e-3  # expert actions clipped to [-1 + eps, 1 - eps] before atanh

    def __post_init__(self):
        super().__post_init__()
        check_positive(self, "bc_every", "expert_action_eps")
        if self.bc_weight < 0 or self.bc_mse_weight < 0:
            raise ValueError("bc_weight and bc_mse_weight must be >= 0")


def _from_sac(config: SACConfig, **changes: Any) -> BCSACConfig:
    return BCSACConfig(**{**dataclasses.asdict(config), **changes})


PAPER = _from_sac(SAC_PRESETS["paper"], buffer_size=500_000)
PRESETS: dict[str, BCSACConfig] = {
    "paper": PAPER,
    "default": dataclasses.replace(PAPER, buffer_size=100_000, learning_starts=10_000),
    "debug": _from_sac(SAC_PRESETS["debug"], bc_every=2),
}


def get_config(name: str = "default", **overrides: Any) -> BCSACConfig:
    return preset(PRESETS, name, **overrides)
