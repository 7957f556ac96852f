"""Child processes of a conversion die with the process that started them (kill -9 included)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def exit_with_parent() -> None:
    """Linux: SIGKILL this process the moment its parent dies. A no-op elsewhere (see `watch_process`)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass


def watch_process(pid: int, interval_s: float = 0.5) -> None:
    """Exits this process once `pid` is gone: the portable fallback, run in a daemon thread."""

    def watch() -> None:
        while _alive(pid):
            time.sleep(interval_s)
        os._exit(1)

    threading.Thread(target=watch, name=f"watch-{pid}", daemon=True).start()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # the pid now belongs to another user's process: ours is gone
        return False
    return True
