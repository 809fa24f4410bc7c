"""Shared fixtures: a keyboard artifact on disk and a CLI runner."""

from __future__ import annotations

import os

import pytest
import typer.main
import typer.testing
from threadpoolctl import threadpool_limits
from typer.testing import CliRunner

from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import write_artifact
from kbcli.stages import keyboard as keyboard_stage

# One BLAS / OpenMP thread per test process: `make test` runs one pytest worker per core, and a
# BLAS pool of one thread per core in each worker oversubscribes them (the pools spin waiting on
# each other). kbcli's own runner limits its workers the same way (kbcli/io/runner.py). The
# variables reach the processes the tests start; numpy is loaded already here, so this process
# is limited through threadpoolctl. The learned bytes are the same (test_golden's rebuild and
# test_stored_results' learn compare them with the stored ones).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
threadpool_limits(limits=1)

#: The click command Typer builds from an app, built once per test process. Typer's CliRunner
#: rebuilds it from the app's functions at every invoke (evaluating every option's annotations:
#: 60 ms an invoke, minutes over the suite's thousands of invokes); the command is the same each
#: time (kbcli registers its commands at import and never changes them), and a real ``kbcli``
#: process builds it once too. Tests that build it themselves (typer.main.get_command) still do.
_COMMANDS: dict[int, tuple[typer.Typer, object]] = {}


def _command_built_once(app: typer.Typer):
    if id(app) not in _COMMANDS:
        _COMMANDS[id(app)] = (app, typer.main.get_command(app))  # the app kept: its id stays its
    return _COMMANDS[id(app)][1]


typer.testing._get_command = _command_built_once


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


@pytest.fixture
def kb_path(tmp_path):
    """A default keyboard artifact written to a temporary folder."""
    path = tmp_path / "kb.h5"
    write_artifact(keyboard_stage.run(KeyboardConfig()), path)
    return path


#: The slowest files (each over ~40 s of one worker in `make test`), slowest first. Under
#: ``--dist loadfile`` a worker takes whole files in collection order, so a slow file collected
#: last (alphabetically: test_stored_results, test_serve) leaves the other worker idle at the end;
#: handing these out first lets the many small files fill in behind them (longest job first).
SLOW_FIRST = ("test_golden.py", "test_doc_examples.py", "test_damaged_artifacts.py",
              "test_faults.py", "test_model_classes.py", "test_stored_results.py",
              "test_robust.py", "test_learn_cli.py", "test_evaluate.py", "test_serve.py")


def pytest_collection_modifyitems(items):
    """Run the files of SLOW_FIRST first, in that order; the others keep theirs (a stable sort)."""
    rank = {name: i for i, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(SLOW_FIRST)))
