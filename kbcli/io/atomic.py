"""Atomic file writes: a temporary file in the destination folder, then ``os.replace``.

A crash or Ctrl-C never leaves a half-written file under the final name; the final file is mode 0644.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from kbcli.errors import ArtifactError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[str]:
    """Yield a temporary path to write; on success it replaces ``path``, on error it is removed.

    Raises
    ------
    ArtifactError
        If the folder cannot be written.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=folder)
    except OSError as exc:
        raise ArtifactError(f"{path}: cannot write in {folder} ({exc.strerror})") from None
    os.close(fd)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno is not None:
            raise ArtifactError(f"{path}: cannot write ({exc.strerror})") from None
        raise
