"""The Typer application, its consoles, the error boundary and the checks of a command's paths.

The CLI only parses, calls stages and reports. Domain errors (:class:`KbcliError`) become one line
on stderr and exit 1, and so do OS errors (a full disk: the path and the cause); usage errors keep
Click's exit 2; Ctrl-C exits 130 and SIGTERM 143, without a traceback.
"""

from __future__ import annotations

import functools
import inspect
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import typer
from rich.console import Console
from typer.core import TyperCommand

import kbcli.cli.record as record
from kbcli import __version__
from kbcli.core.config import plain_words
from kbcli.errors import KbcliError
from kbcli.io import lock, signals
from kbcli.io.atomic import describe_os_error
from kbcli.io.paths import Output, check_outputs, check_replaceable, figure_format, probe_writable

app = typer.Typer(
    name="kbcli",
    help=(
        "Where is my keyboard? A robot arm learns a virtual keyboard, notices when it is moved, "
        "and recovers the displacement with few, well-chosen touches. Each stage reads and writes "
        "HDF5 artifacts: keyboard -> learn -> perturb -> play -> detect -> adapt -> evaluate -> "
        "report. run chains play, detect, adapt and play on (the closed loop); serve adapts with "
        "a robot in another process; animate replays a run; quality measures how the strategies' "
        "advantage depends on the model's quality; inspect shows any artifact; plot draws one; "
        "bench prints the benchmarks."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,
)
plot_app = typer.Typer(help="Draw an artifact as a figure (PNG, PDF or SVG by the -o suffix).",
                       no_args_is_help=True)
bench_app = typer.Typer(
    help="Benchmarks: tables of speed and sample efficiency (not tests).",
    no_args_is_help=True,
)
app.add_typer(plot_app, name="plot")
app.add_typer(bench_app, name="bench")


def _refuse(exc: BaseException) -> None:
    """One ``kbcli: error:`` line and exit 1, for the bench group's own checks (outside
    :func:`handle_errors`)."""
    text = str(exc) if isinstance(exc, KbcliError) else (
        f"{getattr(exc, 'filename', None) or ''}: {describe_os_error(exc)}")
    err.print(f"kbcli: error: {text}", markup=False)
    raise typer.Exit(1) from None


def _bench_done(*_: Any, **__: Any) -> None:
    """After a bench command returned: write the tables it showed where ``--json`` asked."""
    try:
        record.finish()
    except (KbcliError, OSError) as exc:  # a full disk at the end: one line, not a traceback
        _refuse(exc)


def _check_json(path: Path) -> None:
    """Refuse, before the benchmark runs, a ``--json`` path whose folder (or nearest existing
    ancestor: the folders are made) cannot be written (read-only, missing permission)."""
    folder = path.parent if str(path.parent) else Path(".")
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        if not folder.is_dir():
            raise KbcliError(f"{path}: {folder} is not a folder")
        check_replaceable(path)
        probe_writable(folder, path)
    except KbcliError as exc:
        _refuse(exc)


@bench_app.callback(result_callback=_bench_done)
def _bench(json_path: Path | None = typer.Option(
               None, "--json", metavar="PATH",
               help="Also write the tables the benchmark prints to PATH (JSON: the command, "
                    "date, machine and kbcli version with each table's rows), as the "
                    "documentation's results pages read them (benchmarks/results/NAME.json).")
           ) -> None:
    """Benchmarks: tables of speed and sample efficiency (not tests)."""
    if json_path is not None:
        if json_path.suffix != ".json":  # so it can never be one of the command's inputs
            err.print(f"kbcli bench: --json {json_path}: a result file must end in .json")
            raise typer.Exit(1)
        _check_json(json_path)
        record.start(json_path)

#: Width of the consoles when the stream is not a terminal (a pipe, a file, a CI log): wide enough
#: that Rich never wraps a line in the middle of a value (a hash, a path, a number).
PIPE_WIDTH = 10_000


def _console(stderr: bool = False) -> Console:
    stream = sys.stderr if stderr else sys.stdout
    tty = stream.isatty()
    return Console(stderr=stderr, highlight=not stderr, soft_wrap=stderr or not tty,
                   width=None if tty else PIPE_WIDTH)


out = _console()
err = _console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])


