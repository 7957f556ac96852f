"""Orbax checkpoints of a training run: the device carry (learner, environments, optional replay
buffer, PRNG key, step) and a small JSON of the host's state (position in the scenario stream, wall time).

Orbax writes each step to a temporary folder and renames it when complete, so a `kill -9` at any
moment leaves the previous checkpoints intact; `latest_step` only sees finished ones.

The replay buffer (hundreds of MB) is its own item, written by `ReplayHandler` as one `.npy` file per
leaf, a few MB at a time: Orbax's array writer copies each whole array to the host and TensorStore encodes
it again before writing (up to two buffers' worth of extra memory while saving, on the CPU too).
With several processes (`jax.distributed`) each writes the blocks its devices hold, one file per block
(`<leaf>.b<block>.npy`; one process writes the replicated scalars): no two hosts write into one file, which
shared file systems do not all allow. Either layout restores under one process or several.
"""

from __future__ import annotations

import dataclasses
import errno
import functools
import json
import logging
import shutil
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp

from scenariomax.errors import InputError
from vmax_sim.training import distributed
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


def _write_leaf(path: Path, leaf: jax.Array, block: int | None = None) -> None:
    """An .npy file of `leaf` (or of its block `block` only, leading axis 1), copied from the device one slice at a
    time."""
    shape = tuple(leaf.shape) if block is None else (1,) + tuple(leaf.shape[1:])
    with path.open("wb") as handle:
        header = {"descr": np.lib.format.dtype_to_descr(np.dtype(leaf.dtype)), "fortran_order": False,
                  "shape": shape}
        np.lib.format.write_array_header_2_0(handle, header)
        for index, start, stop in _slices(shape, np.dtype(leaf.dtype).itemsize):
            if leaf.ndim < 2:
                part = leaf if block is None else leaf[block:block + 1]
            else:
                part = _take(leaf, index + (block or 0), start, stop - start)
            handle.write(np.ascontiguousarray(jax.device_get(part)).data)


def _block_file(folder: Path, index: int, block: int) -> Path:
    return folder / f"{index}.b{block}.npy"


def _write_own_blocks(folder: Path, index: int, leaf: jax.Array) -> None:
    """The blocks of a leaf split over several processes' devices that this process holds, one file each
    (every block is written once: by the process holding its first replica)."""
    if leaf.ndim == 0:  # replicated: process 0 writes it
        if jax.process_index() == 0:
            _write_leaf(folder / f"{index}.npy", leaf.addressable_data(0))
        return
    for shard in leaf.addressable_shards:
        if shard.replica_id != 0:
            continue
        first = shard.index[0].start or 0
        for offset in range(shard.data.shape[0]):
            _write_leaf(_block_file(folder, index, first + offset), shard.data, block=offset)


def _saved_blocks(folder: Path, index: int, like: jax.Array):
    """block -> the saved rows of that block (memory-mapped, leading axis 1), from the leaf's one file or its
    per-block files; InputError when the shapes differ from `like`'s."""
    whole = folder / f"{index}.npy"
    if whole.exists() or like.ndim == 0:
        saved = np.load(whole, mmap_mode="r")
        shape, dtype, where = saved.shape, saved.dtype, whole
        block_of = lambda block: saved[block:block + 1]  # noqa: E731
    else:
        first = np.load(_block_file(folder, index, 0), mmap_mode="r")
        count = len(list(folder.glob(f"{index}.b*.npy")))
        shape, dtype, where = (count,) + first.shape[1:], first.dtype, _block_file(folder, index, 0)
        block_of = lambda block: np.load(_block_file(folder, index, block), mmap_mode="r")  # noqa: E731
    if shape != tuple(like.shape) or dtype != like.dtype:
        raise InputError(f"{where}: replay buffer of shape {shape} {dtype}, this configuration's is "
                         f"{tuple(like.shape)} {like.dtype}; resume with the run's own configuration")
    if like.ndim == 0:
        return lambda block: saved
    return block_of


