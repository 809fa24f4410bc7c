"""``infogain`` (ours): the action with the largest expected information gain
``I(S; H | a) = H[p(s | a)] - E_h H[p(s | a, h)]`` over the whole posterior predictive.

It is evaluated on a weighted subsample of at most ``hypotheses`` posterior cells. Candidates: a
quarter uniform over the area, a quarter on the model's class edges and half on its corners, each
edge or corner point carried into the pad by a hypothesis drawn from the posterior (shifted by
half a grid cell), so that it falls where the posterior is still undecided.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.adaptation.fields import MAX_HYPOTHESES
from kbcli.core.adaptation.strategies.base import STRATEGIES, Candidates, Context
from kbcli.core.adaptation.strategies.candidates import boundary_candidates, uniform_actions
from kbcli.core.adaptation.strategies.predictive import entropy_rows, information_gain
from kbcli.core.config import Whole, between


class InfogainOptions(Candidates):
    """``infogain``'s options: ``candidates``, and ``hypotheses``, the posterior cells on which
    it evaluates them."""

    what: ClassVar[str] = "strategy infogain"
    hypotheses: between(Whole, 1, MAX_HYPOTHESES) = 512


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
