"""A user's input files are sacred: no command writes over one of its inputs.

Every command that writes is run with each of its outputs (artifact, figure, WAV, report folder or a
file it writes there, checkpoint folder) pointing at each of its inputs (artifacts, TOML configs):
under the same name, through a symlink and through a hard link. Each is refused before any work,
with one line and exit 1, and leaves every file as it was. A further test checks that every
command of the CLI is covered here.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
import typer

from kbcli.cli import app

GOLDEN = Path(__file__).resolve().parent.parent / "data" / "golden"
PIPELINES = Path(__file__).resolve().parent.parent / "pipelines"

#: command -> (argv with {role} placeholders, {input role: placeholder}, {output: placeholder}).
#: An output placeholder names the file it writes; inputs are copies of the golden set.
CASES: dict[str, tuple[list[str], list[str], list[str]]] = {
    "keyboard": (["keyboard", "--config", "{toml_kb}", "-o", "{out}"], ["toml_kb"], ["out"]),
    "plot keyboard": (["plot", "keyboard", "{keyboard}", "-o", "{fig}"], ["keyboard"], ["fig"]),
    "learn": (["learn", "--keyboard", "{keyboard}", "--budget", "20", "--arm", "{toml_arm}",
               "-o", "{out}"], ["keyboard", "toml_arm"], ["out"]),
    "plot model": (["plot", "model", "{model}", "-o", "{fig}"], ["model"], ["fig"]),
    "perturb": (["perturb", "--keyboard", "{keyboard}", "--dx", "3", "-o", "{out}"],
                ["keyboard"], ["out"]),
    "play": (["play", "--model", "{model}", "--scene", "{scene}", "--steps", "4", "--arm",
              "{toml_arm}", "-o", "{out}", "--wav", "{wav}"], ["model", "scene", "toml_arm"],
             ["out", "wav"]),
    "plot play": (["plot", "play", "{history}", "--detection", "{detection}", "-o", "{fig}"],
                  ["history", "detection"], ["fig"]),
    "detect": (["detect", "{history}", "-o", "{out}"], ["history"], ["out"]),
    "adapt": (["adapt", "--model", "{model}", "--scene", "{scene}", "--config", "{toml_golden}",
               "--arm", "{toml_arm}", "-o", "{out}"], ["model", "scene", "toml_golden", "toml_arm"],
              ["out"]),
    "plot adapt": (["plot", "adapt", "{run}", "-o", "{fig}"], ["run"], ["fig"]),
    "run": (["run", "--model", "{model}", "--scene", "{scene}", "--arm", "{toml_arm}", "-o",
             "{out}"], ["model", "scene", "toml_arm"], ["out"]),
    "plot run": (["plot", "run", "{closed_loop}", "-o", "{fig}"], ["closed_loop"], ["fig"]),
    "evaluate": (["evaluate", "--model", "{model}", "--config", "{toml_golden}", "--arm",
                  "{toml_arm}", "-o", "{out}"], ["model", "toml_golden", "toml_arm"], ["out"]),
    "report": (["report", "{evaluation}", "-o", "{folder}"], ["evaluation"], ["folder"]),
    "animate": (["animate", "{run}", "-o", "{gif}"], ["run"], ["gif"]),
    "quality": (["quality", "--config", "{toml_quality}", "--keyboard", "{keyboard}", "-o",
                 "{out}"], ["keyboard", "toml_quality"], ["out"]),
    "serve": (["serve", "--model", "{model}", "--config", "{toml_serve}", "-o", "{out}",
               "--socket", "{sock}"], ["model", "toml_serve"], ["out", "sock"]),
}
#: commands that write nothing
READ_ONLY = {"inspect"}


def _inputs(tmp: Path) -> dict[str, Path]:
    files = {k: tmp / f"{k}.h5" for k in ("keyboard", "model", "scene", "history", "detection",
                                          "run", "closed_loop", "evaluation")}
    for k, p in files.items():
        shutil.copy(GOLDEN / f"{k}.h5", p)
    files["toml_kb"] = tmp / "keyboard.toml"
    shutil.copy(PIPELINES / "keyboard.toml", files["toml_kb"])
    files["toml_golden"] = tmp / "golden.toml"
    shutil.copy(PIPELINES / "golden.toml", files["toml_golden"])
    files["toml_quality"] = tmp / "quality.toml"
    files["toml_quality"].write_text(
        '[quality]\nbudgets = [20]\nexplorations = ["random"]\nmode = "ideal"\narm = "ideal"\n'
        'experiments = 1\nmax_steps = 2\n')
    files["toml_arm"] = tmp / "arm.toml"
    files["toml_arm"].write_text('[arm]\npreset = "servo"\n')
    files["toml_serve"] = tmp / "serve.toml"
    files["toml_serve"].write_text("[serve]\nmax_steps = 3\n")
    return files


def _snapshot(tmp: Path) -> dict[str, bytes]:
    return {str(p.relative_to(tmp)): p.read_bytes() for p in sorted(tmp.rglob("*")) if p.is_file()
            and not p.is_symlink()}


def _defaults(tmp: Path) -> dict[str, str]:
    return {"out": str(tmp / "new.h5"), "fig": str(tmp / "new.png"), "wav": str(tmp / "new.wav"),
            "folder": str(tmp / "newreport"), "gif": str(tmp / "new.gif"),
            "sock": str(tmp / "new.sock")}


def _cases():
    for cmd, (_, ins, outs) in CASES.items():
        for o in outs:
            for i in ins:
                for how in ("same", "symlink", "hardlink"):
                    yield pytest.param(cmd, o, i, how, id=f"{cmd}:{o}={i}:{how}")


def _one_line_refusal(r, *fragments: str) -> str:
    assert r.exit_code == 1, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), r.output
    assert "Traceback" not in r.output
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("cmd, out_role, in_role, how", list(_cases()))
def test_output_that_is_an_input_is_refused(runner, tmp_path, cmd, out_role, in_role, how):
    files = _inputs(tmp_path)
    argv, _, _ = CASES[cmd]
    values = {**_defaults(tmp_path), **{k: str(v) for k, v in files.items()}}
    target = files[in_role]
    if how == "same":
        alias = target
    elif how == "symlink":
        alias = tmp_path / f"link-{out_role}{target.suffix}"
        alias.symlink_to(target)
    else:
        alias = tmp_path / f"hard-{out_role}{target.suffix}"
        os.link(target, alias)
    values[out_role] = str(alias)
    before = _snapshot(tmp_path)
    r = runner.invoke(app, [a.format(**values) for a in argv])
    _one_line_refusal(r, "input", target.name)
    assert _snapshot(tmp_path) == before  # nothing written, nothing changed
    assert not (tmp_path / "newreport").exists()


def test_report_files_inside_the_folder_are_checked(runner, tmp_path):
    """The report writes README.md and figures in its folder: an input of that name is refused,
    an input elsewhere in the folder is fine."""
    FEW = ["--replicates", "2"]  # bootstrap replicates of a differing claim: 2, not 100 (faster)
    folder = tmp_path / "rep"
    folder.mkdir()
    for name in ("README.md", "fig6_entropy.png"):
        src = folder / name
        shutil.copy(GOLDEN / "evaluation.h5", src)
        before = src.read_bytes()
        r = runner.invoke(app, ["report", str(src), "-o", str(folder), *FEW])
        _one_line_refusal(r, "input", name)
        assert src.read_bytes() == before and sorted(os.listdir(folder)) == [name]
        src.unlink()
    shutil.copy(GOLDEN / "evaluation.h5", folder / "eval.h5")
    r = runner.invoke(app, ["report", str(folder / "eval.h5"), "-o", str(folder), *FEW])
    assert r.exit_code == 0, r.output
    assert (folder / "README.md").is_file() and (folder / "eval.h5").read_bytes() == (
        GOLDEN / "evaluation.h5").read_bytes()


def test_checkpoint_folder_holding_an_input_is_refused(runner, tmp_path):
    """evaluate deletes OUTPUT.ckpt/ when done: an input inside it is refused before any work."""
    ckpt = tmp_path / "e.h5.ckpt"
    ckpt.mkdir()
    shutil.copy(GOLDEN / "model.h5", ckpt / "model.h5")
    r = runner.invoke(app, ["evaluate", "--model", str(ckpt / "model.h5"), "--config",
                            str(PIPELINES / "golden.toml"), "-o", str(tmp_path / "e.h5")])
    _one_line_refusal(r, "checkpoint", "delete")
    assert (ckpt / "model.h5").is_file() and not (tmp_path / "e.h5").exists()


def test_two_outputs_of_one_command_must_differ(runner, tmp_path):
    files = _inputs(tmp_path)
    out = tmp_path / "h.h5"
    r = runner.invoke(app, ["play", "--model", str(files["model"]), "--steps", "3", "-o", str(out),
                            "--wav", str(out)])
    _one_line_refusal(r, "--wav", "same file")
    assert not out.exists()


def _commands(group, prefix: str = "") -> set[str]:
    names = set()
    for name, cmd in group.commands.items():
        if hasattr(cmd, "commands"):  # a group of commands
            if name != "bench":  # benchmarks write nothing
                names |= _commands(cmd, f"{prefix}{name} ")
        else:
            names.add(f"{prefix}{name}")
    return names


def test_every_command_is_covered():
    """A new command that writes files must be added to CASES (or READ_ONLY if it writes none)."""
    group = typer.main.get_command(app)
    missing = _commands(group) - set(CASES) - READ_ONLY
    assert not missing, (f"add {sorted(missing)} to CASES in tests/test_inputs_sacred.py: every "
                         f"command's outputs must be checked against its inputs")
