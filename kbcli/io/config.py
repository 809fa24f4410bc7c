"""Read experiment and keyboard configs from TOML files (in ``pipelines/``)."""

from __future__ import annotations

import re
import stat
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from kbcli.errors import ConfigError
from kbcli.io.atomic import describe_os_error

C = TypeVar("C")


def load_config(cls: type[C], path: str | Path, table: str | None = None) -> C:
    """The ``[table]`` of a TOML file read into the config class ``cls``.

    Parameters
    ----------
    cls : type
        A :class:`kbcli.core.config.Config` subclass (or any class with ``from_dict``).
    table : str, optional
        The top-level table; default ``cls.what``.

    Raises
    ------
    ConfigError
        As :func:`load_toml`, or a bad value: the one line of ``cls`` (table, key, what is
        allowed) prefixed with the file's path.
    """
    name = table if table is not None else cls.what
    values = load_toml(path, name)
    try:
        return cls.from_dict(values)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def with_file(cls: type[C], table: Mapping[str, Any], flags: Mapping[str, Any],
              path: str | Path | None) -> C:
    """``cls`` from a config file's table with the flags given on top; a bad value that came from
    the file (not overridden by a flag) is refused naming the file, as :func:`load_config` does.

    Raises
    ------
    ConfigError
        One line (table, key, what is allowed), prefixed with ``path`` when the key is the file's.
    """
    given = {k: v for k, v in flags.items() if v is not None}
    try:
        return cls.from_dict({**table, **given})
    except ConfigError as exc:
        words = set(re.findall(r"[A-Za-z_]\w*", str(exc).split(" must ")[0].split(" has ")[0]))
        if path is not None and any(k in words and k not in given for k in table):
            err = ConfigError(f"{path}: {exc}")
            if hasattr(exc, "option"):  # a part's refusal: the command names where it came from
                err.option, err.reason = exc.option, exc.reason
            raise err from None
        raise


def load_arm(value: str | None):
    """The arm of ``--arm VALUE``: a preset name (``ideal``, ``servo``, ``realistic``) or a TOML
    file with an ``[arm]`` table (``preset = NAME`` plus fields to override). None: ``ideal``.

    Raises
    ------
    ConfigError
        An unknown preset, a missing file or an invalid table.
    """
    from kbcli.sim.arms import arm_config

    path = arm_file(value)
    return arm_config(value if path is None else load_toml(path, "arm"))


def arm_file(value: str | None) -> Path | None:
    """The TOML file ``--arm VALUE`` reads (an input, never to be overwritten), or None for a
    preset name."""
    from kbcli.sim.arms import PRESETS

    if value is None or value in PRESETS or not value.endswith(".toml"):
        return None
    return Path(value)


#: Largest config file read, bytes (a config is a few kB; a larger file is not one).
MAX_CONFIG_BYTES = 1 << 20


def _check_config_file(path: Path) -> None:
    """A regular file of at most :data:`MAX_CONFIG_BYTES` (never a folder, a FIFO that would block
    the read, or a device); ConfigError naming what it is otherwise."""
    try:
        st = path.stat()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the config file ({describe_os_error(exc)})") \
            from None
    if stat.S_ISDIR(st.st_mode):
        raise ConfigError(f"{path}: is a folder, expected a TOML config file")
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" if \
            stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a regular file"
        raise ConfigError(f"{path}: is {kind}, expected a TOML config file")
    if st.st_size > MAX_CONFIG_BYTES:
        raise ConfigError(f"{path}: {st.st_size:,} bytes, more than a config file may hold "
                          f"({MAX_CONFIG_BYTES:,})")


def load_toml(path: str | Path, table: str | None = None) -> dict[str, Any]:
    """Parse a TOML file, optionally returning one top-level table.

    Raises
    ------
    ConfigError
        Missing file, invalid TOML, or a missing table.
    """
    path = Path(path)
    _check_config_file(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the config file ({describe_os_error(exc)})") \
            from None
    return doc if table is None else _table(doc, path, table)


def _table(doc: dict[str, Any], path: Path, table: str) -> dict[str, Any]:
    if table not in doc:
        raise ConfigError(f"{path}: no [{table}] table")
    if not isinstance(doc[table], dict):
        raise ConfigError(f"{path}: {table} must be a table")
    return doc[table]


def load_stage_table(path: str | Path, table: str) -> dict[str, Any]:
    """A stage's ``[table]`` of a TOML file, with a top-level ``[arm]`` table beside it read as
    the stage's arm (the table ``--arm FILE`` reads), so one file can hold both.

    Raises
    ------
    ConfigError
        As :func:`load_toml`; or both ``[arm]`` and ``[table.arm]``, or an ``arm`` that is not a
        table.
    """
    doc = load_toml(path)
    values = dict(_table(doc, Path(path), table))
    if "arm" in doc:
        _table(doc, Path(path), "arm")
        if "arm" in values:
            raise ConfigError(f"{path}: both [arm] and [{table}.arm]: keep one")
        values["arm"] = doc["arm"]
    return values

