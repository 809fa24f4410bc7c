"""The environment's options, :class:`EnvConfig`: what ``gymnasium.make(ID, **options)`` takes.

The task's options (the model, where the keyboard moved, the step limit, the reward, what the agent
observes) are this config's own fields; the adaptation's (the arm, the robot's posterior, its grid,
its stopping rule...) are :class:`kbcli.stages.adapt.AdaptConfig`'s, given as one table ``adapt``
(``gymnasium.make(ID, adapt={"resolution": 1.0})``): the environment runs kbcli's own adaptation
with them, so every option ``kbcli adapt`` takes means the same here.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, BeforeValidator, Field, model_validator

from kbcli.core.config import Config, Flag, Name, Number, Whole, between, member_of
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.envs.rewards import REWARDS
from kbcli.errors import ConfigError
from kbcli.sim.config import ModeName
from kbcli.stages.adapt import AdaptConfig
from kbcli.stages.config import MAX_ADAPT_STEPS
from kbcli.stages.perturb import CATEGORIES

#: The options the environment sets itself, refused inside ``adapt`` (each has its own keyword; the
#: agent, not the environment, chooses the actions).
OWN_OPTIONS = ("family", "mode", "arm", "max_steps", "stop", "strategy")


def _path(v: Any) -> Any:
    """A model given as a path object is kept as its string."""
    return os.fspath(v) if isinstance(v, os.PathLike) else v


def _table(v: Any) -> Any:
    if v is None:
        return {}
    if not isinstance(v, Mapping):
        raise ConfigError(f"must be a table of kbcli adapt options, got {v!r}")
    return dict(v)


class EnvConfig(Config):
    """The options of ``kbcli/KeyboardAdapt-v0`` and ``kbcli/KeyboardAdaptDynamics-v0``
    (keywords of ``gymnasium.make``).

    Attributes
    ----------
    model : str, optional
        The robot's model artifact (``.h5``, kind ``model``); None: the embedded default model
        (``data/default-model.h5``). Its keyboard is the world's.
    category : str, optional
        Where the keyboard moves at each reset: a displacement drawn from ``small``, ``medium`` or
        ``large`` (``kbcli perturb``'s categories, :data:`kbcli.stages.perturb.CATEGORIES`); None:
        a category drawn uniformly first, then a displacement of it.
    move : tuple of float, optional
        A fixed displacement instead (``(dx, dy)``, or ``(angle, dx, dy)`` for ``rigid``), the same
        at every reset; ``reset(options={"move": ...})`` sets one episode's.
    family : str
        The transform family of the displacement and of the robot's estimate.
    max_steps : int
        Touches per episode at most: ``truncated`` after this many.
    reward : str
        :data:`kbcli.envs.rewards.REWARDS`: ``information`` (nats the touch took off the
        posterior's entropy) or ``error`` (minus the estimate's error, px).
    belief : bool
        Also observe kbcli's posterior over the displacement (``obs["belief"]``).
    stop : bool
        ``terminated`` when kbcli's stopping rule holds (else episodes run ``max_steps`` touches,
        as ``kbcli adapt --no-stop`` does, and ``info["stop"]`` says when the rule held).
    mode, arm : str
        The simulated arm: ``ideal`` / ``ideal`` (``KeyboardAdapt-v0``) or ``dynamics`` /
        ``realistic`` (``KeyboardAdaptDynamics-v0``); ``arm`` may also be a table.
    adapt : dict
        Any other option of ``kbcli adapt`` (:class:`~kbcli.stages.adapt.AdaptConfig`: the robot's
        posterior, grid and stopping rule, the reach noise, the feedback).
    """

    what: ClassVar[str] = "env"

    model: Annotated[Name | None, BeforeValidator(_path)] = None
    category: Annotated[Name | None, AfterValidator(
        lambda v: v if v is None else member_of("category", CATEGORIES)(v))] = None
    move: tuple[Number, ...] | None = None
    family: Annotated[Name, AfterValidator(FAMILIES.check)] = "translation"
    max_steps: between(Whole, 1, MAX_ADAPT_STEPS) = 40
    reward: Annotated[Name, AfterValidator(REWARDS.check)] = "information"
    belief: Flag = False
    stop: Flag = True
    mode: ModeName = "ideal"
    arm: Name | dict = "ideal"
    adapt: Annotated[dict[str, Any], BeforeValidator(_table)] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _consistent(self) -> EnvConfig:
        # (a message raised here reads "env: MESSAGE")
        if self.move is not None and self.category is not None:
            raise ConfigError("give either category or move, not both")
        if self.move is not None:
            check_move(self.move, self.family)
        if own := [k for k in self.adapt if k in OWN_OPTIONS]:
            raise ConfigError(f"adapt.{own[0]} is set by the environment ("
                              + ("the agent chooses the actions)" if own[0] == "strategy"
                                 else f"give it as the keyword {own[0]}=)"))
        try:
            self.adapt_config()  # the adaptation checks its own options
        except ConfigError as exc:  # a fresh error: its message names adapt's key
            raise ConfigError(str(exc)) from None
        return self

    def adapt_config(self) -> AdaptConfig:
        """The adaptation the environment runs (``kbcli adapt``'s config)."""
        return AdaptConfig.from_dict({**self.adapt, "family": self.family, "mode": self.mode,
                                      "arm": self.arm, "max_steps": self.max_steps,
                                      "stop": self.stop})


def check_move(move: Any, family: str, name: str = "move") -> tuple[float, ...]:
    """``move`` as the family's parameters (``(dx, dy)`` or ``(angle, dx, dy)``); raises
    :class:`ConfigError` naming ``name``."""
    params = FAMILIES.get(family).params
    try:
        values = tuple(float(v) for v in move)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be {len(params)} numbers ({', '.join(params)}), "
                          f"got {move!r}") from None
    if len(values) != len(params) or not all(v == v and abs(v) != float("inf") for v in values):
        raise ConfigError(f"{name} must be {len(params)} finite numbers ({', '.join(params)}), "
                          f"got {list(values)}")
    return values
