"""Long parallel runs kept in a checkpoint (``kbcli evaluate``, ``kbcli quality``): Ctrl-C keeps
what finished and says how to resume."""

from __future__ import annotations

import contextlib
from collections.abc import Iterable
from typing import Any

import typer

from kbcli.cli.app import err
from kbcli.cli.show import progress
from kbcli.errors import ConfigError, KbcliError
from kbcli.io import signals
from kbcli.io.runner import check_scheduler_address


def check_backend(jobs: int, scheduler: str | None, why: str = "") -> None:
    """Refuse ``--jobs`` below 1, and ``--jobs`` with ``--scheduler`` (``why``: said after)."""
    if jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {jobs}")
    if scheduler is not None:
        if jobs != 1:
            raise ConfigError(f"--jobs and --scheduler exclude each other{why}")
        check_scheduler_address(scheduler)


def load_checkpoint(ckpt: Any, resume: bool, first: str) -> dict[int, dict]:
    """The results kept in ``ckpt`` (none without ``resume``); a note when ``--resume`` finds no
    checkpoint (make's targets always pass --resume: a note, not a refusal), the run starting from
    the ``first`` (a noun: "experiment")."""
    if resume and not ckpt.exists():
        err.print(f"kbcli: note: --resume: no checkpoint {ckpt.folder}/ to continue; starting "
                  f"from the first {first}", markup=False)
    return ckpt.load(resume)


def note_resumed(done: dict, total: int, what: str) -> None:
    """Say how many of ``total`` ``what`` (a plural noun) a resumed run already has."""
    if done:
        err.print(f"resuming: {len(done)} of {total} {what} already done", markup=False)


def run_checkpointed(results: Iterable[tuple[int, dict]], todo: int, ckpt: Any, *, kept: int,
                     total: int, what: str) -> dict[int, dict]:
    """Drain ``(index, result)`` pairs of a parallel job into its checkpoint, with a progress bar.

    On Ctrl-C the pending results are flushed, one line says how many of ``total`` ``what`` (a
    plural noun) are kept and how to resume, and the command exits 130. ``results`` is
    :func:`kbcli.io.runner.execute`'s output, ``todo`` how many to expect, ``kept`` how many the
    checkpoint held when this run resumed. Returns the new results by index.
    """
    fresh: dict[int, dict] = {}
    try:
        for i, res in progress(results, todo, what):
            ckpt.add(i, res)
            fresh[i] = res
        ckpt.flush()
    except KeyboardInterrupt as exc:
        failed = False
        try:
            ckpt.flush()
        except KbcliError:
            failed = True
        n = kept + ckpt.written  # what is on disk
        lost = f" (writing the last {ckpt.pending} failed)" if failed else ""
        if ckpt.exists():  # (it may hold earlier phases' work even when n is 0)
            msg = (f"{n} of {total} {what} kept in {ckpt.folder}{lost}: rerun with --resume to "
                   "continue")
        elif fresh:
            msg = f"{len(fresh)} of {total} {what} had finished, but writing them failed; nothing was kept"
        else:
            msg = f"none of {total} {what} had finished; nothing was kept"
        err.print(f"kbcli: {signals.what(exc)}; {msg}", markup=False)
        raise typer.Exit(signals.exit_code(exc)) from None
    except BaseException as exc:  # keep what finished, then let the error speak
        with contextlib.suppress(KbcliError):
            ckpt.flush()
        if not isinstance(exc, KbcliError) or not ckpt.exists():
            raise
        n = kept + ckpt.written  # what is on disk
        if all(p.name == "meta.json" for p in ckpt.folder.iterdir()):  # nothing to resume
            with contextlib.suppress(OSError):
                ckpt.remove()
            raise
        raise KbcliError(f"{exc}; {n} of {total} {what} kept in {ckpt.folder}: rerun with "
                         "--resume to continue") from None
    return fresh
