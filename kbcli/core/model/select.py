"""``--model-class auto``: the model class chosen by its own cross-validated score.

No class is best on every layout, and the robot must not be told the layout, so it asks its own
samples: with ``K``-fold cross-validation (the same folds for every candidate) each candidate class
is scored by its held-out mislabel rate, every held-out touch weighted by the area it stands for
(:func:`kbcli.core.model.heldout.area_weights`). The choice is a sequence of paired tests
(:func:`prefer`): the classes are taken in the order they declare (``ModelClass.auto``,
:func:`kbcli.core.model.classes.ranked`), and a class replaces the one kept so far only when its
rate is lower by more than :data:`SWITCH_Z` standard errors of the paired, area-weighted
difference (what it chose on each layout: ``docs/design-notes.md``, Model classes).

While exploring, under ``auto`` the model is of the first class that declares it explores
(``ModelClass.explores``), re-chosen every :data:`RESELECT` reaches among those by the same
cross-validation (:func:`explore_choice`). The final model is refitted with the chosen class on
every sample (:func:`choose`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.core.config import Record
from kbcli.core.model.classes import AUTO, MODEL_CLASSES, fit_model, learned_classes, ranked
from kbcli.core.model.heldout import area_weights, class_map, fold_ids, held_out_probs
from kbcli.core.model.reliability import FOLDS
from kbcli.errors import ConfigError

#: A class replaces the one kept so far when its held-out mislabel rate is lower by more than
#: this many standard errors of the paired difference.
SWITCH_Z = 2.0
#: Reaches between two choices of the class ``auto`` explores with (a choice takes 2-3 s on 2
#: cores at 200-800 samples: every 100 reaches doubled the time of a learn run of 800).
RESELECT = 200


@dataclass(frozen=True)
class Selection(Record):
    """The class ``auto`` chose, and why.

    Attributes
    ----------
    chosen : str
    explored_with : str
        The class the exploration ran with.
    cv_error : dict
        Each candidate's area-weighted held-out mislabel rate.
    folds : int
    """

    chosen: str
    explored_with: str
    cv_error: dict
    folds: int

    def summary(self) -> str:
        """One line: the choice and every candidate's score."""
        scores = ", ".join(f"{k} {100 * v:.2f} %" for k, v in
                           sorted(self.cv_error.items(), key=lambda kv: kv[1]))
        return (f"model class: {self.chosen}, chosen by {self.folds}-fold cross-validation on its "
                f"samples (held-out mislabel rate, area-weighted: {scores})")


def explore_class(name: str) -> str:
    """The class an exploration with model class ``name`` refits while it explores (first)."""
    return ranked("explores")[0] if name == AUTO else name


def explore_params(name: str) -> dict:
    """Keyword parameters of class ``name`` while it is refitted during an exploration."""
    return dict(MODEL_CLASSES.get(name).explore_params)


def explore_choice(actions: np.ndarray, perceived: np.ndarray, *, match_threshold: float,
                   area: tuple[float, float, float, float],
                   candidates: tuple[str, ...] | None = None, folds: int = FOLDS) -> str:
    """The class ``auto`` explores with next: the candidate (default: the classes that declare
    they explore) :func:`prefer` keeps on the held-out mislabels of the samples so far (each class
    with its :func:`explore_params`).

    The folds come from a generator seeded with the number of samples, not from the
    exploration's: choosing draws nothing from it, so the reaches of every other class are
    unchanged and the choice is the same whoever asks.
    """
    candidates = ranked("explores") if candidates is None else tuple(candidates)
    wrong, w = held_out_wrong(candidates, actions, perceived,
                              match_threshold=match_threshold, area=area,
                              rng=np.random.default_rng(len(actions)), folds=folds,
                              params={n: explore_params(n) for n in candidates})
    return prefer(candidates, wrong, w)


def paired_z(worse: np.ndarray, better: np.ndarray, w: np.ndarray) -> float:
    """How many standard errors ``better``'s weighted mislabel rate is below ``worse``'s.

    Parameters
    ----------
    worse, better : (n,) ndarrays
        1 where a held-out touch was mislabelled, else 0 (the same touches for both).
    w : (n,) ndarray
        Weights (0: the touch does not count).

    Returns
    -------
    float
        ``D / se(D)``, D the weighted mean of ``worse - better``; 0 when they never differ.
    """
    d = np.asarray(worse, float) - np.asarray(better, float)
    total = float(w.sum())
    if total <= 0:
        return 0.0
    mean = float((w * d).sum()) / total
    se = float(np.sqrt((w ** 2 * (d - mean) ** 2).sum())) / total
    return mean / se if se > 0 else 0.0


