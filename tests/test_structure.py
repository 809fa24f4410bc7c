"""The package's shape (issue 41's limits): small modules and functions, imports that flow one way
(core <- sim <- stages <- io <- viz, bench <- api <- cli), no import cycle, and every function
at most ruff's McCabe complexity 10. ``python tools/structure.py`` prints the same findings."""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("structure", ROOT / "tools" / "structure.py")
structure = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(structure)


def test_no_module_over_400_lines():
    assert structure.long_modules(400) == []


def test_no_function_over_60_lines():
    assert structure.long_functions(60) == []


def test_no_import_cycle():
    assert structure.cycles(structure.graph()) == []


def test_no_import_up_the_layers():
    assert structure.upward(structure.graph()) == []


def test_the_checks_see_a_cycle_and_an_upward_import():
    """The graph walker itself: a made-up package with a cycle and an upward import."""
    g = {"kbcli.core.a": {"kbcli.core.b"}, "kbcli.core.b": {"kbcli.core.a"},
         "kbcli.stages.s": {"kbcli.io.x"}, "kbcli.io.x": set()}
    assert structure.cycles(g) == [["kbcli.core.a", "kbcli.core.b"]]
    assert structure.upward(g) == [("kbcli.stages.s", "kbcli.io.x")]


def test_only_the_simulator_imports_pymunk():
    users = [m for m, p in structure.modules().items()
             if "pymunk" in p.read_text() and "import pymunk" in p.read_text()]
    assert users and all(m.startswith("kbcli.sim") for m in users), users


@pytest.mark.skipif(shutil.which("ruff") is None and not (Path(sys.executable).parent / "ruff").exists(),
                    reason="ruff is in the dev extra (make test installs it)")
def test_mccabe_complexity_at_most_10():
    ruff = Path(sys.executable).parent / "ruff"
    cmd = [str(ruff) if ruff.exists() else "ruff", "check", str(ROOT / "kbcli"), "--select", "C901",
           "--config", "lint.mccabe.max-complexity=10", "--output-format", "concise"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_no_switch_on_a_part_s_name():
    """Code asks a registered part what it is or does (its traits, its options), never compares a
    value with its name (``x == "kde"``, ``s in ("active", "paper-active")``): at most 3 such
    comparisons in kbcli/ (issue 41; 35 before it, sim modes included)."""
    found = structure.name_switches(structure.part_names())
    assert len(found) <= 3, found


def test_the_name_switch_scan_sees_a_switch(tmp_path, monkeypatch):
    """The scanner itself: a made-up module that compares with a part's name, and one that reads an
    option whose values only share a word with a part."""
    pkg = tmp_path / "kbcli"
    pkg.mkdir()
    (pkg / "a.py").write_text('def f(cfg):\n    return cfg.posterior == "kde" or s in ("x", "active")\n')
    (pkg / "b.py").write_text('def g(cfg, r):\n    return cfg.ml_ties == "random" or r.get("ml_ties") == "random"\n')
    monkeypatch.setattr(structure, "ROOT", pkg)
    found = structure.name_switches({"kde", "active", "random"})
    assert [(m, line) for m, line, _ in found] == [("kbcli.a", 2), ("kbcli.a", 2)]
