"""The policies of a run's last checkpoints (or of its last `train.ensemble_every` stretches) driving as one
(`train.ensemble`): the mean of their actions, or by `train.ensemble_rule` their median or their mean steering with
the smallest acceleration.

A student's score swings from one checkpoint to the next on scenes unlike its training scenes (docs/learning.md:
real-scene accuracy 82.8-96.6% 100k env steps apart), and averaging the checkpoints' *weights* did not steady it.
Averaging their *actions* steadies it: on the real scenes the mean action of a run's last four checkpoints scored
above its members' mean in each of four hours (accuracy 86.2-96.6%, mean 92.2; single checkpoints: mean 86.8).
RUN/ensemble/ is a run directory of its own (config.json, checkpoints/<env steps>/ of the last N checkpoints without
the replay buffer, ensemble.json naming them): `vmax-sim evaluate --policy RUN/ensemble` evaluates the ensemble like
any run.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp

from vmax_sim.agents.policy import combine_members
from vmax_sim.agents.types import Learner
from vmax_sim.training.checkpoint import CheckpointStore, write_policy_directory

ENSEMBLE_DIR = "ensemble"
RECORD_FILE = "ensemble.json"


def is_ensemble(run_dir: Path) -> bool:
    """True for a directory written by `EnsembleCheckpoints` (RUN/ensemble)."""
    return (Path(run_dir) / RECORD_FILE).is_file()


def stack_params(members: list) -> object:
    """The members' parameter pytrees stacked on a new leading axis (M, ...): what `ensemble_learner` acts with."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *members)


def ensemble_learner(learner: Learner, rule: str = "mean") -> Learner:
    """`learner` whose act takes stacked parameters (M, ...) and returns the M members' actions combined by `rule`
    (B, A; `train.ensemble_rule`). Only acting changes: the ensemble is a driver, not something to train."""
    act, act_with_info = combine_members(learner.act, rule)
    return learner._replace(act=act, act_with_info=act_with_info, value=None)


class EnsembleCheckpoints:
    """Keeps RUN/ensemble/ holding the learner state of the run's last `size` members (checkpoints, or every
    `train.ensemble_every` env steps)."""

    def __init__(self, run_dir: Path, size: int, every: int | None = None, start: int = 0):
        self.run_dir = Path(run_dir)
        self.directory = self.run_dir / ENSEMBLE_DIR
        self.store = CheckpointStore(self.directory / "checkpoints", keep=size)
        self.size = size
        self.every = every  # None: the run adds a member with each checkpoint
        self.last = start  # env steps of the newest member on the own schedule (the run's start step at first)

    def offer(self, env_steps: int, carry, host: dict, final: bool = False) -> None:
        """On the own schedule (`every`), adds `carry` as a member when `every` env steps have passed since the
        last one, or at the run's `final` step; with checkpoints (`every` None) the run calls `add` itself."""
        if self.every and env_steps != self.last and (final or env_steps - self.last >= self.every):
            self.add(env_steps, carry, host)
            self.last = env_steps

    def add(self, env_steps: int, carry, host: dict) -> None:
        """Writes `carry`'s learner (its replay buffer left out) as the newest member."""
        self.store.save(env_steps, carry.replace(buffer=None), host, with_buffer=False)
        members = sorted(int(step) for step in self.store.manager.all_steps())
        write_policy_directory(self.run_dir, self.directory, RECORD_FILE, {"size": self.size, "members": members})


def member_params(store: CheckpointStore, like, policy_params) -> tuple[object, list[int]]:
    """The policy parameters of every member in an ensemble's `store`, stacked (M, ...), and their env steps.
    `like`: a learner state of the run's shapes; `policy_params`: the learner's state -> parameters."""
    steps = sorted(int(step) for step in store.manager.all_steps())
    return stack_params([policy_params(store.restore_learner(step, like)) for step in steps]), steps


__all__ = ["ENSEMBLE_DIR", "EnsembleCheckpoints", "ensemble_learner", "is_ensemble", "member_params", "stack_params"]