def prefer(names: tuple[str, ...], wrong: dict[str, np.ndarray], w: np.ndarray,
           z: float = SWITCH_Z) -> str:
    """The class kept after testing ``names`` in order: each replaces the one kept so far only
    when :func:`paired_z` of the two is above ``z``."""
    kept = names[0]
    for name in names[1:]:
        if paired_z(wrong[kept], wrong[name], w) > z:
            kept = name
    return kept


def held_out_wrong(names: tuple[str, ...], actions: np.ndarray, perceived: np.ndarray, *,
                   match_threshold: float, area: tuple[float, float, float, float],
                   rng: np.random.Generator, folds: int = FOLDS, params: dict | None = None
                   ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Which samples each class mislabels when they are held out (the same folds for all).

    Parameters
    ----------
    names : tuple of str
        Learned model classes.
    actions, perceived : (n, 2), (n, D) ndarrays
        The samples.
    rng : numpy.random.Generator
        Assigns samples to folds.
    params : dict, optional
        name -> keyword parameters of that class (default: its defaults).

    Returns
    -------
    wrong : dict
        name -> (n,) 1 where the held-out sample's most probable class is not its own, else 0.
    weights : (n,) ndarray
        The area each sample stands for (0 for a sample heard as no known sound).
    """
    x = np.asarray(actions, float).reshape(-1, 2)
    s = np.asarray(perceived, float).reshape(len(x), -1)
    k = int(min(folds, len(x)))
    fold = fold_ids(len(x), k, rng)
    out, weights = {}, np.zeros(len(x))
    for name in names:
        own = (params or {}).get(name, {})
        full = fit_model(name, x, s, match_threshold=match_threshold, area=area, **own)
        labels = full.classify(s)
        weights = area_weights(x) * (labels >= 0)
        wrong = np.zeros(len(x))
        for f in range(k):
            test = fold == f
            if test.all() or not test.any():
                continue
            m = fit_model(name, x[~test], s[~test], match_threshold=match_threshold, area=area,
                          **own)
            cmap = class_map(m.class_features_, full.class_features_, match_threshold)
            p = held_out_probs(m, x[test], cmap, full.n_classes)
            wrong[test] = p.argmax(axis=1) != labels[test]
        out[name] = wrong
    return out, weights


def cv_errors(names: tuple[str, ...], actions: np.ndarray, perceived: np.ndarray, *,
              match_threshold: float, area: tuple[float, float, float, float],
              rng: np.random.Generator, folds: int = FOLDS) -> dict[str, float]:
    """Area-weighted held-out mislabel rate of each class (:func:`held_out_wrong`).

    Returns
    -------
    dict
        name -> rate in [0, 1].
    """
    wrong, w = held_out_wrong(names, actions, perceived, match_threshold=match_threshold,
                              area=area, rng=rng, folds=folds)
    total = max(float(w.sum()), 1e-300)
    return {name: float((v * w).sum() / total) for name, v in wrong.items()}


def choose(actions: np.ndarray, perceived: np.ndarray, *, match_threshold: float,
           area: tuple[float, float, float, float], rng: np.random.Generator,
           explored_with: str | None = None, candidates: tuple[str, ...] | None = None,
           folds: int = FOLDS) -> Selection:
    """The candidate class (default: the classes that declare a place in ``auto``'s order)
    :func:`prefer` keeps on the samples' held-out mislabels (each class cross-validated with its
    :func:`explore_params`: a lighter forest stands for the final one); ``explored_with``
    defaults to the class ``auto`` starts exploring with.

    Raises
    ------
    ConfigError
        If a candidate is not a learned model class.
    """
    candidates = ranked("auto") if candidates is None else tuple(candidates)
    explored_with = explore_class(AUTO) if explored_with is None else explored_with
    valid = learned_classes()
    for name in candidates:
        if name not in valid:
            raise ConfigError(f"model class {name!r} is not learned from samples; valid: "
                              f"{', '.join(valid)}")
    wrong, w = held_out_wrong(candidates, actions, perceived,
                              match_threshold=match_threshold, area=area, rng=rng, folds=folds,
                              params={n: explore_params(n) for n in candidates})
    total = max(float(w.sum()), 1e-300)
    err = {name: float((v * w).sum() / total) for name, v in wrong.items()}
    return Selection(chosen=prefer(candidates, wrong, w), explored_with=explored_with, cv_error=err,
                     folds=int(min(folds, len(np.asarray(actions).reshape(-1, 2)))))


__all__ = ["RESELECT", "SWITCH_Z", "Selection", "choose", "cv_errors", "explore_choice", "explore_class",
           "explore_params", "held_out_wrong",
           "paired_z", "prefer"]
