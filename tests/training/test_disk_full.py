"""A full disk during training ends in one line naming the folder: no Orbax or tensorboardX traceback, no
"coroutine was never awaited" warning, nothing else on stderr."""

from __future__ import annotations

import errno
import logging
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from tests.training.conftest import NUM_OBJECTS
from vmax_sim.training.checkpoint import _disk_error, _DropRaisedInThread, quiet_abandoned_saves
from vmax_sim.training.logger import RunLogger

ENOSPC = OSError(errno.ENOSPC, "No space left on device")


def test_a_write_error_without_a_file_name_names_the_folder(tmp_path):
    named = _disk_error(ENOSPC, tmp_path)
    assert (named.errno, named.filename) == (errno.ENOSPC, str(tmp_path))
    tensorstore = ValueError("Error writing local file \"/x/d/1\": [OSError 28] No space left on device")
    assert _disk_error(tensorstore, tmp_path).filename == str(tmp_path)
    assert _disk_error(ValueError("shape mismatch"), tmp_path) is None  # not a disk error: raised as it was


def test_orbax_thread_logs_of_os_errors_are_dropped_and_other_logs_kept():
    def record(error, msg="_SignalingThread.run() raised an exception: %s"):
        return logging.LogRecord("absl", logging.ERROR, __file__, 1, msg, (error,), (type(error), error, None))

    assert not _DropRaisedInThread().filter(record(ENOSPC))  # raised again in the caller, which reports it
    assert _DropRaisedInThread().filter(record(RuntimeError("bug")))
    assert _DropRaisedInThread().filter(record(ENOSPC, "something else failed"))


def test_a_tensorboard_write_on_a_full_disk_is_raised_once_by_flush_naming_the_folder(tmp_path, monkeypatch):
    logger = RunLogger(tmp_path)
    if logger._events is None:
        pytest.skip("tensorboardX is not installed or laid out differently")

    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(logger._events._inner, "write_event", full)
    monkeypatch.setattr(logger._events._inner, "flush", full)
    logger.log(5, {"return": 1.0})
    logger.flush()  # quiet: it also runs while another error is on its way out
    with pytest.raises(OSError) as raised:
        logger.log(10, {"return": 2.0})  # the next row reports it, in the training loop's thread
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(tmp_path / "tensorboard")
    logger.log(15, {"return": 3.0})  # reported once; later events are dropped
    logger.close()
    assert (tmp_path / "metrics.csv").exists()


def test_orbax_saves_left_unawaited_by_a_failed_checkpoint_do_not_warn():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        quiet_abandoned_saves()
        warnings.warn("coroutine 'JsonCheckpointHandler.async_save' was never awaited", RuntimeWarning, stacklevel=1)
        warnings.warn("coroutine 'mine' was never awaited", RuntimeWarning, stacklevel=1)
    assert [str(w.message) for w in caught] == ["coroutine 'mine' was never awaited"]


def _can_mount_tmpfs(folder: Path) -> bool:
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-rm", "sh", "-c", f"mount -t tmpfs -o size=64k none {folder}"],
                           capture_output=True, check=False)
    return probe.returncode == 0


@pytest.mark.slow  # compiles a tiny SAC run (~1 min on 2 cores)
def test_a_full_disk_during_training_prints_one_line_naming_the_folder(synthetic_shards, tmp_path):
    """A real full disk: a 600 KiB tmpfs (a user namespace, no root) holds the run directory."""
    full = tmp_path / "full"
    full.mkdir()
    if not _can_mount_tmpfs(full):
        pytest.skip("no user namespaces here: cannot mount a small tmpfs without root")
    tiny = ["data.num_roadgraph_points=5000", "data.num_paths=4", "data.max_num_lights=8",
            f"data.num_objects={NUM_OBJECTS}", "algo_preset=debug", "network.embed_dim=16", "network.output_dim=32",
            "network.mlp_hidden=32", "obs.num_objects=4", "obs.num_history=2", "obs.num_path_targets=4",
            "train.total_env_steps=40", "train.chunk_steps=5", "train.pool_size=4", "train.pool_refresh=2",
            "train.eval_scenarios=4", "train.eval_batch_size=4", "train.eval_every=0", "train.checkpoint_every=10"]
    train = [str(Path(sys.executable).parent / "vmax-sim"), "train", "--preset", "sac-mlp", "--quiet",
             "--data", str(synthetic_shards), "--eval-data", str(synthetic_shards), "--out", str(full / "run"), *tiny]
    script = f"mount -t tmpfs -o size=600k none {full} && exec {' '.join(train)}"
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=900)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr  # no traceback, no warning: the error alone
    assert lines[0].startswith(f"error: {full / 'run'}") and "No space left on device" in lines[0], lines[0]
    assert lines[0].endswith(f"rerun with --resume {full / 'run'}")  # the option takes the run directory
