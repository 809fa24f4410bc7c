"""Read experiment and keyboard configs from TOML files (in ``pipelines/``)."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from kbcli.errors import ConfigError


def load_arm(value: str | None):
    """The arm of ``--arm VALUE``: a preset name (``ideal``, ``servo``, ``realistic``) or a TOML
    file with an ``[arm]`` table (``preset = NAME`` plus fields to override). None: ``ideal``.

    Raises
    ------
    ConfigError
        An unknown preset, a missing file or an invalid table.
    """
    from kbcli.sim.arms import PRESETS, arm_config

    if value is None:
        return arm_config(None)
    if value in PRESETS or not value.endswith(".toml"):
        return arm_config(value)
    return arm_config(load_toml(value, "arm"))


def load_toml(path: str | Path, table: str | None = None) -> dict[str, Any]:
    """Parse a TOML file, optionally returning one top-level table.

    Raises
    ------
    ConfigError
        Missing file, invalid TOML, or a missing table.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such config file")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None
    if table is None:
        return doc
    if table not in doc:
        raise ConfigError(f"{path}: no [{table}] table")
    if not isinstance(doc[table], dict):
        raise ConfigError(f"{path}: {table} must be a table")
    return doc[table]
