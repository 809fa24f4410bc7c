"""The CLI at the boundary: help, keyboard, inspect, plot, and the bad-input battery (issue 2)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from helpers import one_line_error as _one_line_error

from kbcli.cli import app


def test_help_lists_every_stage(runner):
    r = runner.invoke(app, ["--help"])
    assert r.exit_code == 0
    for stage in ("keyboard", "inspect", "plot", "bench"):
        assert stage in r.output


def test_keyboard_inspect_plot(runner, tmp_path):
    kb = tmp_path / "kb.h5"
    r = runner.invoke(app, ["keyboard", "--config", "pipelines/keyboard.toml", "--cols", "6", "-o", str(kb)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["inspect", "--json", str(kb)])
    d = json.loads(r.output)
    assert d["kind"] == "keyboard" and d["config"]["cols"] == 6 and d["config"]["rows"] == 4
    assert d["datasets"]["features"]["shape"] == [24, 2]
    r = runner.invoke(app, ["inspect", str(kb)])
    assert r.exit_code == 0 and "provenance" in r.output and "features" in r.output
    r = runner.invoke(app, ["plot", "keyboard", str(kb), "-o", str(tmp_path / "kb.png")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "kb.png").read_bytes()[:4] == b"\x89PNG"


def test_keyboard_is_deterministic(runner, tmp_path):
    for name in ("a.h5", "b.h5"):
        assert runner.invoke(app, ["keyboard", "-o", str(tmp_path / name)]).exit_code == 0
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()


@pytest.mark.parametrize(
    "args, fragments",
    [
        (["--rows", "0"], ["rows"]),
        (["--key-size", "-3"], ["key_size"]),
        (["--key-size", "nan"], ["key_size"]),
        (["--scale", "lydian"], ["scale", "diatonic"]),
        (["--base-note", "Q3"], ["note"]),
        (["--threshold", "0"], ["match_threshold"]),
        (["--config", "missing.toml"], ["missing.toml"]),
    ],
)
def test_bad_keyboard_config(runner, tmp_path, args, fragments):
    out = tmp_path / "kb.h5"
    r = runner.invoke(app, ["keyboard", "-o", str(out), *args])
    _one_line_error(r, *fragments)
    assert not out.exists() and os.listdir(tmp_path) == []


def test_unknown_key_in_toml(runner, tmp_path):
    cfg = tmp_path / "k.toml"
    cfg.write_text("[keyboard]\nrows = 2\nkeysize = 3\n")
    r = runner.invoke(app, ["keyboard", "--config", str(cfg), "-o", str(tmp_path / "kb.h5")])
    _one_line_error(r, "keysize")
    assert not (tmp_path / "kb.h5").exists()


def test_output_folder_missing(runner, tmp_path):
    r = runner.invoke(app, ["keyboard", "-o", str(tmp_path / "no" / "kb.h5")])
    _one_line_error(r, "does not exist")


def test_inspect_bad_files(runner, tmp_path, kb_path):
    _one_line_error(runner.invoke(app, ["inspect", str(tmp_path / "nope.h5")]), "nope.h5", "no such file")
    (tmp_path / "t.h5").write_text("not hdf5")
    _one_line_error(runner.invoke(app, ["inspect", str(tmp_path / "t.h5")]), "t.h5", "not an HDF5")
    data = kb_path.read_bytes()
    (tmp_path / "cut.h5").write_bytes(data[: len(data) // 2])
    _one_line_error(runner.invoke(app, ["inspect", str(tmp_path / "cut.h5")]), "cut.h5", "truncated")


def test_plot_wrong_kind(runner, tmp_path, kb_path):
    from kbcli.io.artifact import write_artifact
    from kbcli.stages.artifact import Artifact

    write_artifact(Artifact(kind="scene", config={}), tmp_path / "s.h5")
    r = runner.invoke(app, ["plot", "keyboard", str(tmp_path / "s.h5"), "-o", str(tmp_path / "k.png")])
    _one_line_error(r, "s.h5", "scene", "expected keyboard")
    assert not (tmp_path / "k.png").exists()


def test_usage_error_exits_2(runner):
    r = runner.invoke(app, ["keyboard", "--rows", "many", "-o", "x.h5"])
    assert r.exit_code == 2


def test_console_script_runs_and_errors_on_stderr(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "kbcli")
    ok = subprocess.run([exe, "--version"], capture_output=True, text=True)
    assert ok.returncode == 0 and "kbcli" in ok.stdout
    bad = subprocess.run([exe, "inspect", str(tmp_path / "x.h5")], capture_output=True, text=True)
    assert bad.returncode == 1 and bad.stdout == ""
    assert bad.stderr.strip().count("\n") == 0 and "no such file" in bad.stderr


def test_default_inputs_are_found_in_the_checkout_from_any_folder(tmp_path, monkeypatch):
    """quality's data/keyboard.h5, evaluate's pipelines/paper.toml...: the current folder's if it
    has one, else the kbcli checkout's; a one-line error naming the option otherwise."""
    from pathlib import Path

    from kbcli.errors import KbcliError
    from kbcli.io.paths import checkout_file

    root = Path(__file__).resolve().parent.parent
    monkeypatch.chdir(tmp_path)
    assert checkout_file("pipelines/paper.toml", "--config") == root / "pipelines" / "paper.toml"
    (tmp_path / "pipelines").mkdir()
    (tmp_path / "pipelines" / "paper.toml").write_text("[evaluate]\n")
    assert checkout_file("pipelines/paper.toml", "--config") == Path("pipelines/paper.toml")
    with pytest.raises(KbcliError, match="pass --keyboard FILE"):
        checkout_file("data/no-such.h5", "--keyboard")


def test_the_console_script_loads_the_cli_under_the_signal_guard():
    """`kbcli` (the installed script) starts where `python -m kbcli` does: a Ctrl-C or SIGTERM
    while the modules load is one line and 130 / 143, not a traceback (issue 29)."""
    import importlib
    import tomllib
    from pathlib import Path

    import kbcli.__main__ as entry

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    module, _, name = project["project"]["scripts"]["kbcli"].partition(":")
    assert getattr(importlib.import_module(module), name) is entry.run
