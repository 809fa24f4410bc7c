"""Which of the adapter's options apply to a method, read from the registered parts.

A part (a kind of posterior, an estimator, a strategy, a transform family) names the options only
it reads where it is registered (``Registry.register(..., uses=...)``, each possibly under a
condition on the config: :class:`~kbcli.core.registry.Uses`); the adapter's own rules (the stopping
rules) name theirs in :data:`RULES`. An option someone names applies to a config only when one of
those parts is chosen by the config (and its condition holds); an option nobody names (the grid,
the model's softening, ...) applies to every config. A method that compares several strategies
under one set of options (an evaluation's method) reads an option when any of them does.

The configs' edges refuse an option a user set that the method would ignore
(:func:`refuse_unused`: an evaluation's methods, ``kbcli adapt`` and ``kbcli run``); the report and
``kbcli inspect`` print only the options that apply (:func:`shown`), while every resolved option
stays recorded in the artifact.

Examples
--------
>>> from kbcli.core.adaptation.config import AdapterConfig
>>> cfg = AdapterConfig(posterior="kde")
>>> applies("robust", cfg), applies("kde_floor", cfg), applies("resolution", cfg)
(False, True, True)
>>> unused(cfg, ["kde_floor", "robust_eta", "candidates"])
['robust_eta']
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from types import SimpleNamespace
from typing import Any

from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.registry import Registry, Uses
from kbcli.errors import ConfigError

#: The parts an adapter config chooses: the option that names each, and its registry.
PARTS: dict[str, Registry] = {"posterior": POSTERIORS, "estimator": ESTIMATORS,
                              "strategy": STRATEGIES, "family": FAMILIES}

#: Options read by the adapter's own rules rather than by a part (the stopping rules): the ML cell
#: is read by the paper's rule (so are its ties), the radius by ours.
RULES: tuple[Uses, ...] = (
    Uses("ml_ties", lambda cfg: cfg.stop_ml is not None, "stop_ml is set", "stop_ml is not set"),
    Uses("stop_radius", lambda cfg: bool(cfg.stop_mass), "stop_mass > 0", "stop_mass = 0"),
)


def readers(option: str) -> list[tuple[str | None, str | None, Uses]]:
    """``(kind, name, uses)`` of every part that names ``option`` (``(None, None, uses)`` for a
    rule of :data:`RULES`); empty: every config reads it."""
    out: list[tuple[str | None, str | None, Uses]] = [
        (kind, name, u) for kind, reg in PARTS.items() for name in reg for u in reg.uses(name)
        if u.option == option]
    return out + [(None, None, u) for u in RULES if u.option == option]


def _chosen(cfg: Any, strategies: Iterable[str] | None) -> dict[str, tuple[str, ...]]:
    chosen = {kind: (getattr(cfg, kind),) for kind in PARTS}
    if strategies is not None:
        chosen["strategy"] = tuple(strategies)
    return chosen


def applies(option: str, cfg: Any, strategies: Iterable[str] | None = None) -> bool:
    """Whether a method with the config ``cfg`` (an :class:`AdapterConfig`, or :func:`view` of a
    recorded one) reads ``option``; ``strategies``: the method's strategies (default its own)."""
    found = readers(option)
    if not found:
        return True
    chosen = _chosen(cfg, strategies)
    return any((kind is None or name in chosen[kind]) and u.holds(cfg) for kind, name, u in found)


def unused(cfg: Any, options: Iterable[str], strategies: Iterable[str] | None = None) -> list[str]:
    """The ``options`` a method with ``cfg`` (and ``strategies``) does not read, in order."""
    return [o for o in options if not applies(o, cfg, strategies)]


def why(option: str, cfg: Any, strategies: Iterable[str] | None = None) -> str:
    """Why ``option`` does not apply: who reads it, and what ``cfg`` chose instead
    (``"it is read only by posterior likelihood; here the posterior is kde"``)."""
    found = readers(option)
    chosen = _chosen(cfg, strategies)
    by_kind: dict[str, list[str]] = {}
    rules = []
    for kind, name, u in found:
        if kind is None:
            rules.append(f"when {u.note}")
        else:
            by_kind.setdefault(kind, []).append(f"{name}{u.describe()}")
    who = [f"by {kind} {_or(names, serial=False)}" for kind, names in by_kind.items()] + rules
    here = [f"the {k} is {chosen[k][0]}" if len(chosen[k]) == 1
            else f"the {k.replace('y', 'ie')}s are {', '.join(chosen[k])}" for k in by_kind]
    here += [u.describe_unmet() for kind, name, u in found
             if (kind is None or name in chosen[kind]) and not u.holds(cfg)]
    return f"it is read only {_or(who)}; here {'; '.join(here) or 'none of them is chosen'}"


def refuse_unused(cfg: Any, given: Mapping[str, str] | Iterable[str], where: str,
                  strategies: Iterable[str] | None = None) -> None:
    """ConfigError naming the first option a user set that the method does not read.

    Parameters
    ----------
    cfg : AdapterConfig
        The method's resolved robot options.
    given : mapping or iterable of str
        The options the user set (a TOML table's keys, the flags given); a mapping gives each the
        label the message names it by (``{"kde_floor": "--kde-floor"}``).
    where : str
        The method, as the message names it (``methods.paper``, ``adapt``).
    strategies : iterable of str, optional
        The method's strategies (default: ``cfg.strategy``).
    """
    labels = dict(given) if isinstance(given, Mapping) else {o: o for o in given}
    strategies = None if strategies is None else tuple(strategies)
    for option in unused(cfg, labels, strategies):
        raise ConfigError(f"{where}: {labels[option]} does not apply to this method: "
                          f"{why(option, cfg, strategies)}")


def view(robot: Mapping[str, Any]) -> SimpleNamespace:
    """A recorded robot config (an artifact's dict, perhaps of an older kbcli) read as a config:
    the adapter's defaults, then the recorded values."""
    defaults = {k: f.default for k, f in AdapterConfig.model_fields.items()}
    return SimpleNamespace(**{**defaults, **dict(robot)})


def shown(robot: Mapping[str, Any], strategies: Iterable[str] | None = None) -> dict[str, Any]:
    """The options of a recorded robot config that its method reads (what tables print)."""
    cfg = view(robot)
    return {k: v for k, v in robot.items() if applies(k, cfg, strategies)}


def _or(parts: list[str], serial: bool = True) -> str:
    """``a, b, or c`` (``serial`` False: ``a, b or c``)."""
    if len(parts) == 1:
        return parts[0]
    return f"{', '.join(parts[:-1])}{', or ' if serial else ' or '}{parts[-1]}"
