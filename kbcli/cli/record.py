"""Benchmark tables kept as a result file: ``kbcli bench --json PATH COMMAND ...``.

Every table a bench command shows goes through :func:`show_table`; with ``--json`` the tables are
also written, when the command ends, to one JSON file with the command line, the date, the machine
and the kbcli version, the git commit of the code and whether its tree was clean, and the sha256 of
every input file the command named: ``{"command", "date", "machine", "kbcli_version",
"platform", "load", "git", "inputs", "tables": [{"title", "columns", "rows": [{column: cell}]}]}``
(:mod:`kbcli.io.provenance`).
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import sys
from pathlib import Path

from rich.console import Console
from rich.table import Table
from rich.text import Text

from kbcli import __version__
from kbcli.io.atomic import atomic_path
from kbcli.io.platform import fingerprint
from kbcli.io.provenance import git_state, inputs

_recorded: list[Table] | None = None
_load_at_start: list[float] | None = None
_path: Path | None = None


def show_table(con: Console, table: Table) -> None:
    """Print ``table`` on ``con``, and keep it when the command records its tables."""
    con.print(table)
    if _recorded is not None:
        _recorded.append(table)


def start(path: Path | None = None) -> None:
    """Keep every table shown from now on (for :func:`finish` to write to ``path``)."""
    global _recorded, _path, _load_at_start
    _recorded, _path, _load_at_start = [], path, load_average()


def finish() -> None:
    """The command ended well: write its tables where :func:`start` was asked to."""
    global _path
    path, _path = _path, None
    if path is not None:
        write(path)
        print(f"wrote {path}", file=sys.stderr)


def _plain(cell) -> str:
    return cell.plain if isinstance(cell, Text) else str(cell)


def table_dict(table: Table) -> dict:
    """A Rich table as ``{"title", "columns", "rows"}`` of plain strings."""
    columns = [_plain(c.header) for c in table.columns]
    cells = [[_plain(x) for x in c.cells] for c in table.columns]
    rows = [dict(zip(columns, r, strict=True)) for r in zip(*cells, strict=True)] if cells else []
    return {"title": _plain(table.title or ""), "columns": columns, "rows": rows}


def machine() -> str:
    """A short description of this machine: CPU model (where readable), cores, OS."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}"


def load_average() -> list[float] | None:
    """The 1, 5 and 15 minute load averages (None where the OS does not say): timings made on a
    busy machine are read beside the load they ran under."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        return None


def load_note() -> str:
    """The load averages as a reader sees them under a timing table ("6.1 5.9 5.2"), or "unknown"."""
    load = load_average()
    return " ".join(f"{x:g}" for x in load) if load else "unknown"


def timing_note(what: str = "wall time") -> str:
    """What the times of a timing table are: ``what`` on a machine others share (its load), and
    CPU time of this process only."""
    return f"{what} on a shared machine (load average {load_note()}); CPU time: this process only"


def write(path: Path, argv: list[str] | None = None) -> None:
    """Write the tables kept so far to ``path`` (atomically) and stop keeping them."""
    global _recorded
    tables, _recorded = _recorded or [], None
    args = sys.argv[1:] if argv is None else argv
    d = {"command": shlex.join(["kbcli", *args]),
         "date": datetime.date.today().isoformat(), "machine": machine(),
         "kbcli_version": __version__, "platform": fingerprint(),
         "load": {"start": _load_at_start, "end": load_average(), "cores": os.cpu_count()},
         "git": git_state(), "inputs": inputs(args),
         "tables": [table_dict(t) for t in tables]}
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps(d, indent=1) + "\n")
