"""The options several commands share (kbcli/cli/options.py): one declaration, the registered
names in every command's help, an unknown name refused in one line that lists the valid ones."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import one_line_error

from kbcli.cli import app
from kbcli.cli import options as opts
from kbcli.cli import paper_flags as paper
from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.io.artifact import write_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact
from kbcli.stages.perturb import PerturbConfig
from kbcli.stages.perturb import run as perturb_run

#: (option, kind of part) -> the commands whose help of the option lists every registered name.
_LISTED_IN = {
    ("--posterior", "posterior"): ["adapt", "serve", "run"],
    ("--estimator", "estimator"): ["adapt", "serve", "run"],
    ("--family", "family"): ["adapt", "serve", "run", "perturb"],
    ("--strategy", "strategy"): ["adapt", "serve", "run", "bench adapt", "bench robust"],
    ("--strategy", "exploration"): ["learn", "bench learn"],
    ("--mode", "mode"): ["adapt", "learn", "play", "run", "evaluate", "bench learn",
                         "bench evaluate", "bench reliability"],
    ("--arm", "arm"): ["adapt", "learn", "play", "run", "evaluate", "bench reliability"],
    ("--layout", "layout"): ["keyboard", "bench adapt", "bench learn", "bench layouts"],
    ("--model-class", "model class"): ["learn", "bench learn"],
    ("--detector", "detector"): ["detect", "run"],
}
#: (command, option, kind of part), one a row of :data:`_LISTED_IN`.
LISTED = [(tuple(command.split()), option, kind)
          for (option, kind), commands in _LISTED_IN.items() for command in commands]


def _option_help(runner, command: tuple[str, ...], option: str) -> str:
    """The help text of ``option`` in ``kbcli COMMAND --help``, on one line."""
    r = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    text, keep = [], False
    for line in r.output.splitlines():
        stripped = line.strip()
        if stripped.startswith("-"):  # an option's first line
            keep = option in stripped.split("  ")[0].replace(",", " ").split()
        if keep:
            text.append(stripped)
    assert text, f"{option} not in kbcli {' '.join(command)} --help"
    joined = " ".join(" ".join(text).split())
    return re.sub(r"(\w)- (\w)", r"\1-\2", joined)  # Click's wrap breaks after a hyphen


@pytest.mark.parametrize(("command", "option", "kind"), LISTED,
                         ids=[f"{' '.join(c)} {o}" for c, o, _ in LISTED])
def test_shared_option_help_lists_every_registered_name(runner, command, option, kind):
    text = _option_help(runner, command, option)
    names = opts.names_of(kind)
    assert names
    for name in names:
        assert name in text, (name, text)


def test_names_come_from_the_registries():
    assert opts.names_of("posterior") == POSTERIORS.names()
    assert opts.names_of("estimator") == ESTIMATORS.names()
    assert opts.names_of("family") == FAMILIES.names()
    for kind in ("layout", "model class", "strategy", "exploration", "detector", "arm", "mode"):
        assert opts.names_of(kind), kind


def test_a_name_registered_later_appears_in_the_source():
    with POSTERIORS.temporarily("toy", object(), summary="a toy posterior"):
        assert "toy" in opts.names_of("posterior")
        assert "toy: a toy posterior" in opts.describe_of("posterior")
    assert "toy" not in opts.names_of("posterior")


def test_one_of_reads_like_a_sentence():
    assert opts.one_of("family") == "translation or rigid"
    assert opts.one_of("mode", "exact") == "ideal, dynamics or exact"


@pytest.fixture
def files(tmp_path):
    kb_art = keyboard_stage.run(KeyboardConfig())
    write_artifact(exact_artifact(kb_art), tmp_path / "model.h5")
    write_artifact(perturb_run(PerturbConfig(params=(8.3, -5.6)), kb_art,
                               rng=np.random.default_rng(0)), tmp_path / "scene.h5")
    return tmp_path


@pytest.mark.parametrize("command", ["adapt", "run"])
def test_an_unknown_posterior_is_one_line_listing_the_valid_ones(runner, files, command):
    r = runner.invoke(app, [command, "--model", str(files / "model.h5"), "--scene",
                            str(files / "scene.h5"), "-o", str(files / "out.h5"),
                            "--posterior", "gaussian"])
    one_line_error(r, "gaussian", *POSTERIORS.names())
    assert not (files / "out.h5").exists()


def test_an_unknown_estimator_is_one_line_listing_the_valid_ones(runner, files):
    r = runner.invoke(app, ["adapt", "--model", str(files / "model.h5"), "--scene",
                            str(files / "scene.h5"), "-o", str(files / "out.h5"),
                            "--estimator", "median"])
    one_line_error(r, "median", *ESTIMATORS.names())


def test_estimator_flag_reaches_the_run(runner, files):
    from kbcli.io.artifact import read_artifact

    r = runner.invoke(app, ["adapt", "--model", str(files / "model.h5"), "--scene",
                            str(files / "scene.h5"), "-o", str(files / "out.h5"), "-T", "3",
                            "--prior-halfwidth", "15", "--estimator", "ml"])
    assert r.exit_code == 0, r.output
    cfg = read_artifact(files / "out.h5", "run").config
    assert cfg["adapt"]["robot"]["estimator"] == "ml"


def test_every_paper_flag_is_declared_once_and_reaches_adapt_and_run():
    """paper.with_paper_flags adds each of paper.PAPER_FLAGS to a command, typed as declared."""
    import typer

    assert set(paper._PAPER_TYPES) == set(paper.PAPER_FLAGS)
    for name in ("adapt", "run"):
        cmd = typer.main.get_command(app).commands[name]
        flags = {o for p in cmd.params for o in p.opts}
        missing = {"--" + f.replace("_", "-") for f in paper.PAPER_FLAGS} - flags
        assert not missing, (name, missing)


def test_with_paper_flags_hands_the_flags_over_as_one_dict():
    seen = {}

    @paper.with_paper_flags
    def cmd(a: int = 1, paper_flags: dict | None = None, b: int = 2):
        seen.update(paper_flags, a=a, b=b)

    import inspect

    names = list(inspect.signature(cmd).parameters)
    assert names[0] == "a" and names[-1] == "b" and "paper_flags" not in names
    assert names[1:-1] == list(paper._PAPER_TYPES)
    cmd(a=3, b=4, kde_floor=0.5)
    assert seen["kde_floor"] == 0.5 and seen["candidates"] is None and (seen["a"], seen["b"]) == (3, 4)
