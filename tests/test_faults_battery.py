"""Faults found by tools/fault_battery.py (issue 29), each at its cause: one line naming the path
and the cause, the right exit code, nothing left half-written."""

from __future__ import annotations

import errno
import importlib
import os

from helpers import one_line_error

import kbcli.cli.record as record
from kbcli.cli import app
from kbcli.errors import KbcliError

cli_app = importlib.import_module("kbcli.cli.app")  # (kbcli.cli.app is also the Typer app)


def test_bench_json_in_an_unwritable_folder_refused_before_the_benchmark(runner, tmp_path,
                                                                          monkeypatch):
    """``bench --json`` into a read-only folder ran the benchmark, then ended in a traceback."""
    ran = []
    monkeypatch.setattr(cli_app, "probe_writable", lambda folder, target: (_ for _ in ()).throw(
        KbcliError(f"{target}: cannot write in {folder} (Read-only file system)")))
    monkeypatch.setattr(record, "machine", lambda: ran.append(1) or "m")
    r = runner.invoke(app, ["bench", "--json", str(tmp_path / "x" / "b.json"), "arm",
                            "--reaches", "2"])
    one_line_error(r, "b.json: cannot write in", "(Read-only file system)")
    assert ran == [] and list(tmp_path.iterdir()) == []


def test_bench_json_on_a_full_disk_is_one_line(runner, tmp_path, monkeypatch):
    """The result file is written after the benchmark, outside the commands' error boundary: a
    full disk there was a traceback with exit 0."""
    def full(path, argv=None):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(record, "write", full)
    out = tmp_path / "b.json"
    r = runner.invoke(app, ["bench", "--json", str(out), "arm", "--reaches", "2"])
    assert r.exit_code == 1, r.output
    assert r.output.strip().splitlines()[-1] == f"kbcli: error: {out}: No space left on device"
    assert "Traceback" not in r.output and list(tmp_path.iterdir()) == []
