"""PPO settings (frozen) and named presets.

Batch vocabulary (Brax's, which V-Max's trainers follow): one update consumes
`batch_size * num_minibatches` sequences of `unroll_length` steps; the loop collects them with `num_envs`
environments in `(batch_size * num_minibatches) // num_envs` unrolls and passes them to `update` as one
rollout with T = unroll_length and B = batch_size * num_minibatches. `update` only needs T * B divisible by
`num_minibatches`: it flattens the rollout and shuffles *transitions* into `num_minibatches` minibatches
(of batch_size * unroll_length transitions with the preset numbers) for each of `num_epochs` epochs.

"paper": batch 512, 16 minibatches, unroll 40, GAE lambda 0.95, clip 0.2, gamma 0.99 (the V-Max paper);
lr 3e-4, value coef 0.5, entropy coef 0.01, 4 epochs, tanh MLPs 256-64-32 (the released configuration).
"default" keeps the learning settings with a batch a single machine collects quickly (16 sequences per
minibatch, 4 minibatches: one update per 2,560 transitions, four times as many updates per env step as with 64
sequences, which took held-out accuracy from <= 58% to 80% at 0.5M env steps; docs/learning.md), discounting by
0.96 per transition: the training loop holds each action for 4 simulator steps with these settings
(`vmax_sim.training.config.ACTION_REPEAT`; 0.96 per 0.4 s is 0.99 per 0.1 s). "debug" is tiny and fast.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vmax_sim.agents.common import check_positive, check_unit_interval, preset

ENTROPY_ESTIMATES = ("gaussian", "sample")
IMITATION_LOSSES = ("mse", "nll")


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    # learning
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_eps: float = 0.2  # ratio clip of the surrogate objective
    value_clip_eps: float | None = None  # clip V around the behaviour value; None: plain squared error
    value_coef: float = 0.5
    entropy_coef: float = 0.01
    # "sample": -log pi(a~), a~ ~ pi (the squashed policy's entropy); "gaussian": closed form before tanh, which
    # keeps rewarding a wider Gaussian once tanh saturates (std 0.9 -> 4.8 on the driving task, docs/agents.md)
    entropy_estimate: str = "sample"
    normalize_advantages: bool = True  # per minibatch, to zero mean and unit std
    num_epochs: int = 4  # passes over the rollout per update
    num_minibatches: int = 16
    max_grad_norm: float | None = 0.5
    reward_scale: float = 1.0
    # weight of |mode(pi(s)) - teacher label|^2 added to the loss (rows the env labels, `Transition.expert_action`:
    # self-play's rule teacher on each agent's own view). The agents drive themselves and the teacher labels the
    # states they reach (DAgger); the PPO terms then work from a driver that already follows its path
    imitation_coef: float = 0.0
    # "mse": |mode - label|^2 (pulls the mode only: the spread is left to the PPO terms, and grew from 0.5 to 0.8-1.3
    # over self-play's 30 minutes); "nll": -log pi(label | s), which also narrows the spread round the label
    imitation_loss: str = "mse"
    # decay of an exponential moving average of the parameters, updated after every update (rollout); when > 0 the
    # average is the policy that is evaluated and saved, while the raw parameters still collect the rollouts (the
    # PPO ratio needs the behaviour policy). Self-play's goal-reaching swung by 15-30 points between checkpoints
    # 20k env steps apart (docs/selfplay.md)
    ema_decay: float = 0.0
    # 0: each epoch splits every rollout row into `num_minibatches` minibatches, rows with mask 0 (self-play's empty
    # or finished agent slots) weighed out of the losses; N > 0: each epoch steps through the mask-1 rows only, N at
    # a time (ceil(active / N) steps), so the gradient work follows the agents that acted, not the slots
    active_minibatch_size: int = 0
    # networks (separate policy and value networks, each with its own encoder)
    policy_hidden_sizes: tuple[int, ...] = (256, 64, 32)
    value_hidden_sizes: tuple[int, ...] = (256, 64, 32)
    activation: str = "tanh"
    log_std_min: float = -5.0
    log_std_max: float = 2.0
    # training loop (read by vmax_sim.training, not by the learner)
    num_envs: int = 16
    unroll_length: int = 40  # T of a rollout
    batch_size: int = 512  # sequences of unroll_length steps per minibatch

    def __post_init__(self):
        check_positive(self, "learning_rate", "num_epochs", "num_minibatches", "num_envs", "unroll_length",
                       "batch_size", "clip_eps", "reward_scale")
        check_unit_interval(self, "gamma", "gae_lambda")
        if self.imitation_coef < 0:
            raise ValueError(f"imitation_coef must be >= 0, got {self.imitation_coef}")
        if self.active_minibatch_size < 0:
            raise ValueError(f"active_minibatch_size must be >= 0, got {self.active_minibatch_size}")
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"ema_decay must be in [0, 1), got {self.ema_decay}")
        if self.imitation_loss not in IMITATION_LOSSES:
            raise ValueError(f"imitation_loss must be one of {IMITATION_LOSSES}, got {self.imitation_loss!r}")
        if self.entropy_estimate not in ENTROPY_ESTIMATES:
            raise ValueError(f"entropy_estimate must be one of {ENTROPY_ESTIMATES}, got {self.entropy_estimate!r}")
        if self.log_std_min >= self.log_std_max:
            raise ValueError("log_std_min must be below log_std_max")

    @property
    def sequences_per_update(self) -> int:
        """B of the rollout given to `update`."""
        return self.batch_size * self.num_minibatches

    @property
    def transitions_per_update(self) -> int:
        return self.sequences_per_update * self.unroll_length

    @property
    def unrolls_per_update(self) -> int:
        """Unrolls of `num_envs` environments the loop runs to fill one rollout (rounded up)."""
        return -(-self.sequences_per_update // self.num_envs)


PAPER = PPOConfig()
PRESETS: dict[str, PPOConfig] = {
    "paper": PAPER,
    "default": dataclasses.replace(PAPER, batch_size=16, num_minibatches=4, gamma=0.96),
    "debug": dataclasses.replace(PAPER, policy_hidden_sizes=(64, 64), value_hidden_sizes=(64, 64), num_envs=8,
                                 unroll_length=16, batch_size=4, num_minibatches=2, num_epochs=2),
}


def get_config(name: str = "default", **overrides: Any) -> PPOConfig:
    return preset(PRESETS, name, **overrides)
