"""Configs on pydantic v2: one frozen model per TOML table, validated by field constraints.

Every config of kbcli (a stage's TOML table, the adapter's options, a detector's, an arm's)
subclasses :class:`Config`: frozen, ``extra="forbid"`` (a typo is an error, never silently
ignored), each field typed and constrained with the aliases below. A bad value raises
:class:`~kbcli.errors.ConfigError` with one line naming the table, the key and what is allowed::

    adapt.resolution must be greater than 0, got -1
    unknown adapt option 'resolutoin'; valid: strategy, posterior, ...

:func:`kbcli.io.config.load_config` prefixes the file's path. Whole numbers are strict (``3.0`` and
``true`` are refused where a count is asked for), numbers are finite, and TOML lists become tuples.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, ValidationError

from kbcli.errors import ConfigError

#: A finite number (an int is accepted and stored as a float; a bool or a string is refused).
Number = Annotated[float, Strict(), Field(allow_inf_nan=False)]
#: A finite number > 0.
Positive = Annotated[float, Strict(), Field(gt=0, allow_inf_nan=False)]
#: A finite number >= 0.
NonNegative = Annotated[float, Strict(), Field(ge=0, allow_inf_nan=False)]
#: A probability in (0, 1).
Rate = Annotated[float, Strict(), Field(gt=0, lt=1)]
#: A whole number (not a bool, not 3.0).
Whole = Annotated[int, Strict()]
#: A whole number >= 1.
Count = Annotated[int, Strict(), Field(ge=1)]
#: A whole number >= 0.
NonNegativeInt = Annotated[int, Strict(), Field(ge=0)]
#: true or false.
Flag = Annotated[bool, Strict()]
#: A name (a registry checks it in the model that uses it).
Name = Annotated[str, Strict()]


def _distinct(v: tuple[str, ...]) -> tuple[str, ...]:
    if len(set(v)) != len(v):
        raise ValueError(f"lists a name twice: {list(v)!r}")
    return v


#: A non-empty list of distinct names.
Names = Annotated[tuple[Name, ...], Field(min_length=1), AfterValidator(_distinct)]


def member_of(kind: str, valid: Iterable[str]) -> Callable[[str], str]:
    """A check of one name: the name itself when it is in ``valid`` (read at each check: a dict or
    a registry filled later counts), else ``ValueError: unknown KIND 'x'; valid: a, b``."""

    def check(name: str) -> str:
        names = tuple(valid)
        if name not in names:
            raise ValueError(f"unknown {kind} {name!r}; valid: {', '.join(names)}")
        return name

    return check


def each(check: Callable[[str], Any]) -> Callable[[tuple[str, ...] | None], tuple[str, ...] | None]:
    """An after-validator of a list of names: ``check(name)`` of each (:func:`member_of`, a
    registry's ``get``), which raises for an unknown one; the list (or None) passes as it is."""

    def check_all(names: tuple[str, ...] | None) -> tuple[str, ...] | None:
        for name in names or ():
            check(name)
        return names

    return check_all


def between(base: Any, low: float | None = None, high: float | None = None, *,
            low_open: bool = False, high_open: bool = False) -> Any:
    """``base`` (:data:`Number`, :data:`Whole`, ...) within an interval; a value outside it is
    refused with the whole interval in the message (``play.steps must be a whole number in
    [1, 100000], got 1000000000``), where pydantic's own message names one bound only.

    Parameters
    ----------
    low, high : float, optional
        The bounds (None: unbounded on that side).
    low_open, high_open : bool
        Whether the bound itself is excluded.
    """
    whole = "a whole number" if _is_whole(base) else "a number"
    lo, hi = _bound(low), _bound(high)
    if low is not None and high is not None:
        text = f"in {'(' if low_open else '['}{lo}, {hi}{')' if high_open else ']'}"
    elif low is not None:
        text = f"{'>' if low_open else '>='} {lo}"
    else:
        text = f"{'<' if high_open else '<='} {hi}"

    def check(v: Any) -> Any:
        ok = v == v  # not NaN
        if low is not None:
            ok = ok and (v > low if low_open else v >= low)
        if high is not None:
            ok = ok and (v < high if high_open else v <= high)
        if not ok:
            raise ValueError(f"must be {whole} {text}, got {_short(v)}")
        return v

    return Annotated[base, AfterValidator(check)]


def _bound(v: float | None) -> str:
    if v is None:
        return ""
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


def _is_whole(base: Any) -> bool:
    return getattr(base, "__origin__", base) is int


_PHRASES = (
    ("Input should be ", "must be "),
    ("Value error, ", ""),
    ("Assertion failed, ", ""),
    ("a valid integer", "a whole number"),
    ("a valid number", "a number"),
    ("a valid boolean", "true or false"),
    ("a valid tuple", "a list"),
    ("a valid string", "a string"),
    ("Tuple should have at least 1 item after validation, not 0", "must not be empty"),
    ("List should have at least 1 item after validation, not 0", "must not be empty"),
)


def plain_words(msg: str) -> str:
    """A pydantic message in kbcli's words ("Input should be a valid integer" -> "must be a
    whole number")."""
    for old, new in _PHRASES:
        msg = msg.replace(old, new)
    return msg


def describe_error(exc: ValidationError, what: str, fields: tuple[str, ...] = ()) -> str:
    """One line for the first error of ``exc``: the table, the key, what is allowed, the value.

    Parameters
    ----------
    what : str
        The config's name in the message (its TOML table: "adapt", "keyboard", ...).
    fields : tuple of str
        The valid keys, listed when a key is unknown.
    """
    e = exc.errors(include_url=False)[0]
    loc = _location(e["loc"])
    inner = (e.get("ctx") or {}).get("error")
    if isinstance(getattr(inner, "validation", None), tuple):  # a nested config's own error
        nested_exc, nested_fields = inner.validation
        return describe_error(nested_exc, f"{what}.{loc}" if loc else what, nested_fields)
    if e["type"] == "extra_forbidden":
        key = e["loc"][-1] if e["loc"] else "?"
        inner = ".".join(str(p) for p in e["loc"][:-1])
        where = f"{what}.{inner}" if inner else what
        valid = f"; valid: {', '.join(fields)}" if fields and not inner else ""
        return f"unknown {where} option {key!r}{valid}"
    msg = plain_words(e["msg"])
    if e["type"] == "missing" and e["loc"] and isinstance(e["loc"][-1], int):
        return (f"{what}.{_location(e['loc'][:-1])} has too few values (no value "
                f"[{e['loc'][-1]}]), got {_short(e.get('input'))}")
    if e["type"] in ("missing",):
        return f"{what}.{loc} is required"
    name = f"{what}.{loc}" if loc else what
    if e["type"] in ("too_long", "too_short"):
        ctx = e.get("ctx") or {}
        most = "most" if e["type"] == "too_long" else "least"
        bound = ctx.get("max_length" if e["type"] == "too_long" else "min_length")
        return f"{name} must have at {most} {bound} values, got {ctx.get('actual_length', '?')}"
    if e["type"] in ("value_error", "assertion_error"):  # a validator's own sentence
        return f"{name} {msg}" if msg.startswith("must ") else f"{name}: {msg}"
    return f"{name} {msg}, got {_short(e.get('input'))}"


def _location(loc: tuple) -> str:
    """A key path as a user writes it: ``origin[1]``, ``adapt.robot.prior_halfwidth``."""
    out = ""
    for p in loc:
        if p == "__root__":
            continue
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _short(v: Any) -> str:
    text = repr(list(v) if isinstance(v, tuple) else v)
    return text if len(text) <= 60 else text[:57] + "..."


class Config(BaseModel):
    """Base of every config: frozen, unknown keys refused, errors as :class:`ConfigError`.

    Subclasses set ``what`` (the TOML table's name used in messages) and declare typed fields.
    Construct with keywords (``AdapterConfig(strategy="random")``) or :meth:`from_dict`; both
    raise ``ConfigError`` (never pydantic's ``ValidationError``).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True,
                              arbitrary_types_allowed=True)
    #: The config's name in messages (its TOML table).
    what: ClassVar[str] = "config"

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            fields = tuple(type(self).model_fields)
            err = ConfigError(describe_error(exc, self.what, fields))
            # kept so that a config nesting this one names the key once: "loop.detector.n_st ..."
            err.validation = (exc, fields)
            inner = (exc.errors(include_url=False)[0].get("ctx") or {}).get("error")
            if hasattr(inner, "option"):  # a part refused an option: kept for the command
                err.option, err.reason = inner.option, inner.reason
            raise err from None

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Config:
        """A config from a TOML table or an artifact's stored config."""
        if not isinstance(d, Mapping):
            raise ConfigError(f"{cls.what} must be a table, got {_short(d)}")
        return cls(**dict(d))

    def to_dict(self) -> dict[str, Any]:
        """The full config (defaults included) as plain JSON-able values (tuples as lists)."""
        return _plain(self.model_dump())

    def replace(self, **changes: Any) -> Config:
        """A copy with ``changes`` applied and validated (``dataclasses.replace`` for configs)."""
        return type(self)(**{**self.to_dict(), **changes})


def refused_option(exc: ConfigError, labels: Mapping[str, str], where: str,
                   to: str = "this method") -> ConfigError:
    """``exc`` naming the flag or file key (``labels``: option -> how the user gave it) of the
    option a part refused (:func:`kbcli.core.options.refusal`); ``exc`` itself otherwise."""
    option = getattr(exc, "option", None)
    if option not in labels:
        return exc
    err = ConfigError(f"{where}: {labels[option]} does not apply to {to}: {exc.reason}")
    err.option, err.reason = option, exc.reason
    return err


class Record:
    """Base of a frozen dataclass of results that an artifact keeps as a plain dict (in its
    attributes): :meth:`to_dict` gives its fields, and ``cls(**record.to_dict())`` rebuilds it."""

    def to_dict(self) -> dict[str, Any]:
        """The fields, by name (:func:`dataclasses.asdict`)."""
        return asdict(self)


def _plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def as_table(cls: type[Config]) -> Any:
    """A before-validator of a field holding a nested config ``cls``: an instance passes as it is,
    a table (mapping) is read by ``cls.from_dict``, anything else is refused."""
    def check(v: Any) -> Config:
        if isinstance(v, cls):
            return v
        if isinstance(v, Mapping):
            return cls.from_dict(dict(v))
        raise ConfigError(f"must be a table ([{cls.what}]), got {type(v).__name__}")

    check.__name__ = f"as_{cls.__name__}"
    return check
