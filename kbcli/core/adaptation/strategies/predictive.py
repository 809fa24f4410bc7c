"""The posterior predictive of a touch's outcome, vectorised over candidates x hypotheses.

For a hard (exact) table the predictive is a weighted histogram of predicted classes
(``bincount``) and the conditional entropy a constant; for a soft (learned) one it is a histogram
of each point's most probable classes weighted by their probabilities (a learned model mixes two
sounds at an edge), and the conditional entropy comes from a precomputed per-cell entropy map.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.adaptation.strategies.base import Context
from kbcli.core.instrument import transforms
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.model.table import LikelihoodTable


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


def ml_outcomes(ctx: Context, actions: np.ndarray) -> np.ndarray:
    """(k,) the sound the model predicts at each action (k, 2) under the posterior's
    maximum-likelihood hypothesis."""
    post = ctx.posterior
    ml = post.grid.params(np.array([post.ml_index()]))
    mx, my = inverse_points(ctx.family, ml, actions, ctx.centre)
    return ctx.table.classes_at(mx, my)[0]
