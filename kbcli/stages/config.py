"""The config base of the stages' tables: :class:`kbcli.core.config.Config` whose validators may
raise a whole sentence.

Fields are checked by their declared constraints (one line naming the table, the key and the
accepted range, :func:`kbcli.core.config.describe_error`); checks across fields or tables raise
:class:`~kbcli.errors.ConfigError`, whose message :class:`StageConfig` passes through as it is.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel, ValidationError

from kbcli.core.config import Config, describe_error
from kbcli.errors import ConfigError

#: Upper bounds of the counts a user types into a stage's table or flags (issue 29: a typo such as
#: 1e9 is refused in one line before any work, never run at full CPU until killed).
#: Reaches of one learning run (the paper's models take 800; the sweep's largest 1600).
MAX_BUDGET = 20_000
#: Touches of one adaptation.
MAX_ADAPT_STEPS = 10_000
#: Experiments per cell of an evaluation or a sweep.
MAX_EXPERIMENTS = 10_000
#: Notes replayed after an adaptation.
MAX_REPLAY_NOTES = 100_000
#: Experiments of one evaluation or sweep in all (the paper's protocol at 50 per cell: 8,800).
MAX_TOTAL_EXPERIMENTS = 1_000_000


def check_total(total: int, what: str) -> None:
    """ConfigError when a run would take more than :data:`MAX_TOTAL_EXPERIMENTS` experiments
    (checked before any work: a cost estimate, issue 29)."""
    if total > MAX_TOTAL_EXPERIMENTS:
        raise ConfigError(f"{what}: {total:,} experiments in all, more than "
                          f"{MAX_TOTAL_EXPERIMENTS:,}: lower --experiments or the config's cells")


def message(exc: ValidationError, what: str, fields: tuple[str, ...] = ()) -> str:
    """One line for the first error of ``exc``: a validator's own :class:`ConfigError` as it is,
    else :func:`kbcli.core.config.describe_error`'s (``what``: the table's name)."""
    first = exc.errors(include_url=False)[0]
    cause = (first.get("ctx") or {}).get("error")
    if isinstance(cause, ConfigError):
        return str(cause)
    return describe_error(exc, what, fields)


class StageConfig(Config):
    """A stage table's config (see the module docstring): frozen, unknown keys refused, errors as
    one-line :class:`ConfigError` (a validator's own sentence kept as it is)."""

    def __init__(self, /, **data: Any) -> None:
        try:
            BaseModel.__init__(self, **data)
        except ValidationError as exc:
            cls = type(self)
            err = ConfigError(message(exc, cls.where(data), tuple(cls.model_fields)))
            cause = (exc.errors(include_url=False)[0].get("ctx") or {}).get("error")
            if hasattr(cause, "option"):  # a part refused an option: kept for the command
                err.option, err.reason = cause.option, cause.reason
            raise err from None

    @classmethod
    def where(cls, data: Mapping[str, Any]) -> str:
        """The table's name in messages (:attr:`what`; a named sub-table adds its name)."""
        return cls.what

    def replace(self, **changes: Any) -> StageConfig:
        """A validated copy with ``changes`` applied (the other fields as they are)."""
        return type(self)(**{**dict(self), **changes})

