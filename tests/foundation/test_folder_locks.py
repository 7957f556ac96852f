"""One writer per output folder: a conversion or a training run refuses a folder another process writes."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from scenariomax import ConvertSettings, Sizes, SyntheticSource, convert
from scenariomax.locks import LOCK_FILE, FolderBusyError, FolderLock
from scenariomax.pipeline import ConversionError

HOLD = ("import sys, time; from scenariomax.locks import FolderLock\n"
        "with FolderLock(sys.argv[1], sys.argv[2]):\n    print('held', flush=True); time.sleep(60)")


@pytest.fixture
def holder(tmp_path):
    """Another process holding the lock of tmp_path / 'out' as a conversion."""
    process = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path / "out"), "conversion"],
                               stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "held"
    yield process
    process.kill()
    process.wait()


def test_a_second_writer_is_refused_naming_the_holder(holder, tmp_path):
    with pytest.raises(FolderBusyError, match=rf"in use by another conversion \(pid {holder.pid}\)"):
        with FolderLock(tmp_path / "out", "training run"):
            pass


def test_a_conversion_into_a_busy_folder_refuses_and_writes_nothing(holder, tmp_path):
    sizes = Sizes(num_objects=16)
    settings = ConvertSettings(out=tmp_path / "out", workers=1, sizes=sizes, progress=False)
    with pytest.raises(ConversionError, match="in use by another conversion"):
        convert(SyntheticSource(num_scenarios=2, seed=0, sizes=sizes), settings)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [LOCK_FILE]  # the holder's note only


def test_the_lock_dies_with_its_process_and_the_folder_converts(holder, tmp_path):
    holder.kill()
    holder.wait()
    time.sleep(0.1)
    sizes = Sizes(num_objects=16)
    result = convert(SyntheticSource(num_scenarios=2, seed=0, sizes=sizes),
                     ConvertSettings(out=tmp_path / "out", workers=1, sizes=sizes, progress=False))
    assert result.num_scenarios == 2
    assert not (tmp_path / "out" / LOCK_FILE).exists()  # the note goes with the lock
    (tmp_path / "out" / LOCK_FILE).write_text("conversion (pid 1)\n")  # as a kill -9 leaves it
    again = convert(SyntheticSource(num_scenarios=2, seed=0, sizes=sizes),
                    ConvertSettings(out=tmp_path / "out", workers=1, sizes=sizes, progress=False, overwrite=True))
    assert again.num_scenarios == 2


def test_an_os_error_without_a_file_name_names_the_folder_written():
    import errno

    from scenariomax.errors import describe_os_error

    full = OSError(errno.ENOSPC, "No space left on device")  # as a library's writer raises it
    line = describe_os_error(full, resume_with="--resume runs/sac", where="runs/sac")
    # the rerun it advises is the command that continues: `vmax-sim train --resume` needs the run directory
    assert line == "runs/sac: No space left on device; free some space, then rerun with --resume runs/sac"
