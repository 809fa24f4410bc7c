"""Stage ``learn``: learn the instrument model M_INST by exploration (paper Sect. III-A, ref. [11]).

The simulated arm (:mod:`kbcli.sim`) reaches for targets chosen by an exploration strategy
(:mod:`kbcli.core.model.explore`) on the pad where the keyboard lies at its reference pose; the
robot hears what its finger played and fits a model of p(sound | action) of the chosen class
(:mod:`kbcli.core.model.classes`) or, by default (``auto``), the class that cross-validation on the
samples prefers (:mod:`kbcli.core.model.select`; the artifact's config then names the class
chosen, ``model_class_requested`` is ``auto`` and the attrs' ``model_selection`` hold every
candidate's score). The keyboard is used only to score the model: the learning curve (accuracy on
a 2 px grid every ``curve_every`` reaches) and the final accuracy and boundary error on a 1 px grid
(:mod:`kbcli.core.model.accuracy`). ``strategy = "exact"`` returns the exact-model artifact
(:func:`kbcli.stages.models.exact_artifact`).

The ``model`` artifact (schema 3) holds ``samples/actions`` (the reach targets), ``samples/landed``
(what the model is fitted on), ``samples/perceived`` (NaN rows: silence), in ``dynamics`` mode
``samples/start_angles``; ``model/...`` (the class's ``to_arrays``), ``curve/{reaches,accuracy}``
and ``evaluation/predicted_keys`` (the predicted key per 1 px cell, -1 silence, -2 no key; row i is
y, from ``evaluation/origin``). Its attrs hold ``accuracy``, ``boundary_error_px``,
``reaches_to_97`` and ``reaches_to_99`` (the first curve point at or above 97 % / 99 %, or None),
``model_class``, ``n_classes`` and ``reliability`` (what the model estimates of itself, and the
calibration it chose: :mod:`kbcli.core.model.reliability`). No time is stored: identical runs give
identical files.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import (
    BeforeValidator,
    Field,
    InstanceOf,
    SerializeAsAny,
    field_serializer,
    model_validator,
)

from kbcli.core.config import Config, Whole, between
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.model import accuracy as scoring
from kbcli.core.model import reliability, select
from kbcli.core.model.base import grid_points
from kbcli.core.model.classes import (
    AUTO,
    EXACT,
    fit_model,
    learned_classes,
    model_choice,
    route_options,
    set_options,
)
from kbcli.core.model.explore import STRATEGIES, Exploration, ExploreConfig
from kbcli.core.model.explore.base import SLOTS
from kbcli.core.options import Options, flat_view, owners, parse_part, route
from kbcli.errors import ArtifactError, ConfigError
from kbcli.sim import SimConfig, World, check_keyboard_reachable, make_reacher
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.config import MAX_BUDGET
from kbcli.stages.models import exact_artifact

CURVE_STEP = 2.0  # px, grid of the learning curve's accuracy
EVAL_STEP = 1.0  # px, grid of the final accuracy and boundary error
LEVELS = (0.97, 0.99)  # accuracies whose first crossing the artifact records
#: Spawn key of the generator that assigns samples to cross-validation folds.
RELIABILITY_KEY = 9
#: Spawn key of the generator of the folds that choose the class under ``auto``.
SELECT_KEY = 10


def model_classes() -> tuple[str, ...]:
    """Valid ``--model-class`` values: ``auto`` and the learned model classes."""
    return (AUTO, *learned_classes())


def strategies() -> tuple[str, ...]:
    """Valid ``--strategy`` values: the exploration strategies and ``exact`` (no learning)."""
    return (*sorted(STRATEGIES), EXACT)


def _name(v: Any) -> Any:
    return v.get("name", "active") if isinstance(v, dict) else getattr(v, "name", v)


def _strategy(v: Any) -> Options:
    """``exact`` (no learning, no option) or an exploration strategy with its options."""
    if _name(v) not in strategies():
        raise ConfigError(f"unknown strategy {_name(v)!r}; valid: {', '.join(strategies())}")
    return Options(name=EXACT) if _name(v) == EXACT else parse_part(STRATEGIES, v, "active")


def _sim(value: Any) -> Any:
    """A ``sim`` table (a recorded config's, :meth:`Config.replace`'s) read as a SimConfig."""
    return SimConfig.from_dict(value) if isinstance(value, Mapping) else value


class LearnConfig(Config):
    """How the model is learned.

    ``strategy`` is an exploration strategy with its options (given flat beside it too) or
    ``exact`` (no learning); ``budget`` reaches, refitting every ``batch``; a learning-curve point
    after the batch that reaches each multiple of ``curve_every``, and at the end; ``sim`` the arm.
    ``model_class`` is a learned class with its options (a name or a table; flat beside it too), or
    ``auto``: explore with :func:`kbcli.core.model.select.explore_class`, re-chosen every
    :data:`kbcli.core.model.select.RESELECT` reaches, then fit the class with the best
    cross-validated score on the samples (never the simulator's truth).
    """

    what: ClassVar[str] = "learn"

    strategy: Annotated[SerializeAsAny[Options], BeforeValidator(_strategy)] = "active"
    budget: between(Whole, 1, MAX_BUDGET) = 800
    batch: between(Whole, 1, MAX_BUDGET) = 10
    curve_every: between(Whole, 1, MAX_BUDGET) = 50
    sim: Annotated[InstanceOf[SimConfig], BeforeValidator(_sim)] = Field(default_factory=SimConfig)
    model_class: model_choice(AUTO) = AUTO

    @model_validator(mode="before")
    @classmethod
    def _part(cls, data: Any) -> Any:
        """Options given flat go to the strategy or the model class (``exact`` takes none)."""
        if not isinstance(data, dict):
            return data
        name = _name(data.get("strategy", "active"))
        if name == EXACT and (given := [k for k in data if owners(STRATEGIES, k)]):
            raise ConfigError(f"strategy exact learns nothing: it takes no option {given[0]!r}")
        data = route(data, SLOTS, cls.model_fields) if name in STRATEGIES else data
        return route_options(data, cls.model_fields)

    @field_serializer("sim")
    def _sim_dict(self, sim: SimConfig) -> dict[str, Any]:
        return sim.to_dict()

    @property
    def exact(self) -> bool:
        """No learning: the exact model (``strategy = "exact"``)."""
        return self.strategy.name == EXACT

    def explore_config(self) -> ExploreConfig:
        return ExploreConfig(strategy=self.strategy, budget=self.budget, batch=self.batch,
                             model_class=self.model_class)


def check_keyboard(art: Artifact) -> Keyboard:
    """The keyboard of a keyboard artifact; ArtifactError for any other kind."""
    if art.kind != "keyboard":
        where = f"{art.path}: " if art.path else ""
        raise ArtifactError(f"{where}is a {art.kind} artifact, expected a keyboard artifact")
    return keyboard_stage.load(art)


class Learning:
    """One learning run as an iterator: each ``next`` does one batch of reaches.

    Iterate it to the end (``len(learning)`` batches), then call :meth:`artifact`.
    """

    def __init__(self, cfg: LearnConfig, keyboard_art: Artifact, *, rng: np.random.Generator,
                 seed: int | None = None) -> None:
        if cfg.exact:
            raise ConfigError("the exact model is not learned: use run() or exact_artifact()")
        self.cfg = cfg
        self.keyboard_art = keyboard_art
        self.keyboard = kb = check_keyboard(keyboard_art)
        check_keyboard_reachable(cfg.sim, kb)
        self.seed = seed
        self.world = World(kb, make_reacher(cfg.sim))
        self._starts: list[np.ndarray] = []
        self.exploration = Exploration(
            cfg.explore_config(), self._touch, kb.area, kb.config.match_threshold, rng
        )
        self.curve_reaches: list[int] = []
        self.curve_accuracy: list[float] = []

    def _touch(self, targets: np.ndarray, rng: np.random.Generator):
        landed, heard = self.world.touch(targets, rng)
        starts = getattr(self.world.reacher, "last_start_angles", None)
        if starts is not None:
            self._starts.append(np.asarray(starts, float).reshape(-1, 2))
        return landed, heard

    def __len__(self) -> int:
        return -(-int(self.cfg.budget) // int(self.cfg.batch))

    def __iter__(self) -> Iterator[int]:
        return self

    def __next__(self) -> int:
        step = next(self.exploration)
        n, every = step.n_reaches, self.cfg.curve_every
        if n // every > (n - len(step.targets)) // every or n >= self.cfg.budget:
            self.curve_reaches.append(n)
            self.curve_accuracy.append(scoring.accuracy(step.model, self.keyboard, CURVE_STEP))
        return n

    def selection(self) -> select.Selection | None:
        """Under ``auto``, the class chosen by cross-validation on the samples (None otherwise)."""
        if self.cfg.model_class.name != AUTO:
            return None
        ex, kb = self.exploration, self.keyboard
        rng = np.random.default_rng(np.random.SeedSequence(self._seed, spawn_key=(SELECT_KEY,)))
        return select.choose(ex.landed, ex.perceived, match_threshold=kb.config.match_threshold,
                             area=kb.area, rng=rng,
                             explored_with=ex.explored_with)

    @property
    def _seed(self) -> int:
        return 0 if self.seed is None else int(self.seed)

    def reliability(self, chosen: str | None = None):
        """The final model (of class ``chosen``, default the one explored with), calibrated, and
        its own estimate of how good it is, from its samples alone
        (:func:`kbcli.core.model.reliability.assess`: 5-fold cross-validation)."""
        ex, kb = self.exploration, self.keyboard
        name = ex.explorer if chosen is None else chosen
        model = ex.model
        if name != ex.explorer or select.explore_params(name):  # the final model's parameters
            model = fit_model(name, ex.landed, ex.perceived,
                              match_threshold=kb.config.match_threshold, area=kb.area,
                              targets=ex.targets, **set_options(self.cfg.model_class))
        rng = np.random.default_rng(np.random.SeedSequence(self._seed,
                                                           spawn_key=(RELIABILITY_KEY,)))
        return reliability.assess(model, ex.landed, ex.perceived, rng=rng)

    def artifact(self, on_phase: Callable[[str], None] | None = None) -> Artifact:
        """The ``model`` artifact (after the last batch); ``on_phase(text)`` is told each phase
        (model selection, calibration, scoring) as it starts."""
        ex = self.exploration
        if len(ex.targets) < self.cfg.budget:
            raise RuntimeError("learning is not finished: iterate to the end first")
        phase = on_phase or (lambda text: None)
        if self.cfg.model_class.name == AUTO:
            phase("choosing the model class (5-fold cross-validation of each)")
        sel = self.selection()
        model_class = self.cfg.model_class.name if sel is None else sel.chosen
        phase(f"cross-validating and calibrating the {model_class} model (5 folds)")
        model, rel = self.reliability(model_class)
        phase("scoring the model against the keyboard")
        pred, scores = self._scores(model)
        samples = {"actions": ex.targets, "landed": ex.landed, "perceived": ex.perceived}
        if self._starts:
            samples["start_angles"] = np.vstack(self._starts)
        origin, _ = grid_points(self.keyboard.area, EVAL_STEP)
        return Artifact(
            kind="model",
            config=model_config(self.cfg, self.keyboard.config.to_dict(),
                                None if sel is None else model_class),
            seed=self.seed,
            data={
                "samples": samples,
                "model": model.to_arrays(),
                "curve": {"reaches": np.asarray(self.curve_reaches, np.int64),
                          "accuracy": np.asarray(self.curve_accuracy, float)},
                "evaluation": {"predicted_keys": pred.astype(np.int16), "origin": origin,
                               "step": np.float64(EVAL_STEP)},
            },
            attrs={
                "strategy": self.cfg.strategy.name,
                "model_class": model_class,
                **({"model_selection": sel.to_dict()} if sel is not None else {}),
                "layout": self.keyboard.layout,
                "mode": self.cfg.sim.mode,
                "n_reaches": int(len(ex.targets)),
                "n_classes": int(model.n_classes),
                **({"n_boundary_lines": int(len(model.lines_))} if hasattr(model, "lines_")
                   else {}),
                "reach_sd_px": float(model.reach_sd_),
                **scores,
                "reliability": rel.to_dict(),
            },
            inputs={"keyboard": ref(self.keyboard_art)},
        )

    def _scores(self, model) -> tuple[np.ndarray, dict]:
        """The key ``model`` predicts in each :data:`EVAL_STEP` px cell, and its scores against
        the keyboard: ``accuracy``, ``boundary_error_px``, ``reaches_to_97`` and ``reaches_to_99``
        (:func:`reaches_to` on the learning curve)."""
        pred, true = scoring.key_maps(model, self.keyboard, EVAL_STEP)
        acc = scoring.accuracy_from_maps(pred, true)
        first = {level: reaches_to(level, np.asarray(self.curve_reaches, np.int64),
                                   np.asarray(self.curve_accuracy, float), acc,
                                   len(self.exploration.targets)) for level in LEVELS}
        return pred, {"accuracy": acc,
                      "boundary_error_px": scoring.boundary_error(pred, true, EVAL_STEP),
                      "reaches_to_97": first[0.97], "reaches_to_99": first[0.99]}


def model_config(cfg: LearnConfig, keyboard: dict, chosen: str | None = None) -> dict:
    """The config a ``model`` artifact records: ``cfg`` flat (parts by name, options beside them),
    the keyboard's config and the scoring grids; under ``auto``, ``model_class`` is the class
    ``chosen`` (the one that reads ``model/...``) and ``model_class_requested = "auto"``."""
    out = {**flat_view(cfg.to_dict(), (*SLOTS, "model_class")), "keyboard": keyboard, "curve_step": CURVE_STEP,
           "eval_step": EVAL_STEP}
    if chosen is not None:
        out.update(model_class=chosen, model_class_requested=AUTO)
    return out


def reaches_to(level: float, reaches: np.ndarray, accuracy: np.ndarray, final: float,
               budget: int) -> int | None:
    """The first learning-curve point (``reaches``, ``accuracy``) at or above ``level``; else the
    whole ``budget`` when the final model's accuracy ``final`` reaches it (the curve is the
    explorer's: the final model may be another class, or the same with its final parameters);
    else None."""
    hit = np.flatnonzero(np.asarray(accuracy, float) >= level)
    if len(hit):
        return int(np.asarray(reaches)[hit[0]])
    return int(budget) if final >= level else None


def learn(cfg: LearnConfig, keyboard_art: Artifact, *, rng: np.random.Generator,
          seed: int | None = None) -> Learning:
    """Start a learning run: ArtifactError if ``keyboard_art`` is not a keyboard artifact,
    OutOfReachError (naming the keys) if its working area is not within the arm's reach."""
    return Learning(cfg, keyboard_art, rng=rng, seed=seed)


def run(cfg: LearnConfig, keyboard_art: Artifact, *, rng: np.random.Generator,
        seed: int | None = None) -> Artifact:
    """Learn a model (or build the exact one) and return its ``model`` artifact.

    ``rng`` drives the exploration and the arm's noise; ``seed`` is recorded in the artifact
    (``rng`` should be ``default_rng(seed)``).
    """
    if cfg.exact:
        kb = check_keyboard(keyboard_art)
        check_keyboard_reachable(cfg.sim, kb)
        return exact_artifact(keyboard_art)
    learning = learn(cfg, keyboard_art, rng=rng, seed=seed)
    for _ in learning:
        pass
    return learning.artifact()
