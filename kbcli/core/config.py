"""Shared config validation: every config dataclass rejects keys it does not know, and checks
its whole numbers and lists of names the same way."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from kbcli.errors import ConfigError


def check_known(cls: type, d: Mapping, what: str) -> None:
    """Raise ``ConfigError`` naming the unknown keys of ``d`` and the valid fields of ``cls``.

    Parameters
    ----------
    cls : dataclass type
    d : mapping
        A TOML table or an artifact's config.
    what : str
        The config's name in the message ("keyboard", "detector", ...).
    """
    known = set(cls.__dataclass_fields__)
    unknown = sorted(set(d) - known)
    if unknown:
        raise ConfigError(
            f"unknown {what} option(s) {', '.join(unknown)}; valid: {', '.join(sorted(known))}"
        )


def check_whole(name: str, v: Any, low: int = 1) -> int:
    """``v`` as an int, or ``ConfigError`` unless it is a whole number (not a bool) >= ``low``."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
        raise ConfigError(f"{name} must be a whole number >= {low}, got {v!r}")
    return int(v)


def check_names(name: str, v: Any) -> tuple[str, ...]:
    """``v`` as a tuple, or ``ConfigError`` unless it is a non-empty list of distinct strings."""
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)) or len(v) == 0 \
            or not all(isinstance(s, str) for s in v):
        raise ConfigError(f"{name} must be a non-empty list of names, got {v!r}")
    if len(set(v)) != len(v):
        raise ConfigError(f"{name} lists a name twice: {list(v)!r}")
    return tuple(v)
