"""One writer per output: a lock file beside it, ``.NAME.kbcli-lock``, holding the writer's pid.

Two commands writing one output would otherwise race, and the last to finish would silently win.
The second is refused with one line naming the first one's pid; a lock whose process is gone (a
run killed with SIGKILL) is taken over. Locks are released (their files removed) when the command
ends, however it ends.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from kbcli.errors import KbcliError
from kbcli.io.atomic import alive

LOCK_SUFFIX = ".kbcli-lock"

#: Locks this process holds: path of the lock file -> how many times it was taken.
_HELD: dict[Path, int] = {}


def lock_file(path: str | os.PathLike) -> Path:
    """The lock file of an output: ``.NAME.kbcli-lock`` in the same folder."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    return folder / f".{path.name}{LOCK_SUFFIX}"


def _holder(lock: Path) -> int | None:
    """The pid in a lock file, or None when unreadable or empty (being written)."""
    try:
        text = lock.read_text(encoding="ascii").strip()
        return int(text) if text else None
    except (OSError, ValueError):
        return None


def acquire(path: str | os.PathLike) -> Path | None:
    """Take the lock of output ``path``; returns its lock file (None when the folder cannot hold
    one: a read-only folder, which the command refuses anyway).

    Raises
    ------
    KbcliError
        Another live process holds it.
    """
    lock = lock_file(path)
    if lock in _HELD:
        _HELD[lock] += 1
        return lock
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            pid = _holder(lock)
            if pid is not None and pid != os.getpid() and alive(pid):
                raise KbcliError(f"{path}: another kbcli (pid {pid}) is writing it; wait for it to "
                                 f"finish or choose another output name") from None
            if pid is None and _young(lock):
                raise KbcliError(f"{path}: another kbcli is starting to write it; wait for it "
                                 f"to finish or choose another output name") from None
            with contextlib.suppress(OSError):  # a killed run's lock
                lock.unlink()
            continue
        except OSError:
            return None
        try:
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError:
            os.close(fd)
            with contextlib.suppress(OSError):
                lock.unlink()
            return None
        os.close(fd)
        _HELD[lock] = 1
        return lock
    raise KbcliError(f"{path}: cannot take the lock {lock}; remove it if no kbcli is running")


def _young(lock: Path, seconds: float = 5.0) -> bool:
    import time

    try:
        return time.time() - lock.stat().st_mtime < seconds
    except OSError:
        return False


def release(lock: Path | None) -> None:
    """Release a lock taken by :func:`acquire` (the file goes when the last holder releases)."""
    if lock is None or lock not in _HELD:
        return
    _HELD[lock] -= 1
    if _HELD[lock] <= 0:
        del _HELD[lock]
        if _holder(lock) == os.getpid():
            with contextlib.suppress(OSError):
                lock.unlink()


def release_all() -> None:
    """Release every lock this process holds."""
    for lock in list(_HELD):
        _HELD[lock] = 1
        release(lock)


def held() -> list[Path]:
    """The lock files this process holds."""
    return sorted(_HELD)
