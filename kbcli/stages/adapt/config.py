"""The adapt stage's config, :class:`AdaptConfig`: the robot's options beside the simulated
arm's and the loop's; and :class:`PlayCheck`, the melody replays around an adaptation."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from pydantic import Field, InstanceOf, field_validator, model_validator

from kbcli.core.adaptation.config import AdapterConfig, option_names
from kbcli.core.config import Flag, Name, Whole, between
from kbcli.core.instrument.melody import DEFAULT_MELODY
from kbcli.errors import ConfigError
from kbcli.sim import SimConfig
from kbcli.sim.arms import PRESETS
from kbcli.sim.config import Arm, ModeName, ReachNoise
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_REPLAY_NOTES, StageConfig

#: What the robot observes: where its finger landed, or only where it aimed.
FEEDBACKS = ("landed", "aim")
#: Steps at which a ``run`` artifact keeps the posterior by default.
DEFAULT_SNAPSHOTS = (0, 1, 2, 3, 5, 10, 20, 40)
#: The world-side and loop options of :class:`AdaptConfig` (everything else is the robot's).
LOOP_FIELDS = ("mode", "reach_noise", "arm", "feedback", "max_steps", "stop")


def robot_fields() -> tuple[str, ...]:
    """The robot's option names in the flat layout (:func:`~kbcli.core.adaptation.config.option_names`:
    the adapter's own and its parts')."""
    return option_names()


def _robot(robot: Any, flat: dict[str, Any]) -> AdapterConfig:
    """The robot's config from a ``robot`` value (None, a table or an AdapterConfig) with the robot
    options given at the top level (``flat``) applied over it."""
    if isinstance(robot, AdapterConfig):
        return robot.replace(**flat) if flat else robot
    if robot is None:
        robot = {}
    if not isinstance(robot, Mapping):
        raise ConfigError("adapt.robot must be a table of adapter options")
    return AdapterConfig.from_dict({**robot, **flat})


class AdaptConfig(StageConfig):
    """One adaptation: the robot's settings (``robot``, a :class:`kbcli.core.adaptation.loop.AdapterConfig`)
    plus the simulated arm's and the loop's.

    ``arm`` (a preset name or a table) is how the simulated arm errs; ``feedback = "landed"``:
    the robot observes where its finger landed; ``"aim"``: only where it aimed, and
    ``robot.blur`` is set to ``reach_noise`` (px). ``max_steps`` is T; ``stop``: end at the
    stopping rule (else run T steps and record when the rule fired).

    The robot's options read through as attributes (``cfg.family`` is ``cfg.robot.family``). They
    may also be given at the top level (``AdaptConfig(strategy="random")``, the flat layout of
    schema-1 artifacts and older TOML files), overriding the same option of ``robot``.
    """

    what: ClassVar[str] = "adapt"

    robot: InstanceOf[AdapterConfig] = Field(default_factory=AdapterConfig)
    mode: ModeName = "ideal"
    reach_noise: ReachNoise = 0.0
    arm: Arm = PRESETS.get("ideal")
    feedback: Name = "landed"
    max_steps: between(Whole, 1, MAX_ADAPT_STEPS) = 40
    stop: Flag = False

    @model_validator(mode="before")
    @classmethod
    def _nest_robot(cls, data: Any) -> Any:
        """Move the robot options given at the top level into ``robot``."""
        if not isinstance(data, Mapping):
            raise ConfigError("the adapt options must be a table")
        d = dict(data)
        robot_keys = robot_fields()
        known = (*cls.model_fields, *robot_keys)
        unknown = [k for k in d if k not in known]
        if unknown:
            raise ConfigError(f"unknown adapt option {unknown[0]!r}; valid: "
                              f"{', '.join(sorted(known))}")
        flat = {k: d.pop(k) for k in robot_keys if k in d}
        d["robot"] = _robot(d.get("robot"), flat)
        return d

    @field_validator("feedback")
    @classmethod
    def _feedback(cls, v: str) -> str:
        if v not in FEEDBACKS:
            raise ValueError(f"unknown feedback {v!r}; valid: {', '.join(FEEDBACKS)}")
        return v

    @model_validator(mode="after")
    def _parts(self) -> AdaptConfig:
        self.sim_config()  # the arm and the robot check their own settings
        self.adapter_config()
        return self

    def __getattr__(self, name: str) -> Any:
        # the robot's options read through (``cfg.strategy``); only called for missing attributes
        if not name.startswith("_") and name in AdapterConfig.model_fields:
            return getattr(self.robot, name)
        return super().__getattr__(name)

    @classmethod
    def flat(cls, **options: Any) -> AdaptConfig:
        """Build from one flat set of options (robot and loop options mixed), as flags give them."""
        return cls.from_dict(options)

    def with_robot(self, **changes: Any) -> AdaptConfig:
        """A copy with some robot options changed."""
        return self.replace(robot=self.robot.replace(**changes))

    def sim_config(self) -> SimConfig:
        return SimConfig(mode=self.mode, reach_noise=self.reach_noise, arm=self.arm)

    def adapter_config(self) -> AdapterConfig:
        """The robot-side config (``blur`` is the reach noise under ``aim`` feedback)."""
        if self.feedback == "aim":
            return self.robot.replace(blur=float(self.reach_noise))
        return self.robot

    def to_dict(self) -> dict:
        """Every resolved option, the robot's nested under ``robot``."""
        d = {k: getattr(self, k) for k in LOOP_FIELDS}
        d["arm"] = self.arm.to_dict()
        return {"robot": self.robot.to_dict(), **d}


class PlayCheck(StageConfig):
    """Playing success measured by replaying the melody (Algorithm 1) around an adaptation:
    ``notes`` touches per replay, after adaptation with the final estimate and, with
    ``reference``, also before the displacement and after it without adaptation."""

    what: ClassVar[str] = "play"

    melody: Name = DEFAULT_MELODY
    notes: between(Whole, 1, MAX_REPLAY_NOTES) = 200
    reference: Flag = True
