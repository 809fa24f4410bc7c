"""Atomic writes: a temporary file (or folder) beside the destination, then ``os.replace``.

A crash, Ctrl-C or SIGTERM never leaves a half-written file under the final name. Temporary files
are named ``.NAME.kbcli-tmp-PID-XXXXXXXX.SUFFIX``, so the next write of ``NAME`` removes those a
killed run left. An OS error becomes one line of :class:`~kbcli.errors.ArtifactError` naming the
destination and the cause.
"""

from __future__ import annotations

import contextlib
import glob
import os
import re
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path

from kbcli.errors import ArtifactError, KbcliError
from kbcli.io.paths import check_replaceable

#: What every kbcli temporary file or folder has in its name.
TMP_MARK = ".kbcli-tmp-"
_PID = re.compile(re.escape(TMP_MARK) + r"(\d+)-")


def describe_os_error(exc: OSError) -> str:
    """The cause of an OS error in a few words: ``No space left on device``."""
    text = exc.strerror or (os.strerror(exc.errno) if exc.errno else "") or str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (another user's counts as running)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def clean_stale(path: str | os.PathLike) -> list[Path]:
    """Remove the temporary files and folders an earlier, killed kbcli run left beside ``path``
    (``.NAME.kbcli-tmp-PID-...`` whose process is gone); returns what was removed."""
    path = Path(path)
    removed: list[Path] = []
    pattern = str(_folder(path) / f".{glob.escape(path.name)}{TMP_MARK}*")
    for name in glob.glob(pattern):
        m = _PID.match(Path(name).name[len(path.name) + 1:])
        if m is None or alive(int(m.group(1))):
            continue
        if _remove(name):
            removed.append(Path(name))
    return removed


def _prefix(path: Path) -> str:
    return f".{path.name}{TMP_MARK}{os.getpid()}-"


def _remove(tmp: str | os.PathLike) -> bool:
    """Remove a file or a folder (not a link's target); whether it was removed."""
    try:
        if os.path.isdir(tmp) and not os.path.islink(tmp):
            shutil.rmtree(tmp)
        else:
            os.unlink(tmp)
    except OSError:
        return False
    return True


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block is done (their handlers then run just after it):
    a temporary file is never created without being known to the cleanup. The hold is at the
    Python level (``pthread_sigmask`` would let the kernel hand the signal to another thread);
    only the main thread runs Python signal handlers, so elsewhere there is nothing to hold.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []

    def hold(signum: int, frame: object) -> None:
        caught.append(signum)

    held = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if callable(handler):  # a Python handler (SIG_DFL and SIG_IGN need no hold)
            held[signum] = signal.signal(signum, hold)
    try:
        yield
    finally:
        for signum, handler in held.items():
            signal.signal(signum, handler)
        if caught:
            held[caught[0]](caught[0], None)


def write_error(path: str | os.PathLike, exc: OSError) -> ArtifactError:
    """The one-line error for an OS error while writing ``path``."""
    return ArtifactError(f"{path}: cannot write ({describe_os_error(exc)})")


def _fsync(path: str) -> None:
    with open(path, "rb+") as fh:
        os.fsync(fh.fileno())


@contextlib.contextmanager
def atomic_paths(paths: Sequence[str | os.PathLike], suffixes: Sequence[str] | None = None
                 ) -> Iterator[list[str]]:
    """Yield temporary paths for several files written together: all of them replace ``paths``
    once every one is written (an error removes them all, and no destination is touched).

    Raises
    ------
    ArtifactError
        A folder that cannot be written, or an OS error while writing (disk full, read-only file
        system, I/O error): the message names the destination and the cause.
    """
    paths = [Path(p) for p in paths]
    suffixes = list(suffixes) if suffixes is not None else [".tmp"] * len(paths)
    tmps: list[str] = []
    current = paths[0] if paths else Path(".")
    started = False
    for path in paths:
        check_replaceable(path)
    try:
        for path, suffix in zip(paths, suffixes, strict=True):
            current = path
            clean_stale(path)
            with _signals_deferred():  # a SIGTERM between mkstemp and append would orphan tmp
                fd, tmp = tempfile.mkstemp(prefix=_prefix(path), suffix=suffix, dir=_folder(path))
                tmps.append(tmp)
                os.close(fd)
        started = True
        yield list(tmps)
        for path, tmp in zip(paths, tmps, strict=True):
            current = path
            _fsync(tmp)
            os.chmod(tmp, 0o644)
        for path, tmp in zip(paths, tmps, strict=True):
            current = path
            os.replace(tmp, path)
    except BaseException as exc:
        for tmp in tmps:
            _remove(tmp)
        if isinstance(exc, OSError) and exc.errno is not None:
            if exc.filename is not None and str(exc.filename) in tmps:
                current = paths[tmps.index(str(exc.filename))]
            if not started:
                raise ArtifactError(f"{current}: cannot write in {_folder(current)} "
                                    f"({describe_os_error(exc)})") from None
            raise write_error(current, exc) from None
        raise
    _sync_folder(_folder(paths[0]) if paths else Path("."))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[str]:
    """Yield a temporary path to write; on success it replaces ``path``, on error it is removed.

    Raises
    ------
    ArtifactError
        If the folder cannot be written, or an OS error (disk full, read-only, I/O error) occurs.
    """
    with atomic_paths([path], [suffix]) as (tmp,):
        yield tmp


def write_bytes(path: str | os.PathLike, data: bytes, suffix: str = ".tmp") -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path, suffix) as tmp, open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()


