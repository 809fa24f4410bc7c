"""Model classes of the instrument: one registry, one interface (``kbcli learn --model-class``).

A model class is a learned model of p(sound | action) (paper Sect. III-A) that every other part of
kbcli uses through one interface, whatever the class:

- ``fit(actions (n, 2), perceived (n, D), targets=None) -> self`` (NaN rows are silence);
- ``predict_proba(points) -> (n, C)``, ``predict_class(points) -> (n,)``;
- ``sample_actions(cls, n, rng) -> (n, 2)``: draws from p(action | sound) (Algorithm 2, line 3);
- ``classify(perceived) -> (n,)``: Eq. 2 matching (0 silence, -1 unknown);
- ``raster(step)``: :class:`~kbcli.core.model.base.ProbabilityRaster` over the working area;
- ``boundary_sites(step, extend, phase) -> {"points", "width", ...}``: the boundaries between
  sounds and the width (px) of the band each could lie in, which ``active`` exploration bisects;
- attributes ``class_features_``, ``match_threshold``, ``area``, ``n_classes``, ``reach_sd_``;
- ``to_arrays() -> dict`` and ``from_arrays(dict)``: storage as plain arrays, never pickle.

Registered in :data:`MODEL_CLASSES`: ``lines`` (:class:`~kbcli.core.model.lines.LearnedModel`),
``svc`` (:class:`~kbcli.core.model.svc.SVCModel`), ``forest``, ``forest-xy`` and ``knn``
(:mod:`kbcli.core.model.classifiers`), each a scikit-learn estimator deriving from
:class:`~kbcli.core.model.pairwise.ModelBase`; and ``exact``
(:class:`~kbcli.core.model.base.ExactModel`), the keyboard's own geometry, not learned, whose
``exact_map`` attribute is True (callers ask the attribute, never the class or its name).

Adding a class is registering a :class:`ModelClass` with ``MODEL_CLASSES.register(name, ...)``: a
loader of the estimator class, which takes ``match_threshold``, ``area`` and its own keyword
parameters and has ``from_arrays``. Fitting goes through :func:`fit_model`, the one place to hook
in anything that wraps every class.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, PlainSerializer

from kbcli.core.options import Options, owners, parse_part, route
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: The class of model artifacts that do not name one (schema 1: every learned model was ``lines``).
DEFAULT_MODEL_CLASS = "lines"
#: The class (and the ``learn`` strategy) of the keyboard's own geometry.
EXACT = "exact"
#: Not a class: ``kbcli learn --model-class auto`` chooses one by cross-validation on the samples
#: (:mod:`kbcli.core.model.select`).
AUTO = "auto"
_COMMON = ("match_threshold", "area")


@dataclass(frozen=True)
class ModelClass:
    """A registered model class.

    Attributes
    ----------
    estimator : callable
        ``estimator() -> type``: the class (imported on first use: scikit-learn's SVC is slow to
        import).
    learned : bool
        Fitted to exploration samples (``fit``, ``to_arrays`` / ``from_arrays``); False for the
        exact model, built from the keyboard.
    auto : int or None
        Its place in ``--model-class auto``'s order of preference (:func:`ranked`; None: ``auto``
        never chooses it).
    explores : int or None
        Its place among the classes ``auto`` explores with (the first is the one it starts with;
        None: ``auto`` never explores with it).
    explore_params : mapping
        Its parameters while it is refitted during an exploration and ``auto``'s
        cross-validation, where they differ from the final model's (a lighter forest).
    """

    estimator: Callable[[], type]
    learned: bool = True
    auto: int | None = None
    explores: int | None = None
    explore_params: Mapping[str, Any] = field(default_factory=dict)

    @property
    def params(self) -> tuple[str, ...]:
        """The class's own keyword parameters (besides ``match_threshold`` and ``area``)."""
        if not self.learned:
            return ()
        return tuple(p for p in self.estimator()._get_param_names() if p not in _COMMON)

    def load(self, arrays: Mapping | None, keyboard: Any = None):
        """The stored model: ``from_arrays(arrays)`` of a learned class, the exact model of
        ``keyboard`` otherwise."""
        if self.learned:
            return self.estimator().from_arrays(arrays)
        return self.estimator()(keyboard)


