"""One writer per folder: an OS lock (`flock` on the folder), held while a conversion or a training run writes.

Two processes writing one output folder interleave their files (a conversion and its `--resume` started together
lost records; two `train --resume` of one run duplicated rows). The second one now refuses in one line naming
the holder (read from `FOLDER/.lock`). The lock dies with its process (even after `kill -9`), so a crash never
leaves a folder locked; the note is removed when the lock is released.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from scenariomax.errors import InputError

LOCK_FILE = ".lock"


class FolderBusyError(InputError):
    """Another process holds the folder's lock."""


class FolderLock:
    """Context manager: the exclusive lock of `folder` (created if missing) for `purpose` ("conversion",
    "training run"); FolderBusyError (one line) when another process holds it.

    The lock is taken on the folder itself, so taking it writes nothing into a folder that may turn out not to be
    ours; `note_holder()` then writes who holds it into FOLDER/.lock for the refusal message (at once unless
    `note=False`, for a caller that first checks the folder is its own)."""

    def __init__(self, folder: str | Path, purpose: str, note: bool = True):
        self.folder = Path(folder)
        self.purpose = purpose
        self.note = note
        self._fd: int | None = None
        self._noted = False

    def __enter__(self) -> FolderLock:
        self.folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.folder, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            holder = _read_holder(self.folder / LOCK_FILE)
            raise FolderBusyError(f"{self.folder}: in use by another {holder or 'process'}; wait for it to end or "
                                  f"stop it, then try again") from None
        self._fd = fd
        if self.note:
            self.note_holder()
        return self

    def note_holder(self) -> None:
        (self.folder / LOCK_FILE).write_text(f"{self.purpose} (pid {os.getpid()})\n")
        self._noted = True

    def __exit__(self, *exc) -> None:
        if self._noted:  # the folder is left as the work made it (a note left by kill -9 is overwritten next time)
            (self.folder / LOCK_FILE).unlink(missing_ok=True)
            self._noted = False
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None


def _read_holder(path: Path) -> str:
    try:
        return path.read_text(errors="replace").strip()[:200]
    except OSError:
        return ""
