"""The policies of a run's last checkpoints driving as one (`train.ensemble`): the mean of their actions.

A student's score swings from one checkpoint to the next on scenes unlike its training scenes (docs/learning.md:
real-scene accuracy 82.8-96.6% 100k env steps apart), and averaging the checkpoints' *weights* did not steady it.
Averaging their *actions* steadies it: on the real scenes the mean action of a run's last four checkpoints scored
above its members' mean in each of four hours (accuracy 86.2-96.6%, mean 92.2; single checkpoints: mean 86.8).
RUN/ensemble/ is a run directory of its own (config.json, checkpoints/<env steps>/ of the last N checkpoints without
the replay buffer, ensemble.json naming them): `vmax-sim evaluate --policy RUN/ensemble` evaluates the ensemble like
any run.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import jax
import jax.numpy as jnp

from vmax_sim.agents.types import Learner
from vmax_sim.training import distributed
from vmax_sim.training.checkpoint import CheckpointStore

ENSEMBLE_DIR = "ensemble"
RECORD_FILE = "ensemble.json"


def is_ensemble(run_dir: Path) -> bool:
    """True for a directory written by `EnsembleCheckpoints` (RUN/ensemble)."""
    return (Path(run_dir) / RECORD_FILE).is_file()


def stack_params(members: list) -> object:
    """The members' parameter pytrees stacked on a new leading axis (M, ...): what `ensemble_learner` acts with."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *members)


def ensemble_learner(learner: Learner) -> Learner:
    """`learner` whose act takes stacked parameters (M, ...) and returns the mean of the M members' actions (B, A).
    Only acting changes: the ensemble is a driver, not something to train."""
    def act(params, observation, key, deterministic):
        actions = jax.vmap(lambda member: learner.act(member, observation, key, deterministic))(params)
        return jnp.mean(actions, axis=0)

    def act_with_info(params, observation, key, deterministic=False):
        action = act(params, observation, key, deterministic)
        return action, {"log_prob": jnp.zeros(action.shape[:1], action.dtype)}  # no density for a mean of members

    return learner._replace(act=act, act_with_info=act_with_info, value=None)


class EnsembleCheckpoints:
    """Keeps RUN/ensemble/ holding the learner state of the run's last `size` checkpoints."""

    def __init__(self, run_dir: Path, size: int):
        self.run_dir = Path(run_dir)
        self.directory = self.run_dir / ENSEMBLE_DIR
        self.size = size
        self._store: CheckpointStore | None = None  # opened at the first member

    def add(self, env_steps: int, carry, host: dict) -> list[int]:
        """Writes `carry`'s learner (its replay buffer left out) as the newest member. -> the members' env steps"""
        if self._store is None:
            self._store = CheckpointStore(self.directory / "checkpoints", keep=self.size)
        self._store.save(env_steps, carry.replace(buffer=None), host, with_buffer=False)
        members = sorted(int(step) for step in self._store.manager.all_steps())
        if distributed.is_primary():
            shutil.copyfile(self.run_dir / "config.json", self.directory / "config.json")
            record = {"size": self.size, "members": members}
            (self.directory / RECORD_FILE).write_text(json.dumps(record, indent=2) + "\n")
        return members


def member_params(directory: Path, like, policy_params) -> tuple[object, list[int]]:
    """The policy parameters of every member of the ensemble in `directory`, stacked (M, ...), and their env steps.
    `like`: a learner state of the run's shapes; `policy_params`: the learner's state -> parameters."""
    store = CheckpointStore(Path(directory) / "checkpoints")
    steps = sorted(int(step) for step in store.manager.all_steps())
    return stack_params([policy_params(store.restore_learner(step, like)) for step in steps]), steps


__all__ = ["ENSEMBLE_DIR", "EnsembleCheckpoints", "ensemble_learner", "is_ensemble", "member_params", "stack_params"]