MODEL_CLASSES: Registry[ModelClass] = Registry("model class")


def _import(module: str, name: str) -> type:
    """The class ``name`` of ``module``, imported on first use (a :class:`ModelClass` loader)."""
    return getattr(importlib.import_module(module), name)


_MODEL = "kbcli.core.model."
_lines = partial(_import, _MODEL + "lines", "LearnedModel")
_svc = partial(_import, _MODEL + "svc", "SVCModel")
_forest = partial(_import, _MODEL + "classifiers", "ForestModel")
_forest_xy = partial(_import, _MODEL + "classifiers", "ForestXYModel")
_knn = partial(_import, _MODEL + "classifiers", "KNNModel")
_exact = partial(_import, _MODEL + "base", "ExactModel")

#: Parameters of a forest while it is refitted after every batch of an exploration and by
#: ``auto``'s cross-validation: 60 trees instead of the final model's 120 (twice as fast a fit).
_LIGHT_FOREST = {"n_estimators": 60}



def _options(module: str, name: str) -> dict[str, Any]:
    """The traits of a class whose options are ``name`` of ``module`` (imported on first use)."""
    return {"options": partial(_import, _MODEL + module, name)}


MODEL_CLASSES.register("lines", ModelClass(_lines, auto=3), traits=_options("lines", "LinesOptions"),
                       summary="straight key edges shared across keys (polygon keys)")
MODEL_CLASSES.register("svc", ModelClass(_svc, auto=2, explores=1), summary="scikit-learn SVMs "
                       "per pair of neighbouring sounds, linear or RBF (any key shape)",
                       traits=_options("svc", "SVCOptions"))
MODEL_CLASSES.register("forest", ModelClass(_forest, auto=0, explores=0,
                                            explore_params=_LIGHT_FOREST),
                       summary="scikit-learn random forest on the coordinates and oblique "
                       "projections (any key shape)", traits=_options("classifiers", "ForestOptions"))
MODEL_CLASSES.register("forest-xy", ModelClass(_forest_xy, auto=1, explore_params=_LIGHT_FOREST),
                       summary="scikit-learn random forest on the two coordinates only (keys "
                       "with horizontal and vertical edges)",
                       traits=_options("classifiers", "ForestXYOptions"))
MODEL_CLASSES.register("knn", ModelClass(_knn, auto=4), summary="scikit-learn k nearest "
                       "samples, distance-weighted votes (any key shape)",
                       traits=_options("classifiers", "KNNOptions"))
MODEL_CLASSES.register(EXACT, ModelClass(_exact, learned=False),
                       summary="the keyboard's own geometry (not learned)")


def learned_classes() -> tuple[str, ...]:
    """The model classes fitted to exploration samples (valid ``--model-class`` values)."""
    return tuple(n for n, mc in MODEL_CLASSES.items() if mc.learned)


def ranked(capability: str) -> tuple[str, ...]:
    """The learned classes that declare a place in ``capability`` (``"auto"``, ``"explores"``:
    :class:`ModelClass`), in that order (ties by name)."""
    places = [(getattr(mc, capability), n) for n, mc in MODEL_CLASSES.items()
              if mc.learned and getattr(mc, capability) is not None]
    return tuple(n for _, n in sorted(places))


def check_learned(name: str) -> str:
    """``name`` when it is a learned model class; ConfigError listing them otherwise."""
    if not MODEL_CLASSES.get(name).learned:
        raise ConfigError(f"model class {name!r} is not learned from samples; valid: "
                          f"{', '.join(learned_classes())}")
    return name


def check_choice(name: str) -> str:
    """``name`` when it is ``auto`` or a learned model class; ConfigError listing them otherwise."""
    if name == AUTO:
        return name
    if name not in MODEL_CLASSES:
        raise ConfigError(f"unknown model class {name!r}; valid: "
                          f"{', '.join((AUTO, *learned_classes()))}")
    return check_learned(name)


def _chosen(value: Any, default: str) -> Any:
    """The class a ``model_class`` value names (a name, a table or an :class:`Options`)."""
    if isinstance(value, Options):
        return value.name
    return value.get("name", default) if isinstance(value, Mapping) else value