def _read_leaf(folder: Path, index: int, like: jax.Array) -> jax.Array:
    """`like` (a fresh array, donated) filled from the saved leaf, one slice at a time."""
    block_of = _saved_blocks(folder, index, like)
    if like.ndim < 2:
        saved = block_of(0) if like.ndim == 0 else np.concatenate([block_of(b) for b in range(like.shape[0])])
        return jax.device_put(np.array(saved), like.sharding)
    for block, start, stop in _slices(tuple(like.shape), like.dtype.itemsize):
        part = np.ascontiguousarray(block_of(block)[:, start:stop])
        like = _fill(like, jnp.asarray(part), block, start)  # uncommitted: placed like `like`
    return like


def _read_own_blocks(folder: Path, index: int, like: jax.Array) -> jax.Array:
    """The saved leaf as a global array sharded like `like` (several processes): each process reads only the
    blocks its devices hold, one device's share in host memory at a time. `like` is deleted first."""
    block_of = _saved_blocks(folder, index, like)
    shape, sharding = tuple(like.shape), like.sharding
    like.delete()  # a fresh buffer: its memory goes to the restored one

    def read(where) -> np.ndarray:
        if not shape:
            return np.array(block_of(0))
        blocks = range(*where[0].indices(shape[0]))
        return np.concatenate([np.asarray(block_of(block)) for block in blocks])[(slice(None),) + where[1:]]

    return jax.make_array_from_callback(shape, sharding, read)


class ReplayHandler(ocp.CheckpointHandler):
    """Saves a pytree of device arrays as numbered .npy files; restores into a like-shaped fresh pytree."""

    def save(self, directory, args: ReplaySave) -> None:
        folder = Path(str(directory))
        folder.mkdir(parents=True, exist_ok=True)
        for index, leaf in enumerate(jax.tree.leaves(args.item)):
            if jax.process_count() > 1:
                _write_own_blocks(folder, index, leaf)
            else:
                _write_leaf(folder / f"{index}.npy", leaf)

    def restore(self, directory, args: ReplayRestore):
        folder = Path(str(directory))
        leaves, treedef = jax.tree.flatten(args.item)
        read = _read_own_blocks if jax.process_count() > 1 else _read_leaf
        return jax.tree.unflatten(treedef, [read(folder, index, leaf) for index, leaf in enumerate(leaves)])

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
        abstract, learner = _abstract(_tree(like)), _abstract(like.learner)
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
        abstract = _abstract(like)
        return self.manager.restore(step, args=ocp.args.Composite(learner=ocp.args.StandardRestore(abstract))).learner


def _abstract(tree):
    """Shape, dtype and sharding of every leaf, for a restore onto this machine's devices. A leaf without a
    sharding (a shape from `jax.eval_shape`) gets the default device's: left out, orbax would use the sharding
    saved in the checkpoint, and a run saved on a GPU would not restore on a CPU ("Topology mismatch")."""
    default = jax.sharding.SingleDeviceSharding(jax.devices()[0])

    def leaf(x):
        struct = ocp.utils.to_shape_dtype_struct(x)
        if getattr(struct, "sharding", None) is None and hasattr(struct, "shape"):
            return jax.ShapeDtypeStruct(struct.shape, struct.dtype, sharding=default)
        return struct

    return jax.tree.map(leaf, tree)


def write_policy_directory(run_dir: Path, directory: Path, record_file: str, record: dict) -> None:
    """Makes `directory` (a run's RUN/best or RUN/ensemble, its checkpoints already saved) a run directory of its own:
    the run's config.json beside them and `record` as JSON in `record_file`. The primary process writes."""
    if distributed.is_primary():
        shutil.copyfile(Path(run_dir) / "config.json", Path(directory) / "config.json")
        (Path(directory) / record_file).write_text(json.dumps(record, indent=2) + "\n")

