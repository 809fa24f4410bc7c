"""Exploration strategies: where to reach next to learn the instrument model (paper ref. [11]).

The robot learns p(sound, action) by touching the pad and listening. A strategy proposes the next
reach targets from what has been heard so far; :class:`Exploration` runs the loop (propose, touch,
refit) as an iterator that yields one batch at a time, so a caller can stop early, record a
learning curve or draw a progress bar without the loop knowing.

Strategies (registry :data:`STRATEGIES`, read with ``STRATEGIES.get(name)``; one signature, see
:data:`Strategy`):

``active``
    1. *Cover.* First a hexagonal lattice of spacing ``explore_radius * sqrt(3)`` (randomly shifted
       and turned, visited in farthest-point order), whose covering radius is ``explore_radius``;
       then, while some point of the working area is further than ``explore_radius`` from every
       landing (near the area's border), the furthest such point. A sound region nobody has
       heard holds an empty disc, so covering to radius r finds every region that contains a disc
       of radius r (a 50 px key holds one of 25 px), with about area / (2.6 r^2) reaches, about
       120 on the default pad, fewer and more even than random reaches need.
    2. *Bisect the widest boundary band.* Every model class (:mod:`kbcli.core.model.classes`)
       reports its predictive uncertainty as ``boundary_sites``: points on the boundaries it
       predicts between sounds, each with the width (px) of the band the boundary could lie in
       there, where the model cannot tell which sound an action makes (the paper's confusion
       factor, Sect. III-E: p(i | a) is neither 0 nor 1 there). ``lines``
       (:mod:`kbcli.core.model.lines`) places each boundary on a straight line that must pass between
       the samples heard on either side, the band between their hulls, with sites every 1 px along
       every boundary piece (and 25 px past its ends); ``svc`` (:mod:`kbcli.core.model.svc`) puts
       its sites where its machines change sign, the band between the nearest samples of either
       sound. The next target is the site with the widest band (capped at twice the distance to
       the nearest landing: a reach already made there said what it could). A batch is chosen
       greedily: after a pick of width w every site's width is capped at w / 2 + its distance to
       the pick.

    Why: the misclassified area along a boundary is its band width integrated along it, so the
    most useful reach is where the band is widest; a reach in the middle of the band lands on one
    side or the other and halves the band there (bisection), and because one line is fitted to all
    the samples along an edge (and along edges that continue each other, across keys), a few
    bisections at the ends of a long edge pin it down everywhere. Random reaches spend most of the
    budget inside regions whose sound is already known; the active rule reaches 99 % accuracy on
    the default keyboard in about a quarter of the reaches random needs (``kbcli bench learn``).

``balanced``
    Boundary seeking and coverage weighed in one greedy rule (:func:`balanced_strategy`): a coarse
    cover first, then the widest gap, a boundary band or an unexplored hole, whichever is wider.

``random``
    Targets uniform over the working area: the baseline.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
from pydantic import AfterValidator
from scipy.spatial import cKDTree

from kbcli.core.config import Config, Count, Name, Positive
from kbcli.core.model.classes import AUTO, DEFAULT_MODEL_CLASS, check_choice, fit_model
from kbcli.core.model.select import RESELECT, explore_choice, explore_class, explore_params
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: Most candidate points the cover of the working area may take (``active`` and ``balanced`` grid
#: it every ``explore_radius / 5`` px): a radius so small that it needs more is refused before any
#: reach (``--explore-radius 1e-6`` would allocate without bound).
MAX_COVER_POINTS = 1_000_000


def check_cover(area: tuple, explore_radius: float) -> None:
    """ConfigError when covering ``area`` to ``explore_radius`` takes more than
    :data:`MAX_COVER_POINTS` candidate points, naming the smallest radius that fits."""
    x0, y0, x1, y1 = area
    cells = (x1 - x0) * (y1 - y0)
    points = cells / (explore_radius / 5) ** 2
    if points > MAX_COVER_POINTS:
        least = 5 * float(np.sqrt(cells / MAX_COVER_POINTS))
        raise ConfigError(f"explore_radius {explore_radius:g} px: covering the working area would "
                          f"take {points:,.0f} candidate points, more than {MAX_COVER_POINTS:,}; "
                          f"use at least {least:.2g} px")

#: A strategy: ``(exploration, n, rng) -> (k, 2)`` targets inside ``exploration.area``, usually
#: k = n; more is a plan the exploration carries out over the next batches. It may read
#: ``exploration.targets``, ``.landed``, ``.perceived``, ``.cfg`` and ``.model`` (fitted on demand).
Strategy = Callable[["Exploration", int, np.random.Generator], np.ndarray]
STRATEGIES: Registry[Strategy] = Registry("exploration strategy")


def _strategy(name: str) -> str:
    return STRATEGIES.check(name)


class ExploreConfig(Config):
    """How exploration proceeds.

    Parameters
    ----------
    strategy : str
        A name in :data:`STRATEGIES`.
    budget : int
        Number of reaches.
    batch : int
        Reaches proposed per model refit.
    explore_radius : float
        ``active``: cover the working area until no point is further than this (px) from a reach.
    n_candidates : int
        ``active``: uniform candidates from which to spread reaches while no boundary is known.
    model_class : str
        The model fitted to the samples (:data:`kbcli.core.model.classes.MODEL_CLASSES`): the
        ``active`` strategy bisects its boundary bands, whatever the class. ``auto``: the
        exploration starts with :data:`kbcli.core.model.select.EXPLORE_CLASS` and re-chooses the class
        it refits every :data:`kbcli.core.model.select.RESELECT` reaches
        (:func:`kbcli.core.model.select.explore_choice`); the final class is chosen by cross-validation
        once the samples are in (:func:`kbcli.core.model.select.choose`).
    """

    what: ClassVar[str] = "explore"

    strategy: Annotated[Name, AfterValidator(_strategy)] = "active"
    budget: Count = 800
    batch: Count = 10
    explore_radius: Positive = 20.0
    n_candidates: Count = 4000
    model_class: Annotated[Name, AfterValidator(check_choice)] = DEFAULT_MODEL_CLASS


def _uniform(area: tuple, n: int, rng: np.random.Generator) -> np.ndarray:
    x0, y0, x1, y1 = area
    return rng.uniform((x0, y0), (x1, y1), size=(n, 2))


def farthest_points(candidates: np.ndarray, taken: np.ndarray, n: int) -> np.ndarray:
    """Greedy max-min picks: each time the candidate furthest from ``taken`` and earlier picks.

    Parameters
    ----------
    candidates : (m, 2) ndarray
    taken : (k, 2) ndarray
    n : int

    Returns
    -------
    (min(n, m), 2) ndarray
    """
    if len(candidates) == 0:
        return np.empty((0, 2))
    if len(taken):
        d = cKDTree(taken).query(candidates)[0]
    else:
        d = np.full(len(candidates), np.inf)
    picks = []
    for _ in range(min(n, len(candidates))):  # loop over picks; each is vectorized over candidates
        i = int(np.argmax(d))
        picks.append(candidates[i])
        d = np.minimum(d, np.hypot(*(candidates - candidates[i]).T))
    return np.array(picks)


def hex_lattice(area: tuple, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """(m, 2) points of a hexagonal lattice over ``area``, randomly shifted and rotated.

    Its covering radius is ``spacing / sqrt(3)``: every point of the plane is that close to a node.
    """
    x0, y0, x1, y1 = area
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    r = np.hypot(x1 - x0, y1 - y0) / 2 + spacing
    n = int(np.ceil(r / spacing)) + 1
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1))
    p = np.column_stack([(i + 0.5 * j).ravel(), (j * np.sqrt(3) / 2).ravel()]) * spacing
    a = rng.uniform(0, np.pi / 3)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    p = p @ rot.T + c + rng.uniform(-spacing / 2, spacing / 2, size=2)
    inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    return p[inside]


def _cover_candidates(area: tuple, spacing: float, rng: np.random.Generator) -> np.ndarray:
    x0, y0, x1, y1 = area
    xs = np.arange(x0 + spacing / 2, x1, spacing)
    ys = np.arange(y0 + spacing / 2, y1, spacing)
    g = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    g = g + rng.uniform(-spacing / 2, spacing / 2, size=g.shape)
    return np.clip(g, (x0, y0), (x1, y1))


@STRATEGIES.register("active", traits={"covers": True})
def active_strategy(exploration: Exploration, n: int, rng: np.random.Generator) -> np.ndarray:
    """Cover the area to ``explore_radius``, then the widest places of the boundary bands."""
    taken, area, cfg = exploration.landed, exploration.area, exploration.cfg
    if len(taken) == 0:  # first: a lattice covering the area to explore_radius, spread-out order
        lattice = hex_lattice(area, cfg.explore_radius * np.sqrt(3), rng)
        return farthest_points(lattice, np.empty((0, 2)), len(lattice))
    cover = _cover_candidates(area, cfg.explore_radius / 5, rng)
    cover = cover[cKDTree(taken).query(cover)[0] > cfg.explore_radius]
    picks = farthest_points(cover, taken, n)
    if len(picks):
        return picks
    model = exploration.model
    if model is None or model.n_classes < 2:
        return farthest_points(_uniform(area, cfg.n_candidates, rng), taken, n)
    sites = model.boundary_sites(step=1.0, phase=float(rng.uniform()))
    x0, y0, x1, y1 = area
    p, w = sites["points"], sites["width"]
    inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    p, w = p[inside], w[inside]
    # a reach right next to a site already told what it could there: cap by the distance to it
    w = np.minimum(w, 2 * cKDTree(taken).query(p)[0]) if len(p) and len(taken) else w
    if len(p) == 0:  # no boundary met yet: keep spreading reaches over the area
        return farthest_points(_uniform(area, cfg.n_candidates, rng), taken, n)
    picks = []
    for _ in range(min(n, len(p))):  # loop over picks; each is vectorized over the sites
        i = int(np.argmax(w))
        picks.append(p[i])
        # the pick will halve the band there; nearby sites gain less the closer they are
        w = np.minimum(w, w[i] / 2 + np.hypot(*(p - p[i]).T))
    return np.array(picks)


@STRATEGIES.register("balanced", traits={"covers": True})
def balanced_strategy(exploration: Exploration, n: int, rng: np.random.Generator) -> np.ndarray:
    """Boundary seeking and coverage weighed in one rule, instead of ``active``'s
    cover-then-bisect.

    First a coarse hexagonal lattice (covering radius ``2 explore_radius``, about a quarter of
    ``active``'s first reaches), so that every sound large enough is heard early. Then every batch
    picks, greedily, the widest of two kinds of gap: a boundary site of the model (its band width
    w, capped as ``active`` caps it) and a hole, a point of the working area at distance d from
    every landing, worth ``2 d`` (a band as wide as the hole could hide there). A pick of width w
    caps every site's width at ``w / 2 + distance`` and every hole's at ``2 distance``. Early the
    holes are wide and coverage wins; as the pad fills, the widest bands take over, and a band
    found late still competes with the holes left (no phase waits for another to finish).

    Not the default (why: ``docs/design-notes.md``, Model classes).
    """
    taken, area, cfg = exploration.landed, exploration.area, exploration.cfg
    if len(taken) == 0:
        lattice = hex_lattice(area, 2 * cfg.explore_radius * np.sqrt(3), rng)
        return farthest_points(lattice, np.empty((0, 2)), len(lattice))
    tree = cKDTree(taken)
    holes = _cover_candidates(area, cfg.explore_radius / 5, rng)
    hw = 2 * tree.query(holes)[0]
    p, w = np.empty((0, 2)), np.empty(0)
    model = exploration.model
    if model is not None and model.n_classes >= 2:
        sites = model.boundary_sites(step=1.0, phase=float(rng.uniform()))
        x0, y0, x1, y1 = area
        p, w = sites["points"], sites["width"]
        inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
        p, w = p[inside], w[inside]
        w = np.minimum(w, 2 * tree.query(p)[0]) if len(p) else w
    pts = np.vstack([p, holes])
    width = np.concatenate([w, hw])
    is_hole = np.r_[np.zeros(len(p), bool), np.ones(len(holes), bool)]
    picks = []
    for _ in range(min(n, len(pts))):  # loop over picks; each is vectorized over the candidates
        i = int(np.argmax(width))
        picks.append(pts[i])
        dist = np.hypot(*(pts - pts[i]).T)
        width = np.where(is_hole, np.minimum(width, 2 * dist),
                         np.minimum(width, width[i] / 2 + dist))
    return np.array(picks)


@STRATEGIES.register("random", traits={"baseline": True})
def random_strategy(exploration: Exploration, n: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform targets over the working area (the baseline)."""
    return _uniform(exploration.area, n, rng)


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
    """Learn the instrument by reaching: an iterator over batches (propose, touch, refit).

    The model is refitted lazily: only when a strategy or the caller asks for it.

    Parameters
    ----------
    cfg : ExploreConfig
    touch : callable
        ``touch(targets (k, 2), rng) -> (landed (k, 2), perceived (k, D))``: the world
        (:meth:`kbcli.sim.World.touch`).
    area : tuple of float
        (xmin, ymin, xmax, ymax) working area in which targets are chosen.
    match_threshold : float
        Eq. 2 threshold used to tell sounds apart.
    rng : numpy.random.Generator

    Yields
    ------
    ExploreStep
        After each batch, until ``cfg.budget`` reaches are done.

    Attributes
    ----------
    targets, landed : (n, 2) ndarray
        Every reach so far.
    perceived : (n, D) ndarray
        Every sound heard so far.
    explorer : str
        The model class refitted now (``cfg.model_class``; under ``auto`` re-chosen every
        :data:`~kbcli.core.model.select.RESELECT` reaches, after the batch that reaches each multiple).
    explorers : list of (int, str)
        Each class explored with and the number of reaches from which it was.
    """

    def __init__(
        self,
        cfg: ExploreConfig,
        touch: Touch,
        area: tuple[float, float, float, float],
        match_threshold: float,
        rng: np.random.Generator,
    ) -> None:
        self.area = tuple(float(v) for v in area)
        if STRATEGIES.trait(cfg.strategy, "covers", False):  # it reaches around its samples
            check_cover(self.area, cfg.explore_radius)
        self.cfg = cfg
        self.touch = touch
        self.match_threshold = match_threshold
        self.rng = rng
        self.strategy = STRATEGIES.get(cfg.strategy)
        self.targets = np.empty((0, 2))
        self.landed = np.empty((0, 2))
        self.perceived = np.empty((0, 0))
        self._model = None
        self._plan = np.empty((0, 2))
        self.explorer = explore_class(cfg.model_class)
        self.explorers = [(0, self.explorer)]

    @property
    def model(self):
        """The model (of class :attr:`explorer`, with :func:`kbcli.core.model.select.explore_params`)
        fitted to every sample so far (None before the first reach)."""
        if len(self.landed) == 0:
            return None
        if self._model is None:
            self._model = fit_model(self.explorer, self.landed, self.perceived,
                                    match_threshold=self.match_threshold, area=self.area,
                                    targets=self.targets, **explore_params(self.explorer))
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
        if (self.cfg.model_class != AUTO or n // RESELECT == before // RESELECT
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
            t = np.vstack([t, _uniform(self.area, k - len(t), self.rng)])
        landed, heard = self.touch(t, self.rng)
        heard = np.asarray(heard, float).reshape(len(t), -1)
        self.targets = np.vstack([self.targets, t])
        self.landed = np.vstack([self.landed, landed])
        self.perceived = heard if done == 0 else np.vstack([self.perceived, heard])
        self._model = None
        self._reselect(done)
        return ExploreStep(len(self.targets), t, landed, heard, self)
