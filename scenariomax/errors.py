"""Errors shared by both halves of the package: the converter (`scenariomax`) and the simulator (`vmax_sim`).

`InputError` is the error a user causes with bad input (a missing, unreadable or malformed file, a wrong
option): its message is one line naming the file and the problem, and the command-line tools print it as
is, without a traceback. Raise it wherever such input is detected; catch it at the command-line boundary.

This module imports nothing from the package, so every module (sources, pipeline, reader, simulator) can
use it without import cycles. Errors about one format stay beside the code that reads that format and
subclass `ValueError` like `InputError` does: `ShardReadError` (`scenariomax.shards`), `SchemaError` and
`BudgetError` (`scenariomax.codec`), `RecordError` (`scenariomax.io`).
"""

from __future__ import annotations

import errno
import os


class InputError(ValueError):
    """A raw input file is unreadable or malformed. The message is one line naming file and reason."""


def describe_os_error(error: OSError, resume_with: str | None = None, where: str | os.PathLike | None = None) -> str:
    """One line for an OS error (read-only or full disk, permission, missing file): the path once, the problem,
    what to do. `resume_with`: the option that continues the command where it stopped (`--resume` for a conversion,
    `--resume RUN_DIR` for training). `where`: the folder being written, named when the error carries no file name
    (a full disk seen by a library's writer)."""
    where = error.filename or where or "the output folder"
    rerun = "rerun" + (f" with {resume_with}" if resume_with else "")
    if error.errno == errno.ENOSPC:
        advice = f"free some space, then {rerun}"
    elif error.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
        advice = "choose a folder you can write to, or fix its permissions"
    elif error.errno == errno.ENOENT:
        advice = "check the path"
    elif error.errno in (errno.EEXIST, errno.ENOTDIR):
        advice = "a file stands where a folder is needed; choose another path"
    else:
        advice = f"fix it, then {rerun}"
    return f"{where}: {error.strerror or type(error).__name__}; {advice}"


def one_line(error: BaseException) -> str:
    """The message a command-line tool prints for a user-caused error: its first line, OS errors described."""
    if isinstance(error, OSError) and error.strerror:
        return describe_os_error(error)
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


__all__ = ["InputError", "describe_os_error", "one_line"]
