"""The Typer application, shared option types and the error boundary.

The CLI only parses, calls stages and reports. Domain errors (:class:`KbcliError`) become one line
on stderr and exit 1; usage errors keep Click's exit 2; Ctrl-C exits 130 without a traceback.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from kbcli import __version__
from kbcli.errors import KbcliError

app = typer.Typer(
    name="kbcli",
    help=(
        "Where is my keyboard? A robot arm learns a virtual keyboard, notices when it is moved, "
        "and recovers the displacement with few, well-chosen touches. Each stage reads and writes "
        "HDF5 artifacts: keyboard -> learn -> perturb -> play -> detect -> adapt -> evaluate -> report."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,
)
plot_app = typer.Typer(help="Draw an artifact as a PNG figure.", no_args_is_help=True)
bench_app = typer.Typer(
    help="Benchmarks: print tables of speed and sample-efficiency figures (not tests).",
    no_args_is_help=True,
)
app.add_typer(plot_app, name="plot")
app.add_typer(bench_app, name="bench")

out = Console()
err = Console(stderr=True, highlight=False, soft_wrap=True)

F = TypeVar("F", bound=Callable[..., Any])


def handle_errors(fn: F) -> F:
    """Turn domain errors into one line on stderr and exit 1; Ctrl-C into exit 130."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except KbcliError as exc:
            err.print(f"kbcli: error: {exc}", markup=False)
            raise typer.Exit(1) from None
        except KeyboardInterrupt:
            err.print("kbcli: interrupted", markup=False)
            raise typer.Exit(130) from None

    return wrapper  # type: ignore[return-value]


def command(typer_app: typer.Typer = app, **kwargs: Any) -> Callable[[F], F]:
    """Register a command on ``typer_app`` behind the error boundary."""

    def deco(fn: F) -> F:
        return typer_app.command(**kwargs)(handle_errors(fn))

    return deco


def interactive() -> bool:
    """Whether to draw progress bars: only on a terminal, never in CI logs."""
    return sys.stderr.isatty() and not os.environ.get("CI")


T = TypeVar("T")


def progress(items: Iterable[T], total: int | None, description: str) -> Iterator[T]:
    """Iterate with a Rich progress bar on a terminal (count, rate, time left); plain otherwise."""
    if not interactive():
        yield from items
        return
    cols = (
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
    )
    with Progress(*cols, console=err, transient=True) as bar:
        task = bar.add_task(description, total=total)
        for item in items:
            yield item
            bar.advance(task)


def output_path(path: Path, force: bool = True) -> Path:
    """Check an output path's folder exists before any work is done."""
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise KbcliError(f"{path}: output folder {folder} does not exist")
    if path.is_dir():
        raise KbcliError(f"{path}: is a folder, expected a file name")
    return path


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
