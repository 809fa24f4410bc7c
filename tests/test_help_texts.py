"""Every --help says what each option means, and shows its default one way: Typer's
``[default: ...]`` (``[default: (...)]`` for a default that a config may fill, or that is described
rather than a value), never a hand-written ``[default X]`` or ``(default X)``."""

from __future__ import annotations

import re

import click
import pytest
import typer
from typer.testing import CliRunner

from kbcli.cli import app

#: A default written by hand in an option's help, in any form but Click's own.
HAND_WRITTEN = re.compile(r"(?i)\[[^\]]*\bdefault\b|\(default\b|\bdefault:")


def _commands(cmd, path=("kbcli",)):
    subs = getattr(cmd, "commands", None)
    if subs:
        for name, sub in subs.items():
            yield from _commands(sub, (*path, name))
    else:
        yield " ".join(path), cmd


COMMANDS = list(_commands(typer.main.get_command(app)))
OPTIONS = [(path, cmd, p) for path, cmd in COMMANDS for p in cmd.params
           if p.param_type_name == "option" and p.name != "help"]


def _record(cmd, param) -> str:
    return param.get_help_record(click.Context(cmd, info_name=cmd.name))[1]


def test_the_walk_finds_every_command():
    assert len(COMMANDS) > 20 and len(OPTIONS) > 150


@pytest.mark.parametrize(("path", "cmd"), COMMANDS, ids=[p for p, _ in COMMANDS])
def test_every_option_has_help_and_shows_its_default_one_way(path, cmd):
    for p in (p for p in cmd.params if p.param_type_name == "option" and p.name != "help"):
        name = f"{path} {p.opts[0]}"
        assert (p.help or "").strip(), f"{name}: no help"
        assert not HAND_WRITTEN.search(p.help), f"{name}: a hand-written default in {p.help!r}"
        shown = _record(cmd, p)
        if isinstance(p.show_default, str) and p.show_default:  # (Typer's form of a described one)
            assert f"[default: ({p.show_default})" in shown, name
        off_flag = p.is_flag and not p.secondary_opts and not p.default
        if p.default is not None and not off_flag and not p.required:
            assert "[default: " in shown, f"{name}: its default {p.default!r} is not shown"


def _default_of(command: str, option: str) -> str:
    r = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "300"})
    text = " ".join(r.output.split())
    m = re.search(re.escape(option) + r"\b.*?\[default: \(?([^\]]+?)\)?\]", text)
    assert m, f"{command} {option}"
    return m.group(1)


def test_adapt_and_serve_say_why_their_stopping_defaults_differ():
    """adapt measures (every touch, the rule's step recorded); serve drives a robot (it stops)."""
    assert _default_of("adapt", "--stop / --no-stop") == "--no-stop"
    assert _default_of("serve", "--stop / --no-stop") == "--stop"
    cmd = dict(COMMANDS)
    for path, why in (("kbcli adapt", "measures"), ("kbcli serve", "no more than it needs")):
        (stop,) = [p for p in cmd[path].params if p.name == "stop"]
        assert why in stop.help, path


def test_an_option_whose_value_a_config_fills_shows_the_default_it_takes():
    assert _default_of("adapt", "--strategy") == "infogain"
    assert _default_of("adapt", "--resolution") == "0.5"
    assert _default_of("keyboard", "--layout") == "grid"
    assert _default_of("evaluate", "--experiments") == "the config's"


def test_a_default_taken_from_the_input_or_other_options_says_where_from():
    """Shown as Typer's described default, ``[default: (...)]``, never left blank."""
    assert _default_of("adapt", "--family") == "the scene's family"
    perturb = dict(COMMANDS)["kbcli perturb"]
    shown = {p.opts[0]: _record(perturb, p) for p in perturb.params if p.param_type_name == "option"}
    for name, others in (("--dx", "--dy or --angle"), ("--dy", "--dx or --angle"),
                         ("--angle", "--dx or --dy")):
        assert f"[default: (0 when {others} is given)]" in " ".join(shown[name].split()), name


def test_the_same_option_means_the_same_in_every_command():
    """``--reach-noise`` said "landing scatter, px" in one command and "(standard deviation)" in
    another: an option shared by several commands now has one help text."""
    helps = {}
    for path, cmd in COMMANDS:
        for p in cmd.params:
            if p.param_type_name == "option" and p.opts[0] == "--reach-noise":
                helps[path] = " ".join(p.help.split())
    assert {"kbcli adapt", "kbcli run", "kbcli learn", "kbcli play"} <= set(helps)
    assert len(set(helps.values())) == 1, helps
