"""Shared fixtures: a keyboard artifact on disk and a CLI runner."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import write_artifact
from kbcli.stages import keyboard as keyboard_stage


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


@pytest.fixture
def kb_path(tmp_path):
    """A default keyboard artifact written to a temporary folder."""
    path = tmp_path / "kb.h5"
    write_artifact(keyboard_stage.run(KeyboardConfig()), path)
    return path