def handle_errors(fn: F) -> F:
    """Turn domain errors and OS errors into one line on stderr and exit 1; Ctrl-C into exit 130,
    SIGTERM into exit 143."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        old_term = signals.install()
        try:
            return fn(*args, **kwargs)
        except KbcliError as exc:
            err.print(f"kbcli: error: {exc}", markup=False)
            raise typer.Exit(1) from None
        except OSError as exc:  # the machine (disk full, read-only, I/O error), not a bug
            if exc.errno is None:
                raise
            where = f"{exc.filename}: " if exc.filename is not None else ""
            err.print(f"kbcli: error: {where}{describe_os_error(exc)}", markup=False)
            raise typer.Exit(1) from None
        except KeyboardInterrupt as exc:
            err.print(f"kbcli: {signals.what(exc)}", markup=False)
            raise typer.Exit(signals.exit_code(exc)) from None
        finally:
            lock.release_all()  # the outputs check_io locked
            signals.restore(old_term)

    return wrapper  # type: ignore[return-value]


def first_sentence(doc: str | None) -> str:
    """The first sentence of a docstring, whole (the command list shows it; never cut)."""
    para = inspect.cleandoc(doc or "").split("\n\n")[0].replace("\n", " ")
    for m in re.finditer(r"[.!?](?=\s+[A-Z(]|$)", para):
        if not re.search(r"\b(Fig|Figs|Sect|Eq|Eqs|Alg|e\.g|i\.e|vs|cf)\.$", para[:m.end()]):
            return para[:m.end()]
    return para


class Command(TyperCommand):
    """A command whose usage errors speak kbcli's words: Typer checks an option's range with
    pydantic, whose "Input should be greater than or equal to 2" becomes "must be ..."."""

    def make_context(self, info_name, args, parent=None, **extra):
        try:
            return super().make_context(info_name, args, parent=parent, **extra)
        except typer.BadParameter as exc:
            exc.message = plain_words(str(exc.message))
            raise


def command(typer_app: typer.Typer = app, **kwargs: Any) -> Callable[[F], F]:
    """Register a command on ``typer_app`` behind the error boundary; its line in the command list
    (``short_help``) is the docstring's first sentence, whole, unless given."""

    def deco(fn: F) -> F:
        kwargs.setdefault("cls", Command)
        kwargs.setdefault("short_help", first_sentence(kwargs.get("help") or fn.__doc__))
        return typer_app.command(**kwargs)(handle_errors(fn))

    return deco


def note_default(name: str, value: Any, why: str) -> None:
    """Say on stderr, once, a default that depends on the input: ``family: rigid, the scene's``."""
    err.print(f"{name}: {value}, {why}", markup=False)


def note_arm(arm: Any, mode: str) -> None:
    """Say on stderr when ``mode`` ignores part of the arm (:func:`kbcli.sim.modes.ideal_mode_note`)."""
    from kbcli.sim.modes import ideal_mode_note

    if (line := ideal_mode_note(arm, mode)) is not None:
        err.print(line, markup=False)


def output_path(path: Path, force: bool = True) -> Path:
    """Check an output path's folder exists before any work is done."""
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise KbcliError(f"{path}: output folder {folder} does not exist")
    if path.is_dir():
        raise KbcliError(f"{path}: is a folder, expected a file name")
    check_replaceable(path)
    probe_writable(folder, path)
    return path


def output_folder(path: Path) -> Path:
    """Check a folder output (a report) can be created or filled before any work is done."""
    parent = path.parent if str(path.parent) else Path(".")
    if path.exists() and not path.is_dir():
        raise KbcliError(f"{path}: exists and is not a folder")
    if not parent.is_dir():
        raise KbcliError(f"{path}: parent folder {parent} does not exist")
    probe_writable(path if path.is_dir() else parent, path, folder_output=not path.is_dir())
    return path


def figure_output(path: Path, what: str = "figure") -> Output:
    """A figure output (``-o x.png``, ``.pdf`` or ``.svg``): the format is the file's suffix,
    checked by :func:`check_io` after the input check."""
    return Output(Path(path), what, figure=True)


def check_io(inputs: dict[str, Path | None], *outputs: Output | tuple[str, Path | None]) -> None:
    """Every check on a command's paths, before any work: each file output's folder exists and is
    writable, a folder output can be made, no output is one of the inputs (the same path, a
    symlink or a hard link to it, or a folder holding it that would be overwritten or removed), and
    no other kbcli is writing it (each output is locked until the command ends).

    ``inputs`` by option name (``{"--model": path}``) and ``outputs`` (an Output or a
    ``(what, path)`` pair); None paths are skipped.
    """
    outs: list[Output] = []
    for o in outputs:
        if isinstance(o, tuple):
            what, p = o
            if p is None:
                continue
            o = Output(Path(p), what)
        outs.append(o)
    check_outputs(inputs, outs)
    for o in outs:
        if o.folder:
            if not o.removes:
                output_folder(o.path)
        else:
            output_path(o.path)
        if o.figure:
            figure_format(o.path)  # ConfigError for a suffix other than .png, .pdf, .svg
    for o in outs:  # one writer per output: a second command on it is refused until this one ends
        lock.acquire(o.path)


def version_callback(value: bool) -> None:
    if value:
        out.print(f"kbcli {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=version_callback, is_eager=True, help="Print the version."
    ),
) -> None:
    """Where is my keyboard? Model-based active adaptation of a robot's action space."""