def _sync_folder(folder: Path) -> None:
    """Make a rename durable (best effort)."""
    with contextlib.suppress(OSError):
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike, *, owned: Sequence[str] = ()) -> Iterator[Path]:
    """Yield a temporary folder beside ``path`` to fill; on success its files move into ``path``.

    A new ``path`` is the temporary folder renamed; an existing one gets each new file replacing
    its namesake (``README.md`` last), and the files an older run wrote there that this one did
    not (matching the globs ``owned``) removed; nothing else in it is touched. An error removes
    the temporary folder and leaves ``path`` as it was.

    Raises
    ------
    KbcliError
        The folder cannot be created, or an OS error while writing, naming ``path`` and the cause.
    """
    path = Path(path)
    clean_stale(path)
    tmp: Path | None = None
    try:
        with _signals_deferred():  # a SIGTERM between mkdtemp and the assignment orphans tmp
            tmp = Path(tempfile.mkdtemp(prefix=_prefix(path), dir=_folder(path)))
        yield tmp
        _move_in(tmp, path, owned)
    except BaseException as exc:
        if tmp is not None:
            _remove(tmp)
        error = _folder_error(exc, tmp, path)
        if error is None:
            raise
        raise error from None
    _sync_folder(_folder(path))


def _move_in(tmp: Path, path: Path, owned: Sequence[str]) -> None:
    """The files of the filled folder ``tmp`` into ``path`` (see :func:`atomic_folder`)."""
    names = sorted(os.listdir(tmp), key=lambda n: (n == "README.md", n))
    for name in names:
        _fsync(str(tmp / name))
    if not path.exists():
        os.chmod(tmp, 0o755)  # (mkdtemp makes it 0700)
        os.rename(tmp, path)
        return
    for name in names:
        os.replace(tmp / name, path / name)
    for pattern in owned:
        for old in path.glob(pattern):
            if old.name not in names and old.is_file():
                with contextlib.suppress(OSError):
                    old.unlink()
    _remove(tmp)


def _folder_error(exc: BaseException, tmp: Path | None, path: Path) -> KbcliError | None:
    """The one-line error for ``exc``, raised while making (``tmp`` None), filling or moving the
    temporary folder ``tmp`` of ``path``: naming ``path`` and the file in it, never ``tmp``; None:
    ``exc`` is not an error of the writing (raise it as it is)."""
    if tmp is None:
        return KbcliError(f"{path}: cannot create the folder in {_folder(path)} "
                          f"({describe_os_error(exc)})") if isinstance(exc, OSError) else None
    if isinstance(exc, OSError) and exc.errno is not None:
        where = path / Path(exc.filename).name if exc.filename is not None and \
            str(exc.filename).startswith(str(tmp)) else path
        return write_error(where, exc)
    if isinstance(exc, KbcliError) and str(tmp) in str(exc):  # name the file, not its draft
        return type(exc)(str(exc).replace(str(tmp), str(path)))
    return None
