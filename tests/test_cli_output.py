"""What the CLI prints: help that speaks of the tool and cuts no sentence, output that is not
wrapped when it goes to a file or a pipe, quiet progress off a terminal, honest interruption
messages, and the package metadata."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import typer

from kbcli.cli import app
from kbcli.cli.app import first_sentence

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "data" / "golden"


def _all_commands(group, prefix=()):
    for name, cmd in group.commands.items():
        yield (*prefix, name), cmd
        if hasattr(cmd, "commands"):
            yield from _all_commands(cmd, (*prefix, name))


COMMANDS = [path for path, _ in _all_commands(typer.main.get_command(app))]


@pytest.mark.parametrize("path", [(), *COMMANDS], ids=lambda p: " ".join(p) or "kbcli")
def test_help_speaks_of_the_tool_and_cuts_no_sentence(runner, path):
    r = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "80"})
    assert r.exit_code == 0, r.output
    assert not re.search(r"\bissue\s*#?\d", r.output, re.I), r.output  # no tracker references
    cut = [ln for ln in r.output.splitlines()
           if re.search(r"[\w,;]\.\.\.$", ln.rstrip()) and "[ARGS]..." not in ln]
    assert not cut, cut  # nothing cut short (click ends a shortened text with "...")


def test_root_help_lists_every_stage(runner):
    r = runner.invoke(app, ["--help"])
    text = " ".join(r.output.split())
    for stage in ("keyboard", "learn", "perturb", "play", "detect", "adapt", "run", "evaluate",
                  "report", "inspect", "plot", "bench", "serve", "animate"):
        assert re.search(rf"\b{stage}\b", text.split("Options:")[0]), stage  # in the description
        assert re.search(rf"^\s+{stage}\s", r.output, re.M), stage  # and in the command list


def test_first_sentence_keeps_abbreviations():
    assert first_sentence("Draw the paper's Fig. 5 and more. Then this.") == (
        "Draw the paper's Fig. 5 and more.")
    assert first_sentence("One line only") == "One line only"


def test_output_is_not_wrapped_off_a_terminal(tmp_path):
    """A long line goes out whole to a pipe, whatever the width of the terminal it came from."""
    exe = os.path.join(os.path.dirname(sys.executable), "kbcli")
    out = tmp_path / "s.h5"
    long_name = tmp_path / ("a-rather-long-folder-name-" * 4)
    long_name.mkdir()
    out = long_name / "scene-with-a-long-name.h5"
    r = subprocess.run([exe, "perturb", "--keyboard", str(GOLDEN / "keyboard.h5"), "--dx", "3.25",
                        "--dy", "-4.5", "-o", str(out)], capture_output=True, text=True,
                       env={**os.environ, "COLUMNS": "40"})
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 1 and str(out) in lines[0] and "dy=-4.50" in lines[0], r.stdout
    assert r.stderr == ""  # no progress bar, no colour codes off a terminal
    assert "\x1b[" not in r.stdout


def test_inspect_json_gives_full_hashes(runner):
    import json

    d = json.loads(runner.invoke(app, ["inspect", "--json", str(GOLDEN / "history.h5")]).output)
    hashes = [d["sha256"], *(r["sha256"] for r in d["inputs"].values())]
    assert len(hashes) == 3 and all(re.fullmatch(r"[0-9a-f]{64}", h) for h in hashes)


def test_interrupted_evaluation_names_no_checkpoint_it_did_not_keep(runner, tmp_path, monkeypatch):
    """Ctrl-C before any experiment finished: no checkpoint folder, and the message says so."""
    from kbcli.cli import evaluate as cli_evaluate

    def interrupted(*a, **k):
        raise KeyboardInterrupt
        yield  # pragma: no cover

    monkeypatch.setattr(cli_evaluate, "execute", interrupted)
    out = tmp_path / "e.h5"
    r = runner.invoke(app, ["evaluate", "--model", str(GOLDEN / "model.h5"), "--config",
                            str(ROOT / "pipelines" / "golden.toml"), "--jobs", "2", "-o",
                            str(out)])
    assert r.exit_code == 130
    assert "nothing was kept" in r.stderr and ".ckpt" not in r.stderr, r.stderr
    assert os.listdir(tmp_path) == []


def test_pyproject_license_is_an_spdx_expression():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert meta["project"]["license"] == "MIT"  # PEP 639: a string, not a table
    req = [r for r in meta["build-system"]["requires"] if r.startswith("setuptools")]
    assert req and re.search(r">=\s*(\d+)", req[0]) and int(
        re.search(r">=\s*(\d+)", req[0]).group(1)) >= 77  # the first setuptools that reads it


def test_ctrl_c_with_a_failing_checkpoint_write_still_exits_130_in_one_line(capsys, tmp_path):
    """run_checkpointed: the flush on Ctrl-C fails (disk full): exit 130 and one line that counts
    only what is on disk, not a second error."""
    import typer

    from kbcli.cli.jobs import run_checkpointed
    from kbcli.errors import KbcliError
    from kbcli.io.checkpoint import Checkpoint

    class Full(Checkpoint):
        def flush(self):
            if 4 in self._pending:
                raise KbcliError("disk full")
            super().flush()

    ck = Full(tmp_path / "o.ckpt", {"x": 1}, every=2)

    def results():
        for i in range(5):
            yield i, {"v": float(i)}
        raise KeyboardInterrupt

    with pytest.raises(typer.Exit) as e:
        run_checkpointed(results(), 5, ck, kept=0, total=9, what="experiments")
    assert e.value.exit_code == 130
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "4 of 9 experiments kept" in lines[0], lines
    assert "writing the last 1 failed" in lines[0]
