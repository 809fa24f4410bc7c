"""``active``, our first reading of the paper's Sect. III-E: draw ``candidates`` uniform actions;
keep the ``active_keep`` most *confusing* ones, confusion being the entropy of the outcome the model
predicts under the current posterior (a coarse subsample of :data:`CONFUSION_HYPOTHESES`
hypotheses); simulate each kept action's outcome under the best (maximum-likelihood) hypothesis,
update the posterior with it (on a weighted subsample of up to ``active_hypotheses`` cells) and
pick the action whose simulated posterior has the lowest entropy."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.adaptation.fields import MAX_HYPOTHESES
from kbcli.core.adaptation.posteriors.posterior import log_normalise
from kbcli.core.adaptation.strategies.base import STRATEGIES, Context, Kept
from kbcli.core.adaptation.strategies.candidates import uniform_actions
from kbcli.core.adaptation.strategies.predictive import (
    entropy_rows,
    inverse_points,
    ml_outcomes,
    outcome_distribution,
)
from kbcli.core.config import Whole, between

#: Hypotheses used by ``active`` to rank candidates by confusion.
CONFUSION_HYPOTHESES = 128


class ActiveOptions(Kept):
    """``active``'s options: ``candidates``, ``active_keep``, and ``active_hypotheses``, the
    posterior cells its simulated updates use."""

    what: ClassVar[str] = "strategy active"
    active_hypotheses: between(Whole, 1, MAX_HYPOTHESES) = 2048


def _candidates(r: dict) -> str:
    return (f"`active` draws {r.get('candidates', '(default)')} candidates uniformly over the "
            "working area and ranks them by the entropy of the posterior predictive over "
            f"{r.get('active_hypotheses', '(default)')} hypotheses, keeping the "
            f"{r.get('active_keep', '(default)')} most confusing; the model's own confusion factor "
            "is not used")


def _simulation(r: dict) -> str:
    return ("each kept candidate is simulated with the model's likelihood table, not a KDE "
            "term of Algorithm 2; at the first step the best hypothesis of a flat posterior "
            "is the grid's first cell")


@STRATEGIES.register("active", traits={
    "paper": True, "options": ActiveOptions,
    "departures": {"candidates": _candidates, "simulation": _simulation}})
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
    simulated = ml_outcomes(ctx, kept)  # (k,)
    # update a weighted subsample of the posterior with each simulated outcome
    idx2, w2 = post.sample_hypotheses(cfg.active_hypotheses, rng)
    x, y = inverse_points(ctx.family, grid.params(idx2), kept, ctx.centre)  # (K, k)
    logw = np.log(w2)[:, None] + table.log_prob(x, y, simulated[None, :])
    _, q = log_normalise(logw, axis=0)
    after = entropy_rows(q.T)
    return kept[int(np.argmin(after))]
