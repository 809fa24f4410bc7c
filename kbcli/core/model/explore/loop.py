"""The exploration loop: propose, touch, refit, as an iterator that yields one batch at a time, so
a caller can stop early, record a learning curve or draw a progress bar without the loop knowing.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from kbcli.core.model.classes import AUTO, fit_model, set_options
from kbcli.core.model.explore.base import STRATEGIES, Covering, ExploreConfig, check_cover
from kbcli.core.model.explore.cover import uniform
from kbcli.core.model.select import RESELECT, explore_choice, explore_class, explore_params


@dataclass
class ExploreStep:
    """One batch of reaches, and the exploration it belongs to.

    Attributes
    ----------
    n_reaches : int
        Reaches done so far (this batch included).
    targets, landed : (k, 2) ndarray
        This batch's targets and where the finger landed.
    perceived : (k, D) ndarray
        What was heard (NaN rows: silence).
    """

    n_reaches: int
    targets: np.ndarray
    landed: np.ndarray
    perceived: np.ndarray
    exploration: Exploration

    @property
    def model(self):
        """The model fitted to every sample so far (valid until the next step)."""
        return self.exploration.model


Touch = Callable[[np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray]]


class Exploration:
    """Learn the instrument by reaching: an iterator of :class:`ExploreStep` over batches
    (propose, touch, refit) until ``cfg.budget`` reaches are done; the model is refitted only
    when a strategy or the caller asks for it.

    ``touch(targets (k, 2), rng) -> (landed (k, 2), perceived (k, D))`` is the world; targets are
    chosen in the working ``area``; ``match_threshold`` tells sounds apart (Eq. 2).

    Attributes
    ----------
    targets, landed : (n, 2) ndarray
        Every reach so far.
    perceived : (n, D) ndarray
        Every sound heard so far.
    explorer : str
        The model class refitted now (under ``auto`` re-chosen every
        :data:`~kbcli.core.model.select.RESELECT` reaches).
    explorers : list of (int, str)
        Each class explored with and the number of reaches from which it was.
    """

    def __init__(self, cfg: ExploreConfig, touch: Touch, area: tuple[float, float, float, float],
                 match_threshold: float, rng: np.random.Generator) -> None:
        self.area = tuple(float(v) for v in area)
        if isinstance(cfg.strategy, Covering):  # it reaches around its samples
            check_cover(self.area, cfg.strategy.explore_radius)
        self.cfg = cfg
        self.touch = touch
        self.match_threshold = match_threshold
        self.rng = rng
        self.strategy = STRATEGIES.get(cfg.strategy.name)
        self.targets = np.empty((0, 2))
        self.landed = np.empty((0, 2))
        self.perceived = np.empty((0, 0))
        self._model = None
        self._plan = np.empty((0, 2))
        self.explorer = explore_class(cfg.model_class.name)
        self.explorers = [(0, self.explorer)]

    @property
    def model(self):
        """The model (of class :attr:`explorer`, with :func:`kbcli.core.model.select.explore_params`)
        fitted to every sample so far (None before the first reach)."""
        if len(self.landed) == 0:
            return None
        if self._model is None:
            own = set_options(self.cfg.model_class) if self.explorer == self.cfg.model_class.name \
                else {}
            self._model = fit_model(self.explorer, self.landed, self.perceived,
                                    match_threshold=self.match_threshold, area=self.area,
                                    targets=self.targets, **{**explore_params(self.explorer), **own})
        return self._model

    @property
    def explored_with(self) -> str:
        """The classes explored with, in words (e.g. ``forest, svc from 200 reaches``)."""
        return ", ".join(c if n == 0 else f"{c} from {n} reaches" for n, c in self.explorers)

    def _reselect(self, before: int) -> None:
        """Under ``auto``: re-choose :attr:`explorer` when the last batch (from ``before``
        reaches) reached a multiple of :data:`~kbcli.core.model.select.RESELECT` before the budget and two
        classes or more (silence among them) were heard (eagerly, whoever asks for the model when)."""
        n = len(self.landed)
        if (self.cfg.model_class.name != AUTO or n // RESELECT == before // RESELECT
                or n >= self.cfg.budget):
            return
        silent = np.isnan(self.perceived).all(axis=1)
        if len(np.unique(self.perceived[~silent], axis=0)) + bool(silent.any()) < 2:
            return
        name = explore_choice(self.landed, self.perceived, match_threshold=self.match_threshold,
                              area=self.area)
        if name != self.explorer:
            self.explorer = name
            self.explorers.append((n, name))

    def __iter__(self) -> Iterator[ExploreStep]:
        return self

    def __next__(self) -> ExploreStep:
        done = len(self.targets)
        if done >= self.cfg.budget:
            raise StopIteration
        k = min(self.cfg.batch, self.cfg.budget - done)
        if len(self._plan) == 0:
            self._plan = np.asarray(self.strategy(self, k, self.rng), float).reshape(-1, 2)
        t, self._plan = self._plan[:k], self._plan[k:]
        if len(t) < k:  # a strategy may run short of candidates: top up uniformly
            t = np.vstack([t, uniform(self.area, k - len(t), self.rng)])
        landed, heard = self.touch(t, self.rng)
        heard = np.asarray(heard, float).reshape(len(t), -1)
        self.targets = np.vstack([self.targets, t])
        self.landed = np.vstack([self.landed, landed])
        self.perceived = heard if done == 0 else np.vstack([self.perceived, heard])
        self._model = None
        self._reselect(done)
        return ExploreStep(len(self.targets), t, landed, heard, self)
