"""Training over several processes (`jax.distributed`): one per host, or one per GPU, joined into one run.

Every process runs the same program on one global "data" mesh over all processes' devices. The helpers here
are the few places where processes differ or must agree: who writes the run directory (process 0), barriers,
decisions every process must take together (stop after this chunk), the exchange of the scenario stream's
shares, and this process's copy of replicated arrays (evaluation runs on local devices). With one process each
is a no-op, so single-process training runs exactly the code it always did.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping

import jax
import numpy as np

from scenariomax.errors import InputError

# the variables `vmax-sim train` reads when its flags are not given (JAX itself reads JAX_COORDINATOR_ADDRESS)
COORDINATOR_VAR, NUM_PROCESSES_VAR, PROCESS_ID_VAR = "JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID"


@dataclasses.dataclass(frozen=True)
class DistributedSettings:
    """How this process joins the run; None fields are detected by JAX from the cluster (SLURM, Open MPI)."""

    coordinator: str | None  # HOST:PORT of process 0's coordination service
    num_processes: int | None
    process_id: int | None


def _int_setting(value, name: str) -> int | None:
    if value is None or value == "":
        return None
    try:
        return int(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an integer, got {value!r}") from None


def distributed_settings(coordinator: str | None = None, num_processes: int | str | None = None,
                         process_id: int | str | None = None, detect: bool = False,
                         environ: Mapping[str, str] | None = None) -> DistributedSettings | None:
    """The settings of a multi-process run from flags, else JAX_COORDINATOR_ADDRESS / JAX_NUM_PROCESSES /
    JAX_PROCESS_ID; `detect` leaves what is unset to JAX's cluster detection. None: a single process (nothing set
    and no detection, or one process)."""
    environ = os.environ if environ is None else environ
    coordinator = coordinator or environ.get(COORDINATOR_VAR) or None
    count = _int_setting(num_processes if num_processes is not None else environ.get(NUM_PROCESSES_VAR),
                         "--num-processes")
    index = _int_setting(process_id if process_id is not None else environ.get(PROCESS_ID_VAR), "--process-id")
    if not detect and coordinator is None and count is None and index is None:
        return None
    if count == 1 and (index or 0) == 0:
        return None
    if count is not None and count < 1:
        raise InputError(f"--num-processes must be at least 1, got {count}")
    if index is not None and (index < 0 or (count is not None and index >= count)):
        raise InputError(f"--process-id must be in [0, {count}), got {index}" if count else
                         f"--process-id must be at least 0, got {index}")
    if coordinator is not None and (":" not in coordinator or not coordinator.rsplit(":", 1)[1].isdigit()):
        raise InputError(f"--coordinator must be HOST:PORT, got {coordinator!r}")
    if not detect and None in (coordinator, count, index):
        missing = [name for name, value in (("--coordinator", coordinator), ("--num-processes", count),
                                            ("--process-id", index)) if value is None]
        raise InputError(f"several processes need {', '.join(missing)} too (or {COORDINATOR_VAR}, "
                         f"{NUM_PROCESSES_VAR}, {PROCESS_ID_VAR}; --distributed detects them under SLURM / Open MPI)")
    return DistributedSettings(coordinator, count, index)


def initialize(settings: DistributedSettings) -> None:
    """Joins the run (blocks until every process has joined). Call before any JAX computation."""
    try:
        jax.distributed.initialize(settings.coordinator, settings.num_processes, settings.process_id)
    except ValueError as error:  # nothing given and no cluster detected, or a bad value
        raise InputError(f"cannot start a multi-process run: {error} (give --coordinator, --num-processes and "
                         f"--process-id where no SLURM or Open MPI environment names them)") from None
    except RuntimeError as error:  # the coordinator cannot be reached, a timeout, ...
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise InputError(f"cannot join the multi-process run at {settings.coordinator or 'the detected coordinator'}:"
                         f" {first}") from None


def num_processes() -> int:
    return jax.process_count()


def process_share() -> tuple[int, int]:
    """(this process's index, the process count)."""
    return jax.process_index(), jax.process_count()


def is_primary() -> bool:
    """Process 0 writes the run directory (config, logs, summary, pictures); every process writes checkpoints."""
    return jax.process_index() == 0


def barrier(name: str) -> None:
    """Waits until every process gets here (no-op with one process)."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)


def primary_first(fn: Callable, name: str):
    """fn() in process 0, then in the others (e.g. generating a cached dataset the others then read); `name`
    names the barrier between, the same in every process."""
    if jax.process_count() == 1:
        return fn()
    if is_primary():
        result = fn()
        barrier(name)
        return result
    barrier(name)
    return fn()


def any_process(flags: list[bool]) -> list[bool]:
    """Element-wise: is each flag set in any process (a stop request or the wall-clock budget seen by one process
    stops every process after the same chunk)."""
    if jax.process_count() == 1:
        return [bool(flag) for flag in flags]
    from jax.experimental import multihost_utils

    gathered = multihost_utils.process_allgather(np.asarray(flags, np.int32))  # (processes, flags)
    return [bool(value) for value in np.asarray(gathered).reshape(jax.process_count(), -1).any(axis=0)]


def exchange(tree):
    """Every process's tree (numpy leaves (k, ...)) stacked in process order: leaves (processes, k, ...)."""
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=False)


def local_copy(tree):
    """This process's copy of replicated arrays that span several processes (evaluation and the policy run on
    local devices); other leaves as they are."""
    def local(leaf):
        if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable:
            return leaf.addressable_data(0)
        return leaf

    return jax.tree.map(local, tree)
