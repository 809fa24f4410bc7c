"""A part's own options, and the config field that chooses a part (a union keyed by its name).

An interchangeable part (a posterior, a strategy, a layout) declares its options as a subclass of
:class:`Options` beside its code and registers it (``traits={"options": KdeOptions}``). A config
names the part and carries only that part's options: the field :func:`part_field` reads a name
(``"kde"``), a table (``{"name": "kde", "kde_samples": 1000}``) or an :class:`Options`, looks the
part up in its registry and validates the table with the part's own model, so an option the
part does not take is refused by the part, naming it (a pydantic discriminated union whose
members are whatever is registered, a plug-in's included).

The flat form users type (``kde_samples = 1000`` beside ``posterior = "kde"``: command-line flags,
TOML tables, the configs stored by kbcli before parts owned their options) is routed to the
chosen parts by :func:`route`: each option goes to the part of its kind that declares it.

Examples
--------
>>> from kbcli.core.registry import Registry
>>> SHAPES = Registry("shape")
>>> class DiscOptions(Options):
...     radius: float = 1.0
>>> _ = SHAPES.register("disc", object(), traits={"options": DiscOptions})
>>> _ = SHAPES.register("dot", object())
>>> parse_part(SHAPES, {"name": "disc", "radius": 2.0})
DiscOptions(name='disc', radius=2.0)
>>> parse_part(SHAPES, {"name": "dot", "radius": 2.0})
Traceback (most recent call last):
...
kbcli.errors.ConfigError: shape dot takes no option 'radius' (shape disc does); its options: none
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Annotated, Any, ClassVar

from pydantic import BeforeValidator, PlainSerializer, SerializeAsAny

from kbcli.core.config import Config, Name
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError


class Options(Config):
    """The options of one registered part: ``name`` is the part's name, the other fields its own
    options (a subclass declares them, each typed and constrained). A part that registers none
    takes no option."""

    what: ClassVar[str] = "options"
    name: Name

    def own(self) -> dict[str, Any]:
        """The part's options by name, ``name`` aside."""
        return {k: v for k, v in self.to_dict().items() if k != "name"}

    def inactive(self) -> dict[str, str]:
        """Options that are set but not read under the part's other options, each with why
        (``{"robust_eta": "robust = false"}``); the edges refuse those a user gave."""
        return {}

    def samples_actions(self) -> bool:
        """Whether the part draws actions from p(action | sound) with the adapter's sampler."""
        return False


def options_of(registry: Registry, name: str) -> type[Options]:
    """The options model ``name`` registered (``traits={"options": ...}``, the class or a loader
    of it that imports its module on first use); :class:`Options` (no option of its own) when it
    registered none."""
    found = registry.trait(name, "options", Options)
    return found if isinstance(found, type) else found()


def declared(registry: Registry, name: str) -> tuple[str, ...]:
    """The options ``name`` takes (its model's fields, ``name`` aside)."""
    return tuple(k for k in options_of(registry, name).model_fields if k != "name")


def owners(registry: Registry, option: str) -> list[str]:
    """The registered parts of ``registry`` that take ``option``."""
    return [n for n in registry.names() if option in declared(registry, n)]


def parse_part(registry: Registry, value: Any, default: str | None = None) -> Options:
    """``value`` (a name, a table with ``name``, or an :class:`Options`) as the part's options.

    Raises
    ------
    ConfigError
        An unknown part (listing the registered ones), or an option the part does not take
        (naming the part, who takes it, and the part's own options).
    """
    if isinstance(value, Options):
        if isinstance(value, options_of(registry, value.name)):
            return value
        value = value.to_dict()
    if isinstance(value, str):
        value = {"name": value}
    if not isinstance(value, Mapping):
        raise ConfigError(f"{registry.kind} must be a name or a table, got {value!r}")
    table = dict(value)
    name = table.setdefault("name", default)
    registry.check(name)
    mine = declared(registry, name)
    for key in table:
        if key != "name" and key not in mine:
            raise refusal(registry, name, key)
    return options_of(registry, name).from_dict(table)


