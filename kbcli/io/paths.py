"""Output paths checked against input paths before any work: a user's input files are sacred.

Every command calls :func:`check_outputs` first: an output that is an input under another name
(the same path, a link to it, or a folder holding it that would be filled or removed) is refused
with one line. Two paths are the same file when their resolved paths or ``(st_dev, st_ino)`` are.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from kbcli.errors import KbcliError

PathLike = str | os.PathLike


@dataclass(frozen=True)
class Output:
    """A path a command would write.

    Attributes
    ----------
    path : Path
        The file, or the folder when ``folder`` is True.
    what : str
        What it is, for the message ("--output", "--wav", "report folder").
    folder : bool
        A folder the command creates or fills (report, checkpoint), writing ``files`` in it.
    removes : bool
        The command deletes the folder afterwards (a checkpoint): no input may live inside it.
    figure : bool
        A figure: its suffix picks the format (:func:`figure_format`).
    """

    path: Path
    what: str = "output"
    folder: bool = False
    files: tuple[str, ...] = field(default_factory=tuple)
    removes: bool = False
    figure: bool = False


def _file_type(mode: int) -> str | None:
    """What a non-regular file is ("a FIFO", "a character device", ...), None for a regular one."""
    import stat

    for test, name in ((stat.S_ISREG, None), (stat.S_ISDIR, "a folder"),
                       (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def check_replaceable(path: PathLike) -> None:
    """Refuse (:class:`KbcliError`) an output path that exists and is not a regular file (a FIFO,
    ``/dev/null``, a socket; a symlink to one): writing replaces the file."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return  # a new path (or one the write itself will report on)
    kind = _file_type(mode)
    if kind is not None:
        raise KbcliError(f"{path}: is {kind}; an output is a regular file or a new path "
                         f"(kbcli replaces it): choose another output name")


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except (OSError, RuntimeError):  # a symlink loop
        return path.absolute()


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` name the same file: equal resolved paths or equal (device, inode)."""
    a, b = Path(a), Path(b)
    if _resolved(a) == _resolved(b):
        return True
    ia, ib = _identity(a), _identity(b)
    return ia is not None and ia == ib


def _inside(folder: Path, path: Path) -> bool:
    f, p = _resolved(folder), _resolved(path)
    return f == p or f in p.parents


def check_outputs(inputs: Mapping[str, PathLike | None] | Iterable[tuple[str, PathLike | None]],
                  outputs: Iterable[Output]) -> None:
    """Refuse any output that would overwrite (or delete) an input, or another output.

    Parameters
    ----------
    inputs : mapping or iterable of (what, path)
        The files the command reads, by role ("--model", "RUN"); None entries are skipped.
    outputs : iterable of Output
        What it would write.

    Raises
    ------
    KbcliError
        One line naming the output and the input it would destroy.
    """
    items = inputs.items() if isinstance(inputs, Mapping) else inputs
    ins = [(what, Path(p)) for what, p in items if p is not None]
    outs = list(outputs)
    for o in outs:
        targets = [o.path] if not o.folder else [o.path / name for name in o.files]
        for what, src in ins:
            for t in targets:
                if same_file(t, src):
                    name, role = (t, f"the {o.what}") if t == o.path else \
                        (f"{o.path}/{t.name}", f"a file the {o.what} writes")
                    raise KbcliError(
                        f"{name}: {role} is the input {src} ({what}); refusing to overwrite "
                        f"an input: choose another output name"
                    )
            if o.folder and o.removes and _inside(o.path, src):
                raise KbcliError(
                    f"{o.path}: the {o.what} holds the input {src} ({what}), which it would "
                    f"delete: choose another output name"
                )
            if o.folder and same_file(o.path, src):
                raise KbcliError(f"{o.path}: the {o.what} is the input {src} ({what})")
    for i, a in enumerate(outs):
        for b in outs[i + 1:]:
            pa = [a.path] if not a.folder else [a.path / n for n in a.files]
            pb = [b.path] if not b.folder else [b.path / n for n in b.files]
            if any(same_file(x, y) for x in pa for y in pb):
                raise KbcliError(f"{a.path}: the {a.what} and the {b.what} ({b.path}) are the same "
                                 f"file; give them different names")


#: Figure formats a ``-o`` suffix selects (matplotlib writes each natively).
FIGURE_FORMATS = ("png", "pdf", "svg")


def figure_format(path: PathLike) -> str:
    """The figure format of an output path, from its suffix (``.png``, ``.pdf`` or ``.svg``).

    Raises
    ------
    ConfigError
        Another suffix (or none): the message lists the formats.
    """
    from kbcli.errors import ConfigError

    ext = Path(path).suffix.lower().lstrip(".")
    if ext not in FIGURE_FORMATS:
        raise ConfigError(f"{path}: a figure is written as {', '.join('.' + f for f in FIGURE_FORMATS)}"
                          f" (chosen by the suffix), got {Path(path).suffix or 'no suffix'}")
    return ext


def probe_writable(folder: PathLike, target: PathLike, *, folder_output: bool = False) -> None:
    """Refuse (:class:`KbcliError`), before any work, a folder in which nothing can be created,
    by creating and removing a temporary file (or folder) there."""
    import tempfile

    folder = Path(folder) if str(folder) else Path(".")
    try:
        if folder_output:
            tempfile.TemporaryDirectory(prefix=".kbcli-probe-", dir=folder).cleanup()
        else:
            fd, tmp = tempfile.mkstemp(prefix=".kbcli-probe-", dir=folder)
            os.close(fd)
            os.unlink(tmp)
    except OSError as exc:
        raise KbcliError(f"{target}: cannot write in {folder} ({exc.strerror or exc})") from None


def checkout_file(relative: PathLike, option: str) -> Path:
    """A default input named relative to a kbcli checkout (``data/...``, ``pipelines/...``): that
    path in the current folder, else in the checkout this package runs from.

    Raises
    ------
    KbcliError
        When neither exists (an installed kbcli without its checkout): pass ``option``.
    """
    rel = Path(relative)
    for base in (Path.cwd(), Path(__file__).resolve().parents[2]):
        if (base / rel).is_file():
            return base / rel if base != Path.cwd() else rel
    raise KbcliError(f"{rel}: not found here nor in the kbcli checkout: pass {option} FILE")


#: The embedded default model (learned in dynamics mode by ``make data``), relative to a checkout.
DEFAULT_MODEL = "data/default-model.h5"


def default_model_path() -> Path:
    """Where the embedded default model is: ``data/default-model.h5`` of the current folder, else
    of the kbcli checkout this package runs from.

    Raises
    ------
    KbcliError
        When neither exists (an installed kbcli without its checkout): pass ``--model``.
    """
    return checkout_file(DEFAULT_MODEL, "--model")
