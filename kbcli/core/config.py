"""Shared config validation: every config dataclass rejects keys it does not know."""

from __future__ import annotations

from collections.abc import Mapping

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
