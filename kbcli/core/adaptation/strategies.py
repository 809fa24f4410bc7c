"""Where to touch next: the action-selection strategies of the adaptation (paper Sect. III-E).

A strategy is a plain function registered by name in :data:`STRATEGIES` (``@STRATEGIES.register(name)``)
and read with ``STRATEGIES.get(name)``::

    fn(ctx: Context, rng: numpy.random.Generator) -> (2,) ndarray   # the next action, pad px

It sees the robot's side only: the current posterior, the rasterised model, the working area and
the model's class boundaries (never the true pose). Registered:

- ``random`` (the paper's baseline): uniform over the working area (the model's ``area``: the
  keyboard's reference bounds plus the margin, where the displaced keyboard can plausibly be;
  ``random_actions = "area"``), or sampled from the model (``"model"``: a sound, then an action
  from p(action | sound), the paper's "random selection of samples").
- ``active`` (our first reading of the paper's): draw ``candidates`` uniform actions; keep the ``active_keep`` most
  *confusing* ones, confusion being the entropy of the outcome the model predicts under the current
  posterior (a coarse subsample of 128 hypotheses); simulate each kept action's outcome under the
  best (maximum-likelihood) hypothesis, update the posterior with it (on a weighted subsample of up
  to ``active_hypotheses`` cells) and pick the action whose simulated posterior has the lowest entropy.
- ``paper-active`` (the paper's, as Sect. III-E writes it): ``candidates`` actions sampled from
  the model, the ``active_keep`` with the largest confusion factor of the model kept, each
  simulated under the maximum-likelihood hypothesis and the posterior updated with the simulated
  sound by the adapter's own term (the KDE of Algorithm 2 with the ``kde`` posterior), the largest
  entropy reduction chosen (:func:`paper_active_strategy`).
- ``infogain`` (ours): the action with the largest expected information gain
  ``I(S; H | a) = H[p(s | a)] - E_h H[p(s | a, h)]``, the mutual information between the outcome and
  the transform over the whole posterior predictive (not only the best hypothesis). It is evaluated
  on a weighted subsample of at most ``hypotheses`` posterior cells (the exact support once it is
  small; systematic resampling before). Candidates: a quarter uniform over the area, a quarter on
  the model's class edges and half on its corners (where three or four sounds meet), each edge or
  corner point carried into the pad by a hypothesis drawn from the posterior (shifted by half a
  grid cell, so the boundary falls between cells), so that it falls where the posterior is still
  undecided.

Both model-based strategies work for hard (exact) and soft (learned) models: for a hard table the
predictive distribution is a weighted histogram of predicted classes (``bincount``) and the
conditional entropy is a constant; for a soft one the predictive is a histogram of each point's
four most probable classes weighted by their probabilities (a learned model mixes two sounds at an
edge), and the conditional entropy comes from a precomputed per-cell entropy map.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

import numpy as np

from kbcli.core.adaptation.fields import MAX_CANDIDATES, MAX_HYPOTHESES, choice
from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.adaptation.posteriors.posterior import Posterior, log_normalise
from kbcli.core.config import Name, Whole, between
from kbcli.core.instrument import transforms
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.model.table import LikelihoodTable
from kbcli.core.options import Options
from kbcli.core.registry import Registry

StrategyFn = Callable[["Context", np.random.Generator], np.ndarray]

#: The adaptation strategies (``--strategy``), read with ``STRATEGIES.get(name)``.
STRATEGIES: Registry[StrategyFn] = Registry("strategy")

#: Hypotheses used by ``active`` to rank candidates by confusion.
CONFUSION_HYPOTHESES = 128


@dataclass
class Context:
    """What a strategy may look at.

    Attributes
    ----------
    posterior : Posterior
    table : LikelihoodTable
        The model, rasterised (reference frame).
    area : tuple of float
        (xmin, ymin, xmax, ymax) where actions may go.
    edges, corners : (n, 2) ndarrays
        The model's class boundaries in the reference frame (:meth:`LikelihoodTable.boundary_points`).
    cfg : AdapterConfig
        The adapter config; the strategy's own options are ``cfg.strategy`` (:attr:`options`).
    touched : (k, 2) ndarray
        Where the touches so far were read (felt positions).
    redundancy_radius : float
        Touches within this radius (px) count as one spot (0: off; ``AdapterConfig``).
    sampler : object
        Draws actions from p(action | sound) (``random`` with ``random_actions = "model"``,
        ``paper-active``).
    simulate, simulate_many : callable
        The adapter's own posterior term of a simulated touch, and of several at once
        (``paper-active``).
    """

    posterior: Posterior
    table: LikelihoodTable
    area: tuple[float, float, float, float]
    edges: np.ndarray
    corners: np.ndarray
    cfg: Any
    touched: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    redundancy_radius: float = 0.0
    #: ``sample_actions(cls, n, rng)``: draws of p(action | sound) (the model or its raster)
    sampler: Any = None
    #: ``simulate(action (2,), cls) -> log term``: the term a touch would multiply the posterior by
    simulate: Callable[[np.ndarray, int], np.ndarray] | None = None
    #: ``simulate_many(actions (k, 2), classes (k,)) -> (k, *grid.shape)``: ``simulate`` of each
    simulate_many: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    #: ``outcome(table, hyp (K, P), weights (K,), actions (M, 2)) -> (pred (M, C), cond (M,))``:
    #: the adapter's own predictive of a touch's outcome when it is not the table's (the
    #: repaired belief, :func:`kbcli.core.adaptation.repair.repair_outcome`); None: ``outcome_distribution``
    outcome: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None

    @property
    def options(self) -> Any:
        """The strategy's own options (``cfg.strategy``: ``candidates``, ...)."""
        return self.cfg.strategy

    @property
    def family(self) -> str:
        return self.posterior.grid.family

    @property
    def centre(self) -> np.ndarray:
        return self.posterior.grid.centre