def _auto_refuses(key: str) -> ConfigError:
    """``auto`` refusing the option ``key`` (as :func:`kbcli.core.options.refusal` words it)."""
    reason = (f"model class auto takes no option {key!r}: it fits each class with its defaults "
              f"(name a class that takes it: {', '.join(owners(MODEL_CLASSES, key))})")
    err = ConfigError(reason)
    err.option, err.reason = key, reason
    return err


def parse_choice(value: Any, default: str = AUTO) -> Options:
    """``auto`` (no option) or a learned class with its own options, from a name, a table
    (``{"name": "forest", "n_estimators": 200}``) or an :class:`Options`; an option the class
    does not take is refused by it (:func:`kbcli.core.options.parse_part`)."""
    if check_choice(_chosen(value, default)) != AUTO:
        return parse_part(MODEL_CLASSES, value, default)
    given = value.own() if isinstance(value, Options) else value if isinstance(value, Mapping) else {}
    if extra := [k for k in given if k != "name"]:
        raise _auto_refuses(extra[0])
    return Options(name=AUTO)


def set_options(options: Options) -> dict[str, Any]:
    """The options of a class a user set (its defaults left out): what a model records and what
    its fits are given (over :attr:`ModelClass.explore_params` while exploring)."""
    return {k: v for k, v in options.own().items() if k in options.model_fields_set}


def _recorded(options: Options) -> Any:
    given = set_options(options)
    return {"name": options.name, **given} if given else options.name


def model_choice(default: str) -> Any:
    """The type of a config field choosing ``auto`` or a learned class with its options (default
    ``default``), written as the class's name when no option is set (the config of a model learned
    with the defaults is the one it always was)."""
    def parse(v: Any) -> Options:
        return parse_choice(v, default)

    return Annotated[Options, BeforeValidator(parse), PlainSerializer(_recorded)]


def route_options(data: dict, own: Iterable[str], default: str = AUTO) -> dict:
    """``data`` with the class's options given flat (``n_estimators = 200`` beside
    ``model_class = "forest"``) moved into its ``model_class`` table (``auto`` refuses them)."""
    flat = [k for k in data if k not in set(own) and owners(MODEL_CLASSES, k)]
    if not flat:
        return data
    if check_choice(_chosen(data.get("model_class", default), default)) == AUTO:
        raise _auto_refuses(flat[0])
    return route(data, {"model_class": (MODEL_CLASSES, default)}, own)


def model_class_of(config: Mapping) -> str:
    """The model class a model artifact's config names: ``exact`` for the exact model (its
    ``strategy``), else its ``model_class`` (absent in schema 1: ``lines``)."""
    if config.get("strategy") == EXACT:
        return EXACT
    name = config.get("model_class")
    return DEFAULT_MODEL_CLASS if name is None else name


def make_model(name: str, *, match_threshold: float, area: tuple[float, float, float, float],
               **params: Any):
    """An unfitted model of the learned class ``name``.

    Raises
    ------
    ConfigError
        For an unknown or not learned class, or a parameter the class does not take.
    """
    mc = MODEL_CLASSES.get(check_learned(name))
    unknown = sorted(set(params) - set(mc.params))
    if unknown:
        raise ConfigError(f"model class {name} takes no parameter {unknown[0]!r}; valid: "
                          f"{', '.join(mc.params) or 'none'}")
    return mc.estimator()(match_threshold=float(match_threshold),
                          area=tuple(float(v) for v in area), **params)


def fit_model(name: str, actions: np.ndarray, perceived: np.ndarray, *, match_threshold: float,
              area: tuple[float, float, float, float], targets: np.ndarray | None = None,
              **params: Any):
    """A model of class ``name`` fitted to exploration samples (the one entry every caller uses)."""
    model = make_model(name, match_threshold=match_threshold, area=area, **params)
    return model.fit(actions, perceived, targets=targets)


def model_from_arrays(d: dict, name: str | None = None):
    """Rebuild a stored model of the learned class ``name`` (default ``lines``) from its arrays."""
    return MODEL_CLASSES.get(check_learned(DEFAULT_MODEL_CLASS if name is None else name)).load(d)
