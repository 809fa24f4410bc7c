"""Progress bars and spinners (on a terminal only) and the tables a benchmark prints when it ends
(kept for ``kbcli bench --json`` by :func:`kbcli.cli.record.show_table`)."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Collection, Iterable, Iterator
from typing import Any, TypeVar

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from kbcli.cli.app import err, out

T = TypeVar("T")


def interactive() -> bool:
    """Whether to draw progress bars: only on a terminal, never in CI logs."""
    return sys.stderr.isatty() and not os.environ.get("CI")


@contextlib.contextmanager
def _bar(description: str, total: int | None) -> Iterator[tuple[Progress, Any]]:
    """A transient progress bar on stderr (description, bar, count, elapsed, time left)."""
    cols = (TextColumn("[progress.description]{task.description}"), BarColumn(),
            MofNCompleteColumn(), TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn())
    with Progress(*cols, console=err, transient=True) as bar:
        yield bar, bar.add_task(description, total=total)


def progress(items: Iterable[T], total: int | None, description: str, *,
             advance: Callable[[T], float] | None = None,
             describe: Callable[[T], str | None] | None = None) -> Iterator[T]:
    """Iterate with a Rich progress bar on a terminal (count, rate, time left); plain otherwise.

    ``total`` units of work (None: no bar end); ``advance(item)``: the units an item stands for
    (default 1); ``describe(item)``: a new description after it (None keeps the current one).
    """
    if not interactive():
        yield from items
        return
    with _bar(description, total) as (bar, task):
        for item in items:
            yield item
            bar.advance(task, 1 if advance is None else advance(item))
            if describe is not None and (text := describe(item)) is not None:
                bar.update(task, description=text)


def drain(items: Iterable[Any], total: int | None, description: str, **kw: Any) -> None:
    """Run an iterator of steps to its end behind :func:`progress`."""
    for _ in progress(items, total, description, **kw):
        pass


@contextlib.contextmanager
def ticker(total: int | None, description: str) -> Iterator[Callable[..., None]]:
    """A progress bar driven by a callback, for stages that report their steps through one:
    ``with ticker(T, "adapting") as tick: stage.run(..., on_step=tick)``. Plain when not a
    terminal (the callback does nothing)."""
    if not interactive():
        yield lambda *a, **k: None
        return
    with _bar(description, total) as (bar, task):
        yield lambda *a, **k: bar.advance(task)


@contextlib.contextmanager
def phases(description: str) -> Iterator[Callable[[str], None]]:
    """A spinner with the elapsed time on a terminal for work done in named phases: yields
    ``phase(text)``, which shows the phase now running (nothing when not a terminal)."""
    if not interactive():
        yield lambda text: None
        return
    cols = (SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn())
    with Progress(*cols, console=err, transient=True) as bar:
        task = bar.add_task(description, total=None)
        yield lambda text: bar.update(task, description=text)


@contextlib.contextmanager
def busy(description: str) -> Iterator[None]:
    """A spinner with the elapsed time on a terminal, for work that has no natural count (drawing a
    figure, writing a report); nothing otherwise."""
    with phases(description):
        yield


def wide(width: int) -> Console:
    """The console of a table ``width`` columns wide: the terminal's, else one never narrower
    (a table is never wrapped at a narrow default width when the output is not a terminal)."""
    return out if interactive() else Console(width=max(out.width, width), highlight=False)


def table(title: str, columns: Iterable[str], left: int | Collection[str] = 1, *,
          title_justify: str = "left", **column: Any) -> Table:
    """A table of ``columns``, numbers right-justified: all but the first ``left`` columns (or
    but those named in ``left``); ``column``: further options of every column."""
    t = Table(title=title, title_justify=title_justify)
    for i, col in enumerate(columns):
        at_left = i < left if isinstance(left, int) else col in left
        t.add_column(col, justify="left" if at_left else "right", **column)
    return t