# ---------------------------------------------------------------------------------------------
# Helpers (vectorised over candidates x hypotheses)
# ---------------------------------------------------------------------------------------------
def uniform_actions(area: tuple[float, float, float, float], n: int,
                    rng: np.random.Generator) -> np.ndarray:
    """(n, 2) uniform points over ``area``."""
    x0, y0, x1, y1 = area
    return rng.uniform((x0, y0), (x1, y1), size=(n, 2))


def inverse_points(family: str, hyp: np.ndarray, actions: np.ndarray,
                   centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of ``T_h^-1(a)`` for hypotheses (K, P) x actions (M, 2): two (K, M) arrays."""
    if not FAMILIES.get(family).rotates:  # a shift: T_h^-1(a) = a - h
        return actions[None, :, 0] - hyp[:, 0, None], actions[None, :, 1] - hyp[:, 1, None]
    p = transforms.inverse_many(family, hyp, actions, centre)
    return p[..., 0], p[..., 1]


def outcome_distribution(table: LikelihoodTable, family: str, hyp: np.ndarray,
                         weights: np.ndarray, actions: np.ndarray,
                         centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posterior predictive of the outcome of each action, and the expected conditional entropy.

    Parameters
    ----------
    hyp : (K, P) ndarray
        Hypotheses.
    weights : (K,) ndarray
        Their posterior weights (summing to one).
    actions : (M, 2) ndarray

    Returns
    -------
    pred : (M, C) ndarray
        ``p(s | a) = sum_h w_h p_eps(s | T_h^-1 a)``.
    cond : (M,) ndarray
        ``sum_h w_h H[p_eps(. | T_h^-1 a)]``, nats.
    """
    x, y = inverse_points(family, hyp, actions, centre)
    c, m = table.n_classes, len(actions)
    if table.hard:
        cls = table.classes_at(x, y)  # (K, M)
        flat = (np.arange(m)[None, :] * c + cls).ravel()
        w = np.broadcast_to(weights[:, None], cls.shape).ravel()
        pred = np.bincount(flat, weights=w, minlength=m * c).reshape(m, c)
        pred = (1 - table.eps) * pred + table.eps / c
        return pred, np.full(m, table.conditional_entropy())
    cls, p = table.top_at(x, y)  # (K, M, k): the few classes each point can sound
    flat = (np.arange(m)[None, :, None] * c + cls).ravel()
    pred = np.bincount(flat, weights=(weights[:, None, None] * p).ravel(), minlength=m * c)
    pred = (1 - table.eps) * pred.reshape(m, c) / pred.reshape(m, c).sum(axis=1, keepdims=True)
    # einsum, not BLAS: a threaded BLAS on a busy machine costs more than it saves here
    cond = np.einsum("k,km->m", weights, table.entropy_at(x, y))
    return pred + table.eps / c, cond


def entropy_rows(p: np.ndarray) -> np.ndarray:
    """Entropy (nats) of each row of a (M, C) array of distributions."""
    q = np.where(p > 0, p, 1.0)
    return -(p * np.log(q)).sum(axis=-1)


def information_gain(table: LikelihoodTable, family: str, hyp: np.ndarray, weights: np.ndarray,
                     actions: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(M,) expected information gain of each action, nats: the mutual information
    ``I(S; H | a) = H[p(s | a)] - sum_h w_h H[p_eps(. | T_h^-1 a)]`` between the outcome and the
    hypothesis (not the predictive entropy alone, which also counts the noise of one hypothesis).
    Arguments as :func:`outcome_distribution`."""
    pred, cond = outcome_distribution(table, family, hyp, weights, actions, centre)
    return entropy_rows(pred) - cond


def _clip(area: tuple[float, float, float, float], pts: np.ndarray) -> np.ndarray:
    x0, y0, x1, y1 = area
    return np.clip(pts, (x0, y0), (x1, y1))


def boundary_candidates(ctx: Context, n_edges: int, n_corners: int, hyp: np.ndarray,
                        weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Model edge and corner points carried into the pad by hypotheses drawn from ``weights``.

    Returns
    -------
    (n, 2) ndarray, n <= n_edges + n_corners (fewer when the model has no edges or corners).
    """
    src = []
    if len(ctx.edges) and n_edges > 0:
        src.append(ctx.edges[rng.integers(len(ctx.edges), size=n_edges)])
    if len(ctx.corners) and n_corners > 0:
        src.append(ctx.corners[rng.integers(len(ctx.corners), size=n_corners)])
    if not src:
        return np.empty((0, 2))
    pts = np.vstack(src)
    h = hyp[rng.choice(len(hyp), size=len(pts), p=weights)]
    # put the boundary half a cell off the hypothesis, between grid cells: then every cell lies
    # cleanly on one side and the cell nearest the truth always agrees with the outcome
    h = h.copy()
    h[:, -2:] += rng.choice([-0.5, 0.5], size=(len(h), 2)) * ctx.posterior.grid.resolution
    if not FAMILIES.get(ctx.family).rotates:
        out = pts + h
    else:
        out = transforms.apply_many(ctx.family, h, pts[:, None, :], ctx.centre)[:, 0, :]
    return _clip(ctx.area, out)


# ---------------------------------------------------------------------------------------------
# The strategies
# ---------------------------------------------------------------------------------------------
def model_actions(ctx: Context, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) actions sampled from the model as Algorithm 1 plays: a sound uniform over the model's
    sounds (silence excluded: the robot plays notes), then an action from p(action | sound)
    (``ctx.sampler``), clipped to the working area."""
    c = ctx.table.n_classes
    if c < 2:
        return uniform_actions(ctx.area, n, rng)
    cls = rng.integers(1, c, size=n)
    out = np.empty((n, 2))
    for k in np.unique(cls):  # one draw per sound heard, in class order
        sel = np.flatnonzero(cls == k)
        out[sel] = ctx.sampler.sample_actions(int(k), len(sel), rng)
    return _clip(ctx.area, out)


#: Where the ``random`` strategy's actions come from (``random_actions``).
RANDOM_ACTIONS = ("area", "model")


class RandomOptions(Options):
    """``random``'s options.

    Parameters
    ----------
    random_actions : str
        ``area`` (uniform over the working area, the historical baseline) or ``model`` (a sound
        uniform over the model's sounds, then an action from p(action | sound), drawn as the
        adapter's ``kde_sampler`` says: the paper's "random selection of samples").
    """

    what: ClassVar[str] = "strategy random"
    random_actions: Annotated[Name, choice(*RANDOM_ACTIONS)] = "area"

    def samples_actions(self) -> bool:
        return self.random_actions == "model"


class Candidates(Options):
    """Options of a strategy that ranks sampled candidate actions.

    Parameters
    ----------
    candidates : int
        Candidate actions per decision.
    """

    candidates: between(Whole, 1, MAX_CANDIDATES) = 256


class Kept(Candidates):
    """Options of a strategy that keeps the most confusing candidates: ``active_keep`` of them."""

    active_keep: between(Whole, 1, MAX_CANDIDATES) = 8


class PaperActiveOptions(Kept):
    """``paper-active``'s options: ``candidates`` (sampled from the model) and ``active_keep``."""

    what: ClassVar[str] = "strategy paper-active"

    def samples_actions(self) -> bool:
        return True


class ActiveOptions(Kept):
    """``active``'s options: ``candidates``, ``active_keep``, and ``active_hypotheses``, the
    posterior cells its simulated updates use."""

    what: ClassVar[str] = "strategy active"
    active_hypotheses: between(Whole, 1, MAX_HYPOTHESES) = 2048


class InfogainOptions(Candidates):
    """``infogain``'s options: ``candidates``, and ``hypotheses``, the posterior cells on which
    it evaluates them."""

    what: ClassVar[str] = "strategy infogain"
    hypotheses: between(Whole, 1, MAX_HYPOTHESES) = 512


@STRATEGIES.register("random", traits={"options": RandomOptions})
def random_strategy(ctx: Context, rng: np.random.Generator) -> np.ndarray:
    """The paper's baseline, "random selection of samples": uniform over the working area
    (``random_actions = "area"``) or an action sampled from the model (``"model"``:
    :func:`model_actions`)."""
    if ctx.options.random_actions == "model":
        return model_actions(ctx, 1, rng)[0]
    return uniform_actions(ctx.area, 1, rng)[0]


def _active_candidates(r: dict) -> str:
    return (f"`active` draws {r.get('candidates', '(default)')} candidates uniformly over the "
            "working area and ranks them by the entropy of the posterior predictive over "
            f"{r.get('active_hypotheses', '(default)')} hypotheses, keeping the "
            f"{r.get('active_keep', '(default)')} most confusing; the model's own confusion factor "
            "is not used")


def _active_simulation(r: dict) -> str:
    return ("each kept candidate is simulated with the model's likelihood table, not a KDE "
            "term of Algorithm 2; at the first step the best hypothesis of a flat posterior "
            "is the grid's first cell")


@STRATEGIES.register("active", traits={
    "paper": True, "options": ActiveOptions,
    "departures": {"candidates": _active_candidates, "simulation": _active_simulation}})
def active_strategy(ctx: Context, rng: np.random.Generator) -> np.ndarray:
    """The paper's: most confusing candidates, then the largest simulated entropy reduction under
    the best hypothesis."""
    cfg, post, table = ctx.options, ctx.posterior, ctx.table
    cands = uniform_actions(ctx.area, cfg.candidates, rng)
    grid = post.grid
    idx, w = post.sample_hypotheses(CONFUSION_HYPOTHESES, rng)
    pred, _ = outcome_distribution(table, ctx.family, grid.params(idx), w, cands, ctx.centre)
    confusion = entropy_rows(pred)
    keep = np.argsort(-confusion, kind="stable")[: cfg.active_keep]
    kept = cands[keep]
    # simulate each kept action under the maximum-likelihood hypothesis
    ml = grid.params(np.array([post.ml_index()]))
    mx, my = inverse_points(ctx.family, ml, kept, ctx.centre)
    simulated = table.classes_at(mx, my)[0]  # (k,)
    # update a weighted subsample of the posterior with each simulated outcome
    idx2, w2 = post.sample_hypotheses(cfg.active_hypotheses, rng)
    x, y = inverse_points(ctx.family, grid.params(idx2), kept, ctx.centre)  # (K, k)
    logw = np.log(w2)[:, None] + table.log_prob(x, y, simulated[None, :])
    _, q = log_normalise(logw, axis=0)
    after = entropy_rows(q.T)
    return kept[int(np.argmin(after))]


def _kde(cfg) -> bool:
    """Whether the config's posterior draws samples of p(action | sound) (the KDE's); ``cfg``: a
    config or a recorded config's dict."""
    name = cfg.get("posterior", "likelihood") if isinstance(cfg, dict) else \
        getattr(cfg, "posterior", "likelihood")
    return POSTERIORS.get(name).uses_samples


def _paper_candidates(r: dict) -> str:
    return (f"`paper-active`: {r.get('candidates', '(default)')} candidates sampled from the model "
            "(a sound uniform over the model's sounds, then an action from p(a | s)), ranked by "
            f"the model's confusion factor 1 - (p1 - p2), the {r.get('active_keep', '(default)')} "
            "most confusing kept (the counts and the sounds' distribution are open)")


def _paper_simulation(r: dict) -> str:
    sim = r.get("simulate_draw") or r.get("kde_draw", "shared")
    return ("each kept candidate's sound simulated at the maximum-likelihood hypothesis and "
            "the whole posterior updated with the method's own term"
            + (f" (KDE samples of the simulated touches: {sim})" if _kde(r) else ""))


@STRATEGIES.register("paper-active", traits={
    "paper": True, "simulates": True, "options": PaperActiveOptions,
    "departures": {"candidates": _paper_candidates, "simulation": _paper_simulation}})
def paper_active_strategy(ctx: Context, rng: np.random.Generator) -> np.ndarray:
    """Sect. III-E as the paper writes it.

    1. ``candidates`` actions sampled from the model (:func:`model_actions`: a sound, then an
       action from p(action | sound));
    2. each ranked by the model's confusion factor at the action, ``1 - (p1 - p2)``, its own
       uncertainty over which sound is heard there (:meth:`LikelihoodTable.confusion_at`, read in
       the model's frame, as the action is sampled); the ``active_keep`` most confusing are kept
       (stable order: ties, e.g. an exact model that is never unsure, keep the sampling order);
    3. each kept action's outcome simulated under the best (maximum-likelihood) hypothesis so far
       (its most probable sound);
    4. the current posterior updated with each simulated outcome by the adapter's own term
       (``ctx.simulate_many``: with the KDE posterior, Algorithm 2 on the simulated sound, fresh
       samples for each), on the whole grid (the entropies after, :meth:`Posterior.entropies_after`);
    5. the action with the largest entropy reduction (lowest entropy after) chosen.

    Choices the paper leaves open: the number of candidates and kept ones (``candidates`` 256,
    ``active_keep`` 8), the distribution of the sampled sounds (uniform over the model's sounds),
    the frame of the confusion factor (the model's). Not the paper's, an option: with the KDE
    posterior, ``simulate_draw = "shared"`` gives the simulated touches one set of samples per
    sound for the whole adaptation instead of new ones per simulated touch (faster; the real
    touches keep ``kde_draw``).
    """
    cfg, post, table = ctx.options, ctx.posterior, ctx.table
    cands = model_actions(ctx, cfg.candidates, rng)
    confusion = table.confusion_at(cands[:, 0], cands[:, 1])
    kept = cands[np.argsort(-confusion, kind="stable")[: cfg.active_keep]]
    grid = post.grid
    ml = grid.params(np.array([post.ml_index()]))
    mx, my = inverse_points(ctx.family, ml, kept, ctx.centre)
    simulated = table.classes_at(mx, my)[0]  # (k,)
    after = np.concatenate([post.entropies_after(_simulated_terms(ctx, kept[sel], simulated[sel]))
                            for sel in _chunks(len(kept), grid.size)])
    return kept[int(np.argmin(after))]


#: Grid cells of simulated terms held at once (``paper-active``: 8 terms of a rigid grid at
#: 0.5 px would take 80 MB).
SIMULATED_CELLS = 2**21


def _chunks(k: int, cells: int) -> list[slice]:
    """Slices of ``range(k)`` holding at most ``SIMULATED_CELLS`` cells of terms (at least one)."""
    step = max(1, SIMULATED_CELLS // max(cells, 1))
    return [slice(i, i + step) for i in range(0, k, step)]


def _simulated_terms(ctx: Context, actions: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """``(k, *grid.shape)`` the adapter's terms of simulated touches (together when it can)."""
    if ctx.simulate_many is not None:
        return ctx.simulate_many(actions, classes)
    return np.stack([ctx.simulate(a, int(c)) for a, c in zip(actions, classes, strict=True)])


@STRATEGIES.register("infogain", traits={"options": InfogainOptions})
def infogain_strategy(ctx: Context, rng: np.random.Generator) -> np.ndarray:
    """Largest expected information gain over the whole posterior predictive."""
    cfg, post = ctx.options, ctx.posterior
    idx, w = post.sample_hypotheses(cfg.hypotheses, rng)
    hyp = post.grid.params(idx)
    m = cfg.candidates
    n_uniform = m // 4
    n_edges = m // 4
    cands = np.vstack([
        uniform_actions(ctx.area, n_uniform, rng),
        boundary_candidates(ctx, n_edges, m - n_uniform - n_edges, hyp, w, rng),
    ])
    if ctx.outcome is None:
        gain = information_gain(ctx.table, ctx.family, hyp, w, cands, ctx.centre)
    else:  # the adapter's own predictive (the repaired belief)
        pred, cond = ctx.outcome(ctx.table, hyp, w, cands)
        gain = entropy_rows(pred) - cond
    if ctx.redundancy_radius > 0 and len(ctx.touched):
        # the (k + 1)-th touch at a spot enters the posterior with weight 1 / (k + 1): so does
        # its gain (a model wrong at a spot is wrong there every time)
        d2 = ((cands[:, None, :] - ctx.touched[None, :, :]) ** 2).sum(axis=2)
        gain = gain / (1 + (d2 <= ctx.redundancy_radius ** 2).sum(axis=1))
    return cands[int(np.argmax(gain))]