def refusal(registry: Registry, name: str, key: str) -> ConfigError:
    """The part ``name`` refusing option ``key``: a ConfigError naming the part, who takes the
    option and the part's own options; ``option`` and ``reason`` are kept on it (a command names
    the flag the option came from: :func:`kbcli.core.config.refused_option`)."""
    who = owners(registry, key)
    names = who[0] if len(who) == 1 else f"{', '.join(who[:-1])} and {who[-1]}" if who else ""
    whose = f" ({registry.kind} {names} {'does' if len(who) == 1 else 'do'})" if who else ""
    reason = f"{registry.kind} {name} takes no option {key!r}{whose}"
    err = ConfigError(f"{reason}; its options: {', '.join(declared(registry, name)) or 'none'}")
    err.option, err.reason = key, reason
    return err


def part_field(registry: Registry, default: str, *, named: bool = False) -> Any:
    """The type of a config field that chooses a part of ``registry`` and carries its options
    (default ``default``, a name): read by :func:`parse_part`, written with the part's own
    fields (``{"name": ..., option: value, ...}``); with ``named``, a part with no option of its
    own is written as its name (the stored form of a field that was a name)."""
    def parse(v: Any) -> Options:
        return parse_part(registry, v, default)

    parse.__name__ = f"parse_{registry.kind.replace(' ', '_')}"
    field = Annotated[SerializeAsAny[Options], BeforeValidator(parse)]
    return Annotated[field, PlainSerializer(_as_name)] if named else field


def _as_name(part: Options) -> str | dict[str, Any]:
    return part.to_dict() if part.own() else part.name


def route(data: Mapping[str, Any], slots: Mapping[str, tuple[Registry, str]],
          own: Iterable[str], *, strict: bool = True,
          keep: Mapping[str, Iterable[str]] | None = None) -> dict[str, Any]:
    """A config's table with the parts' options given flat moved into the parts' tables.
    Parameters
    ----------
    slots : mapping
        slot -> (registry, default name): the fields that choose a part.
    own : iterable of str
        The config's own options (they stay where they are).
    strict : bool
        Refuse an option of a slot's kind that the chosen part does not take (the part names it);
        False: drop it (a stored config of an older kbcli).
    keep : mapping, optional
        slot -> names: options of a slot taken by any of these parts pass (:func:`for_part` then
        gives each its own).

    Returns
    -------
    dict
        ``data`` with each slot a table ``{"name": ..., options...}``; options no part declares
        stay flat (the config refuses them as unknown).
    """
    out = dict(data)
    own = set(own)
    for slot, (registry, default) in slots.items():
        chosen = out.get(slot, default)
        if not isinstance(chosen, (str, Mapping, Options)):
            continue  # the field refuses it
        table = chosen.to_dict() if isinstance(chosen, Options) else (
            {"name": chosen} if isinstance(chosen, str) else dict(chosen))
        name = table.setdefault("name", default)
        registry.check(name)
        kinds = {k for n in registry.names() for k in declared(registry, n)}
        accepted = set(declared(registry, name))
        for other in (keep or {}).get(slot, ()):
            accepted |= set(declared(registry, other))
        for key in [k for k in out if k in kinds and k not in own and k not in slots]:
            value = out.pop(key)
            if key in accepted:
                table[key] = value
            elif strict:
                raise refusal(registry, name, key)
        if not strict:
            table = {k: v for k, v in table.items() if k == "name" or k in accepted}
        out[slot] = table
    return out


def for_part(registry: Registry, name: str, flat: Mapping[str, Any]) -> dict[str, Any]:
    """``flat`` without the options of ``registry``'s kind that ``name`` does not take (the
    options a method shares between its strategies, given to one of them)."""
    kinds = {k for n in registry.names() for k in declared(registry, n)}
    mine = set(declared(registry, name))
    return {k: v for k, v in flat.items() if k not in kinds or k in mine}


def flat_view(table: Mapping[str, Any], slots: Iterable[str]) -> dict[str, Any]:
    """A config's table with each slot's part read as its name and its options set beside it
    (the flat layout of a recorded config; a flat table passes as it is)."""
    out = {}
    for k, v in table.items():
        if k in slots and isinstance(v, Mapping):
            out[k] = v.get("name")
            out.update({o: x for o, x in v.items() if o != "name"})
        else:
            out[k] = v
    return out
