"""The local worker processes of a parallel run: how many the machine can use, and that none
outlives the kbcli that started it.

More processes than cores only run slower (each also holds a model in memory), so ``--jobs`` is
capped at the cores this process may use (:func:`cap_jobs`). A worker watches its parent
(:func:`watch_parent`) and exits when the parent is gone, even when it was killed with SIGKILL,
which no handler can catch; on an error, Ctrl-C or SIGTERM joblib stops the workers itself.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity; the machine's count elsewhere)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def cap_jobs(jobs: int, option: str = "--jobs") -> tuple[int, str | None]:
    """``jobs`` capped at :func:`usable_cores` (more processes than cores only run slower, and
    each one holds a model in memory), and a note saying so (None when not capped). Values below
    1 pass through, for :func:`kbcli.io.runner.execute` to refuse (``option``: the flag the note names)."""
    cores = usable_cores()
    if isinstance(jobs, int) and jobs > cores:
        return cores, (f"{option} {jobs} is more than the {cores} cores this machine lets kbcli "
                       f"use: running {cores} worker processes")
    return jobs, None


@contextlib.contextmanager
def children_deaf_to_ctrl_c() -> Iterator[None]:
    """Start worker processes inside this block: they never see Ctrl-C.

    A terminal sends Ctrl-C to the whole process group, and the parent stops the workers itself.
    SIGINT is blocked in this thread for the block, and a blocked signal stays blocked across fork
    and exec; a Ctrl-C that arrives during the block is delivered to this process just after it.
    """
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    # Started first: Python 3.11's tracker unblocks SIGINT (SIG_UNBLOCK, not the old mask) after
    # starting itself, which loky does just before its workers.
    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


_WATCHING: list[int] = []


def watch_parent(parent: int, every: float = 1.0) -> None:
    """Exit this worker process when its parent ``parent`` dies (a worker never outlives the kbcli
    that started it, even one killed with SIGKILL): a daemon thread notices the worker being
    re-parented and ends the process. Started once per process, only in a direct child."""
    if _WATCHING or os.getppid() != parent:
        return
    _WATCHING.append(parent)

    def watch() -> None:
        while True:
            time.sleep(every)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="kbcli-parent-watch", daemon=True).start()
