"""SAC settings (frozen) and named presets.

"paper" holds the V-Max paper's SAC settings (lr 1e-4, gamma 0.99, tau 0.005, alpha 0.2, batch 64, 16 envs,
4 gradient updates per env step, 1M buffer, 50k learning starts; MLPs 256-64-32 as in the released
configs). The paper gives alpha = 0.2; we read it as the initial value of a learned temperature with
target entropy -A (set `learn_alpha=False` to keep it fixed). "default" sizes the buffer / warm-up for one
machine and discounts by 0.96 per transition: the training loop holds each action for 4 simulator steps with
these settings (`vmax_sim.training.config.ACTION_REPEAT`), and 0.96 per 0.4 s is the paper's 0.99 per 0.1 s.
"debug" is tiny and fast, for smoke tests.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vmax_sim.agents.common import check_positive, check_unit_interval, preset


@dataclasses.dataclass(frozen=True)
class SACConfig:
    # learning
    learning_rate: float = 1e-4  # actor, critic and temperature (Adam)
    critic_learning_rate: float | None = None  # None: same as learning_rate
    alpha_learning_rate: float | None = None  # None: same as learning_rate
    gamma: float = 0.99
    tau: float = 0.005  # Polyak coefficient of the target critic
    init_alpha: float = 0.2  # initial (or fixed) temperature
    learn_alpha: bool = True  # tune the temperature towards target_entropy
    target_entropy: float | None = None  # None: -action_dim
    reward_scale: float = 1.0
    max_grad_norm: float | None = None  # global-norm clipping of each gradient; None: off
    num_critics: int = 2  # Q heads on the shared critic encoder; targets take their min
    shared_encoder: bool = False  # the actor reads the critic encoder's features (detached): ~2x cheaper updates
    # networks
    policy_hidden_sizes: tuple[int, ...] = (256, 64, 32)
    value_hidden_sizes: tuple[int, ...] = (256, 64, 32)
    activation: str = "relu"
    log_std_min: float = -5.0
    log_std_max: float = 2.0
    # training loop (read by vmax_sim.training, not by the learner)
    num_envs: int = 16
    batch_size: int = 64  # transitions per update
    updates_per_step: int = 4  # gradient updates per (batched) env step
    buffer_size: int = 1_000_000  # transitions
    learning_starts: int = 50_000  # transitions in the buffer before the first update

    def __post_init__(self):
        check_positive(self, "learning_rate", "num_critics", "num_envs", "batch_size", "updates_per_step",
                       "buffer_size", "init_alpha", "reward_scale")
        check_unit_interval(self, "gamma", "tau")
        if self.log_std_min >= self.log_std_max:
            raise ValueError("log_std_min must be below log_std_max")

    def target_entropy_for(self, action_dim: int) -> float:
        return -float(action_dim) if self.target_entropy is None else float(self.target_entropy)


PAPER = SACConfig()
PRESETS: dict[str, SACConfig] = {
    "paper": PAPER,
    "default": dataclasses.replace(PAPER, buffer_size=100_000, learning_starts=10_000, gamma=0.96),
    "debug": dataclasses.replace(PAPER, learning_rate=1e-3, policy_hidden_sizes=(64, 64),
                                 value_hidden_sizes=(64, 64), num_envs=4, batch_size=32, updates_per_step=1,
                                 buffer_size=10_000, learning_starts=256),
}


def get_config(name: str = "default", **overrides: Any) -> SACConfig:
    return preset(PRESETS, name, **overrides)
