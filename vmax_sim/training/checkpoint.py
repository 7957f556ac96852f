"""Orbax checkpoints of a training run: the device carry (learner, environments, optional replay
buffer, PRNG key, step) and a small JSON of the host's state (position in the scenario stream, wall time).

Orbax writes each step to a temporary folder and renames it when complete, so a `kill -9` at any
moment leaves the previous checkpoints intact; `latest_step` only sees finished ones.

The replay buffer (hundreds of MB) is its own item, written by `ReplayHandler` as one `.npy` file per
leaf, a few MB at a time: Orbax's array writer copies each whole array to the host and TensorStore encodes
it again before writing (up to two buffers' worth of extra memory while saving, on the CPU too).
"""

from __future__ import annotations

import dataclasses
import errno
import functools
import logging
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp

from scenariomax.errors import InputError
from vmax_sim.training.loop import TrainCarry

SLICE_BYTES = 4 * 2**20  # bytes moved between the device and a file at a time (larger: more memory, no faster)


class _DropRaisedInThread(logging.Filter):
    """Orbax saves in a helper thread, logs its exception with a traceback, then raises it again in the caller:
    an OS error (a full disk) would reach the screen twice, once as a traceback. The caller reports it."""

    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        return not (isinstance(error, OSError) and "raised an exception" in str(record.msg))


logging.getLogger("absl").addFilter(_DropRaisedInThread())


def quiet_abandoned_saves() -> None:
    """Orbax sorts a checkpoint's items by name and writes the blocking replay after creating the coroutines of
    the items before it ("host", "learner"): when the replay fails (a full disk), those are never awaited and
    Python warns at exit, under the one-line error that already says the checkpoint was not written."""
    warnings.filterwarnings("ignore", message=r"coroutine '\w+CheckpointHandler\.async_save' was never awaited",
                            category=RuntimeWarning)


def _disk_error(error: Exception, folder: Path) -> OSError | None:
    """An OSError naming `folder` for a write error that names no file: ours (a file handle's write) carries
    no name, TensorStore's (Orbax's array writer) is a ValueError whose text says ENOSPC. None otherwise."""
    if isinstance(error, OSError) and error.errno is not None:
        return error if error.filename else OSError(error.errno, error.strerror, str(folder))
    if isinstance(error, ValueError) and "No space left on device" in str(error):
        return OSError(errno.ENOSPC, "No space left on device", str(folder))
    return None


def _tree(carry: TrainCarry) -> dict:
    """Everything but the learner and the replay (saved as their own items: evaluation restores the
    learner alone)."""
    return {"env": carry.env, "key": carry.key, "env_steps": carry.env_steps}


