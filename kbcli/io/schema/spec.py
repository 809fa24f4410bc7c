"""The vocabulary of the artifact schemas: dtype kinds, :class:`Dataset`, :class:`Schema` and the
types of summary attributes and config entries."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

#: dtype kinds: f float, i/u integer, b bool, U text (a string dataset)
FLOAT, INT, BOOL, TEXT = "f", "iu", "b", "U"
NUM = "fiu"
FLAG = "biu"  # 0/1 results stored as bool or small integers

#: What a message calls each accepted set of dtype kinds.
KIND_WORDS = {"f": "floats", "iu": "integers", "b": "booleans", "U": "text", "fiu": "numbers",
              "biu": "0/1 flags"}

#: Fewest sound classes (besides silence) a learned model must tell apart: ``kbcli learn`` refuses to
#: write, and every reader refuses to load, a model with fewer (it cannot locate a moved keyboard).
MIN_SOUNDS = 2


@dataclass(frozen=True)
class Dataset:
    """A required (or optional) dataset.

    Parameters
    ----------
    path : str
        Slash path in the artifact, possibly with ``{placeholders}`` expanded over a list in the
        summary attributes (``{modes}`` over ``attrs["modes"]``).
    kinds : str
        Accepted numpy dtype kinds (``"f"``, ``"iu"``, ``"b"``, ``"U"``).
    shape : tuple of int or str
        Axis lengths (int), symbols shared by every dataset of the artifact (``"T"``) or ``"*"``
        (any length); its length is the expected ``ndim``.
    optional : bool
        May be absent (checked when present).
    when : callable, optional
        ``when(artifact) -> bool``: required only for such artifacts (e.g. learned models).
    index, upto : str, optional
        The values are indices into an axis of that symbol (``[0, n)``) or steps (``[0, n]``).
    finite : bool
        Float values must be finite (the default); False for log densities (``-inf``).
    nan : bool
        NaN marks a missing value (silence's features, a score before its warm-up, a count never
        reached); infinite values are still refused.
    """

    path: str
    kinds: str
    shape: tuple[int | str, ...] = ()
    optional: bool = False
    when: Callable[[Any], bool] | None = None
    index: str | None = None
    upto: str | None = None
    finite: bool = True
    nan: bool = False


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


#: summary attribute types: "int", "num", "str", "bool", "list", "strs" (list of str), "dict",
#: "nums" (list of numbers), "numdict" (dict of numbers); a trailing "?" also allows null.
TYPES: dict[str, Callable[[Any], bool]] = {
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "num": _is_num,
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
    "list": lambda v: isinstance(v, list),
    "strs": lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
    "nums": lambda v: isinstance(v, list) and all(_is_num(x) for x in v),
    "dict": lambda v: isinstance(v, dict),
    "numdict": lambda v: isinstance(v, dict) and all(_is_num(x) for x in v.values()),
}
WORDS = {"int": "a whole number", "num": "a number", "str": "text", "bool": "true or false",
         "list": "a list", "strs": "a list of names", "nums": "a list of numbers",
         "dict": "a table", "numdict": "a table of numbers"}


def typed(value: Any, spec: str) -> bool:
    """Whether ``value`` is of type ``spec`` (a key of :data:`TYPES`, ``?``: or None)."""
    if spec.endswith("?"):
        return value is None or TYPES[spec[:-1]](value)
    return TYPES[spec](value)


@dataclass(frozen=True)
class Schema:
    """What one schema version of a kind holds.

    Parameters
    ----------
    datasets : tuple of Dataset
    attrs : dict
        Summary attributes (``attrs`` JSON) and their types (see :data:`TYPES`); a name ending in
        ``?`` may be absent (its type is checked when present).
    config : dict
        Config entries and their types; a dotted key reaches into a table (``"loop.adapt"``), a
        key ending in ``?`` may be absent.
    checks : tuple of callables
        ``check(artifact) -> str | None``: a message when a rule across entries fails.
    """

    datasets: tuple[Dataset, ...] = ()
    attrs: dict[str, str] = field(default_factory=dict)
    config: dict[str, str] = field(default_factory=dict)
    checks: tuple[Callable[[Any], str | None], ...] = ()


def extend(base: Schema, *datasets: Dataset, **attrs: str) -> Schema:
    """A later version of a schema: ``base`` plus datasets and summary attributes."""
    return Schema(datasets=(*base.datasets, *datasets), attrs={**base.attrs, **attrs},
                  config=base.config, checks=base.checks)
