"""``kbcli.io.config.load_config``: a TOML table into a pydantic config, errors prefixed with the
file's path (one line naming table, key and what is allowed)."""

from __future__ import annotations

from typing import ClassVar

import pytest

from kbcli.core.config import Config, Count, Positive
from kbcli.errors import ConfigError
from kbcli.io.config import load_config


class Toy(Config):
    what: ClassVar[str] = "toy"
    steps: Count = 3
    scale: Positive = 1.0


def _file(tmp_path, text: str):
    path = tmp_path / "toy.toml"
    path.write_text(text)
    return path


def test_reads_the_table_into_the_config(tmp_path):
    path = _file(tmp_path, "[toy]\nsteps = 5\n[other]\nx = 1\n")
    cfg = load_config(Toy, path)
    assert isinstance(cfg, Toy) and cfg.steps == 5 and cfg.scale == 1.0
    assert load_config(Toy, _file(tmp_path, "[alt]\nscale = 2.5\n"), "alt").scale == 2.5


def test_a_bad_value_names_the_file_table_and_key_on_one_line(tmp_path):
    path = _file(tmp_path, "[toy]\nsteps = 0\n")
    with pytest.raises(ConfigError) as err:
        load_config(Toy, path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: toy.steps") and "\n" not in msg


def test_an_unknown_key_and_a_missing_table_name_the_file(tmp_path):
    with pytest.raises(ConfigError, match=r"toy\.toml: .*stpes"):
        load_config(Toy, _file(tmp_path, "[toy]\nstpes = 5\n"))
    with pytest.raises(ConfigError, match=r"toy\.toml: no \[toy\] table"):
        load_config(Toy, _file(tmp_path, "[other]\nx = 1\n"))
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(Toy, tmp_path / "missing.toml")
