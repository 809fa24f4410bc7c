"""The evaluation protocol's named methods: :class:`Method` (a ``[evaluate.methods.NAME]`` table:
adapt options and the strategies compared under them) and the two built in, ``paper`` and
``kbcli``."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, Field, field_validator, model_validator

from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.config import Name, Names, each, member_of
from kbcli.core.options import for_part, owners
from kbcli.errors import ConfigError
from kbcli.sim import MODES
from kbcli.stages.config import StageConfig

#: The strategies of the layout before named methods when it names none.
DEFAULT_STRATEGIES = ("random", "active", "infogain")
#: Adapt options the protocol sets per experiment (not in a method's table).
PER_EXPERIMENT = ("strategy", "mode", "max_steps", "family", "reach_noise", "arm")
#: Keys of a method's table that are not adapt options.
METHOD_KEYS = ("strategies", "modes", "categories", "description", "seeds_of")

#: The paper's method as the paper writes it (Sect. III-D, III-E; ``pipelines/paper.toml`` names
#: the choices it leaves open): Eq. 7-8 with Algorithm 2's fresh samples and no floor, the
#: maximum-likelihood hypothesis (ties at random), the learned model as it is, the random selection
#: of samples from the model and the active strategy of Sect. III-E (``paper-active``).
PAPER_METHOD = {"description": "the paper's text: product of KDEs (Eq. 7-8) with Algorithm 2's "
                               "fresh samples, no floor, maximum-likelihood estimate, random "
                               "samples of the model and the active strategy of Sect. III-E",
                "strategies": ["random", "paper-active"], "posterior": "kde", "kde_draw": "fresh",
                "kde_sampler": "raster", "kde_beyond": "silent", "kde_floor": 0.0, "estimator": "ml",
                "ml_ties": "random", "random_actions": "model", "stop_ml": 0.02, "stop_mass": 0.0,
                "model_blur": 0.0}
#: Ours: the adapter's defaults, every strategy.
KBCLI_METHOD = {"description": "kbcli's best: the adapter's defaults", "strategies":
                ["random", "active", "infogain"]}


def adapt_stage():
    """The adapt stage package, or None while it is not available."""
    import importlib

    try:
        return importlib.import_module("kbcli.stages.adapt")
    except ModuleNotFoundError as exc:
        if exc.name != "kbcli.stages.adapt":
            raise
        return None


def known_strategies() -> tuple[str, ...]:
    """Strategy names the adapter offers (:data:`kbcli.core.adaptation.strategies.STRATEGIES`)."""
    from kbcli.core.adaptation.strategies import STRATEGIES

    return tuple(STRATEGIES)


#: ``check_modes(names)``: ``names`` itself when each is a mode of :data:`kbcli.sim.MODES` (for
#: validators; None passes).
check_modes = each(member_of("mode", MODES))


class Method(StageConfig):
    """A named way to adapt: adapt options and the strategies compared under them.

    ``strategies`` must include the protocol's ``baseline``. ``options`` are adapt-stage options
    (:class:`kbcli.stages.adapt.AdaptConfig`; left out: its defaults); ``strategy``, ``mode``,
    ``max_steps``, ``family`` and ``reach_noise`` are set by the protocol. ``modes`` and
    ``categories`` restrict where the method runs (None: everywhere). ``seeds_of``: seed the
    experiments as the method of that name (seeds contain the method's name), so a method renamed
    keeps its numbers; None: its own name.
    """

    what: ClassVar[str] = "methods"

    name: Name
    strategies: Names
    options: Annotated[Mapping[str, Any], AfterValidator(lambda v: MappingProxyType(dict(v)))] = (
        Field(default_factory=dict))
    modes: Annotated[Names | None, AfterValidator(check_modes)] = None
    categories: Names | None = None
    description: Name = ""
    seeds_of: Name | None = None

    @property
    def seed_name(self) -> str:
        """The name in the experiments' seeds (``seeds_of``, or the method's own)."""
        return self.name if self.seeds_of is None else self.seeds_of

    @classmethod
    def where(cls, data: Mapping[str, Any]) -> str:
        return f"methods.{data.get('name')}"

    @field_validator("strategies")
    @classmethod
    def _strategies(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        known = known_strategies()
        for st in v:
            if st not in known:
                raise ValueError(f"unknown strategy {st!r}; valid: {', '.join(known)}")
        return v

    @model_validator(mode="after")
    def _not_per_experiment(self) -> Method:
        fixed = sorted(set(self.options) & set(PER_EXPERIMENT))
        robot = self.options.get("robot")
        if isinstance(robot, Mapping):
            fixed += sorted(set(robot) & set(PER_EXPERIMENT))
        if fixed:
            raise ConfigError(
                f"methods.{self.name}.{fixed[0]} is set per experiment by the protocol: use "
                "strategies, modes, max_steps, family, reach_noise and arm of [evaluate] instead")
        return self

    @model_validator(mode="after")
    def _strategies_take(self) -> Method:
        """A strategy option (``candidates``, ...) must be taken by one of the method's
        strategies (each gets those it takes: :meth:`options_for`)."""
        robot = self.options.get("robot")
        flat = {**self.options, **(dict(robot) if isinstance(robot, Mapping) else {})}
        flat.pop("robot", None)
        for key in flat:
            who = owners(STRATEGIES, key)
            if who and not set(who) & set(self.strategies):
                raise ConfigError(f"methods.{self.name}: {key} does not apply to this method: no "
                                  f"strategy of it takes it (strategy {', '.join(who)} "
                                  f"{'does' if len(who) == 1 else 'do'})")
        return self

    def options_for(self, strategy: str) -> dict[str, Any]:
        """The method's adapt options for one of its strategies: a strategy option another of its
        strategies takes left out (a ``robot`` table's too)."""
        out = for_part(STRATEGIES, strategy, self.options)
        if isinstance(out.get("robot"), Mapping):
            out["robot"] = for_part(STRATEGIES, strategy, out["robot"])
        return out

    def given(self) -> list[str]:
        """The adapt options the method's table sets (a ``robot`` table's too)."""
        robot = self.options.get("robot")
        inner = list(robot) if isinstance(robot, Mapping) else []
        return [k for k in self.options if k != "robot"] + inner

    def runs_in(self, mode: str, category: str) -> bool:
        return ((self.modes is None or mode in self.modes)
                and (self.categories is None or category in self.categories))

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"strategies": list(self.strategies)}
        if self.modes is not None:
            d["modes"] = list(self.modes)
        if self.categories is not None:
            d["categories"] = list(self.categories)
        if self.description:
            d["description"] = self.description
        if self.seeds_of is not None:
            d["seeds_of"] = self.seeds_of
        d.update({k: (dict(v) if isinstance(v, Mapping) else v) for k, v in self.options.items()})
        return d

    @classmethod
    def from_table(cls, name: str, table: Any) -> Method:
        """A method from its TOML table: ``strategies`` (and ``modes``, ``categories``,
        ``description``) beside the adapt options."""
        if not isinstance(table, Mapping):
            raise ConfigError(f"methods.{name} must be a table (strategies and adapt options)")
        d = dict(table)
        if "strategies" not in d:
            raise ConfigError(f"methods.{name} needs strategies = [...]")
        kw = {k: d.pop(k) for k in METHOD_KEYS if k in d}
        return cls(name=name, options=d, **kw)


def default_methods() -> tuple[Method, ...]:
    return (Method.from_table("paper", PAPER_METHOD), Method.from_table("kbcli", KBCLI_METHOD))
