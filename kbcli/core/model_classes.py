"""Model classes of the instrument: one registry, one interface (``kbcli learn --model-class``).

A model class is a learned model of p(sound | action) (paper Sect. III-A) that every other part of
kbcli (the exploration, the adapter, its strategies, the play loop, the plots) uses through one
interface, whatever the class:

- ``fit(actions (n, 2), perceived (n, D), targets=None) -> self``: learn from exploration samples
  (where the finger landed, what was heard; NaN rows are silence);
- ``predict_proba(points) -> (n, C)``, ``predict_class(points) -> (n,)``;
- ``sample_actions(cls, n, rng) -> (n, 2)``: draws from p(action | sound) (Algorithm 2, line 3);
- ``classify(perceived) -> (n,)``: Eq. 2 matching (0 silence, -1 unknown);
- ``raster(step)``: :class:`~kbcli.core.model.ProbabilityRaster` over the working area;
- ``boundary_sites(step, extend, phase) -> {"points", "width", ...}``: where the model places the
  boundaries between sounds and how wide the band is that each could lie in (px): the predictive
  uncertainty that the ``active`` exploration bisects;
- attributes ``class_features_``, ``match_threshold``, ``area``, ``n_classes``, ``reach_sd_``;
- ``to_arrays() -> dict`` and ``from_arrays(dict)``: storage as plain arrays, never pickle.

Registered (:data:`MODEL_CLASSES`):

``lines`` (:class:`~kbcli.core.learned.LearnedModel`)
    Keys bounded by straight lines shared across keys: exact and sample-efficient for polygon keys
    (grid, hex, piano, polygons); it cannot bend around a round pad.
``svc`` (:class:`~kbcli.core.svc_model.SVCModel`)
    One scikit-learn support-vector machine per pair of neighbouring sounds (linear where a
    straight line separates the pair's samples, RBF elsewhere), probabilities from the margin: any
    key shape, curved boundaries included.

Adding a class is adding an entry with :func:`register`: a factory taking ``match_threshold``,
``area`` and the class's own keyword parameters, and a ``from_arrays``. Fitting goes through
:func:`fit_model` (``fit(actions, perceived)`` for every class), so anything that wraps every
class (a reliability estimate, a calibration) has one place to hook in.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from kbcli.errors import ConfigError


@dataclass(frozen=True)
class ModelClass:
    """A registered model class: how to make one and how to rebuild a stored one."""

    name: str
    summary: str
    factory: Callable[..., Any]
    from_arrays: Callable[[dict], Any]
    params: tuple[str, ...] = ()


MODEL_CLASSES: dict[str, ModelClass] = {}
#: The class of model artifacts that do not name one (schema 1: every learned model was ``lines``).
DEFAULT_MODEL_CLASS = "lines"


def register(name: str, summary: str, factory: Callable[..., Any],
             from_arrays: Callable[[dict], Any], params: tuple[str, ...] = ()) -> None:
    """Add a model class to :data:`MODEL_CLASSES`."""
    MODEL_CLASSES[name] = ModelClass(name, summary, factory, from_arrays, params)


def get_model_class(name: str) -> ModelClass:
    """The model class called ``name``; ConfigError listing the valid ones otherwise."""
    try:
        return MODEL_CLASSES[name]
    except (KeyError, TypeError):
        raise ConfigError(
            f"unknown model class {name!r}; valid: {', '.join(MODEL_CLASSES)}") from None


def make_model(name: str, *, match_threshold: float, area: tuple[float, float, float, float],
               **params: Any):
    """An unfitted model of class ``name``.

    Raises
    ------
    ConfigError
        For an unknown class or a parameter the class does not take.
    """
    mc = get_model_class(name)
    unknown = sorted(set(params) - set(mc.params))
    if unknown:
        raise ConfigError(f"model class {name} takes no parameter {unknown[0]!r}; valid: "
                          f"{', '.join(mc.params) or 'none'}")
    return mc.factory(match_threshold=float(match_threshold),
                      area=tuple(float(v) for v in area), **params)


def fit_model(name: str, actions: np.ndarray, perceived: np.ndarray, *, match_threshold: float,
              area: tuple[float, float, float, float], targets: np.ndarray | None = None,
              **params: Any):
    """A model of class ``name`` fitted to exploration samples (the one entry every caller uses)."""
    model = make_model(name, match_threshold=match_threshold, area=area, **params)
    return model.fit(actions, perceived, targets=targets)


def model_from_arrays(d: dict, name: str | None = None):
    """Rebuild a stored model of class ``name`` (default ``lines``) from its arrays."""
    return get_model_class(DEFAULT_MODEL_CLASS if name is None else name).from_arrays(d)


def _lines(**kw: Any):
    from kbcli.core.learned import LearnedModel

    return LearnedModel(**kw)


def _lines_from(d: dict):
    from kbcli.core.learned import LearnedModel

    return LearnedModel.from_arrays(d)


def _svc(**kw: Any):
    from kbcli.core.svc_model import SVCModel

    return SVCModel(**kw)


def _svc_from(d: dict):
    from kbcli.core.svc_model import SVCModel

    return SVCModel.from_arrays(d)


register("lines", "straight key edges shared across keys (polygon keys)", _lines, _lines_from,
         ("n_neighbors", "min_sd", "max_sd", "extrapolation", "merge_angle", "merge_offset",
          "piece_reach", "sd_scale", "noise_sd", "floor", "noise_tol"))
register("svc", "scikit-learn SVMs per pair of neighbouring sounds, linear or RBF (any key shape)",
         _svc, _svc_from, ("length_scale", "C", "local_radius", "n_neighbors", "linear_pairs"))
