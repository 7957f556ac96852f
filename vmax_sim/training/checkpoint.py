"""Orbax checkpoints of a training run: the device carry (learner, environments, optional replay
buffer, PRNG key, step) and a small JSON of the host's state (position in the scenario stream, wall time).

Orbax writes each step to a temporary folder and renames it when complete, so a `kill -9` at any
moment leaves the previous checkpoints intact; `latest_step` only sees finished ones.
"""

from __future__ import annotations

from pathlib import Path

import jax
import orbax.checkpoint as ocp

from vmax_sim.training.loop import TrainCarry


def _tree(carry: TrainCarry, with_buffer: bool) -> dict:
    """Everything but the learner (saved as its own item so evaluation restores it alone)."""
    tree = {"env": carry.env, "key": carry.key, "env_steps": carry.env_steps}
    if with_buffer and carry.buffer is not None:
        tree["buffer"] = carry.buffer
    return tree


class CheckpointStore:
    def __init__(self, directory: Path, keep: int = 2):
        self.directory = Path(directory).absolute()
        options = ocp.CheckpointManagerOptions(max_to_keep=keep, enable_async_checkpointing=False, create=True)
        self.manager = ocp.CheckpointManager(self.directory, options=options)

    def latest_step(self) -> int | None:
        return self.manager.latest_step()

    def save(self, step: int, carry: TrainCarry, host: dict, with_buffer: bool) -> None:
        args = ocp.args.Composite(learner=ocp.args.StandardSave(carry.learner),
                                  state=ocp.args.StandardSave(_tree(carry, with_buffer)),
                                  host=ocp.args.JsonSave(host))
        self.manager.save(step, args=args, force=True)
        self.manager.wait_until_finished()

    def host_state(self, step: int) -> dict:
        return dict(self.manager.restore(step, args=ocp.args.Composite(host=ocp.args.JsonRestore())).host)

    def restore(self, step: int, like: TrainCarry, with_buffer: bool) -> TrainCarry:
        """The carry saved at `step`, shaped like `like` (a fresh buffer when none was saved)."""
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, _tree(like, with_buffer))
        learner = jax.tree.map(ocp.utils.to_shape_dtype_struct, like.learner)
        both = self.manager.restore(step, args=ocp.args.Composite(
            learner=ocp.args.StandardRestore(learner), state=ocp.args.StandardRestore(abstract)))
        restored = both.state
        return TrainCarry(learner=both.learner, env=restored["env"],
                          buffer=restored.get("buffer", like.buffer), key=restored["key"],
                          env_steps=restored["env_steps"])

    def restore_learner(self, step: int, like) -> object:
        """Only the learner state (evaluation of a trained run)."""
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, like)
        return self.manager.restore(step, args=ocp.args.Composite(learner=ocp.args.StandardRestore(abstract))).learner