def _slices(shape: tuple[int, ...], itemsize: int) -> list[tuple[int, int, int]]:
    """(block, start, stop) row ranges of a (blocks, rows, ...) leaf, in its row-major order, each of about
    SLICE_BYTES or less; one range (0, 0, 0) standing for the whole leaf when it has no row axis."""
    if len(shape) < 2:
        return [(0, 0, 0)]
    row_bytes = itemsize * int(np.prod(shape[2:], dtype=np.int64))
    step = max(1, SLICE_BYTES // max(row_bytes, 1))
    return [(block, start, min(start + step, shape[1])) for block in range(shape[0])
            for start in range(0, shape[1], step)]


@functools.partial(jax.jit, static_argnums=3)
def _take(leaf: jax.Array, block: jax.Array, start: jax.Array, size: int) -> jax.Array:
    starts = (block, start) + (0,) * (leaf.ndim - 2)
    return jax.lax.dynamic_slice(leaf, starts, (1, size) + leaf.shape[2:])  # one compilation per slice size


@functools.partial(jax.jit, donate_argnums=0)
def _fill(store: jax.Array, part: jax.Array, block: jax.Array, start: jax.Array) -> jax.Array:
    starts = (block, start) + (0,) * (store.ndim - 2)
    return jax.lax.dynamic_update_slice(store, part.astype(store.dtype), starts)


def _write_leaf(path: Path, leaf: jax.Array) -> None:
    """An .npy file of `leaf`, copied from the device one slice at a time."""
    with path.open("wb") as handle:
        header = {"descr": np.lib.format.dtype_to_descr(np.dtype(leaf.dtype)), "fortran_order": False,
                  "shape": tuple(leaf.shape)}
        np.lib.format.write_array_header_2_0(handle, header)
        for block, start, stop in _slices(tuple(leaf.shape), np.dtype(leaf.dtype).itemsize):
            part = leaf if leaf.ndim < 2 else _take(leaf, block, start, stop - start)
            handle.write(np.ascontiguousarray(jax.device_get(part)).data)


def _read_leaf(path: Path, like: jax.Array) -> jax.Array:
    """`like` (a fresh array, donated) filled from the .npy file at `path`, one slice at a time."""
    saved = np.load(path, mmap_mode="r")
    if saved.shape != tuple(like.shape) or saved.dtype != like.dtype:
        raise InputError(f"{path}: replay buffer of shape {saved.shape} {saved.dtype}, this configuration's is "
                         f"{tuple(like.shape)} {like.dtype}; resume with the run's own configuration")
    if like.ndim < 2:
        return jax.device_put(np.array(saved), like.sharding)
    for block, start, stop in _slices(tuple(like.shape), like.dtype.itemsize):
        part = np.ascontiguousarray(saved[block:block + 1, start:stop])
        like = _fill(like, jnp.asarray(part), block, start)  # uncommitted: placed like `like`
    return like


class ReplayHandler(ocp.CheckpointHandler):
    """Saves a pytree of device arrays as numbered .npy files; restores into a like-shaped fresh pytree."""

    def save(self, directory, args: ReplaySave) -> None:
        folder = Path(str(directory))
        folder.mkdir(parents=True, exist_ok=True)
        for index, leaf in enumerate(jax.tree.leaves(args.item)):
            _write_leaf(folder / f"{index}.npy", leaf)

    def restore(self, directory, args: ReplayRestore):
        folder = Path(str(directory))
        leaves, treedef = jax.tree.flatten(args.item)
        return jax.tree.unflatten(treedef, [_read_leaf(folder / f"{index}.npy", leaf)
                                            for index, leaf in enumerate(leaves)])

    def metadata(self, directory) -> None:
        return None


@ocp.args.register_with_handler(ReplayHandler, for_save=True)
@dataclasses.dataclass
class ReplaySave(ocp.args.CheckpointArgs):
    item: object  # the replay pytree


@ocp.args.register_with_handler(ReplayHandler, for_restore=True)
@dataclasses.dataclass
class ReplayRestore(ocp.args.CheckpointArgs):
    item: object  # a fresh replay of the same structure: its arrays are donated and filled


class CheckpointStore:
    def __init__(self, directory: Path, keep: int = 2):
        self.directory = Path(directory).absolute()
        quiet_abandoned_saves()
        options = ocp.CheckpointManagerOptions(max_to_keep=keep, enable_async_checkpointing=False, create=True)
        self.manager = ocp.CheckpointManager(self.directory, options=options)

    def latest_step(self) -> int | None:
        return self.manager.latest_step()

    def save(self, step: int, carry: TrainCarry, host: dict, with_buffer: bool) -> None:
        items = {"learner": ocp.args.StandardSave(carry.learner), "state": ocp.args.StandardSave(_tree(carry)),
                 "host": ocp.args.JsonSave(host)}
        if with_buffer and carry.buffer is not None:
            items["replay"] = ReplaySave(carry.buffer)
        try:
            self.manager.save(step, args=ocp.args.Composite(**items), force=True)
            self.manager.wait_until_finished()
        except (OSError, ValueError) as error:
            named = _disk_error(error, self.directory)
            if named is None:
                raise
            raise named from None

    def host_state(self, step: int) -> dict:
        return dict(self.manager.restore(step, args=ocp.args.Composite(host=ocp.args.JsonRestore())).host)

    def restore(self, step: int, like: TrainCarry, with_buffer: bool) -> TrainCarry:
        """The carry saved at `step`, shaped like `like`; the replay is read into like.buffer (donated), or
        like.buffer itself when none was saved."""
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, _tree(like))
        learner = jax.tree.map(ocp.utils.to_shape_dtype_struct, like.learner)
        items = {"learner": ocp.args.StandardRestore(learner), "state": ocp.args.StandardRestore(abstract)}
        if with_buffer and like.buffer is not None:
            items["replay"] = ReplayRestore(like.buffer)
        try:
            both = self.manager.restore(step, args=ocp.args.Composite(**items))
        except KeyError:  # no "replay" item: written before the replay stored each observation once
            raise InputError(f"{self.directory / str(step)}: checkpoint from an older V-Max (replay buffer in "
                             f"the old layout); start a new run with another --out") from None
        restored = both.state
        return TrainCarry(learner=both.learner, env=restored["env"],
                          buffer=both.replay if "replay" in items else like.buffer, key=restored["key"],
                          env_steps=restored["env_steps"])

    def restore_learner(self, step: int, like) -> object:
        """Only the learner state (evaluation of a trained run)."""
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, like)
        return self.manager.restore(step, args=ocp.args.Composite(learner=ocp.args.StandardRestore(abstract))).learner
