"""``paper-active``, Sect. III-E as the paper writes it: ``candidates`` actions sampled from the
model, the ``active_keep`` with the largest confusion factor of the model kept, each simulated
under the maximum-likelihood hypothesis and the posterior updated with the simulated sound by the
adapter's own term (the KDE of Algorithm 2 with the ``kde`` posterior), the largest entropy
reduction chosen."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.adaptation.strategies.base import STRATEGIES, Context, Kept
from kbcli.core.adaptation.strategies.candidates import model_actions
from kbcli.core.adaptation.strategies.predictive import ml_outcomes

#: Grid cells of simulated terms held at once (bounds the memory of one batch of simulated
#: touches; ``docs/design-notes.md``).
SIMULATED_CELLS = 2**21


class PaperActiveOptions(Kept):
    """``paper-active``'s options: ``candidates`` (sampled from the model) and ``active_keep``."""

    what: ClassVar[str] = "strategy paper-active"

    def samples_actions(self) -> bool:
        return True


def _kde(cfg) -> bool:
    """Whether the config's posterior draws samples of p(action | sound) (the KDE's); ``cfg``: a
    config or a recorded config's dict."""
    name = cfg.get("posterior", "likelihood") if isinstance(cfg, dict) else \
        getattr(cfg, "posterior", "likelihood")
    return POSTERIORS.get(name).uses_samples


def _candidates(r: dict) -> str:
    return (f"`paper-active`: {r.get('candidates', '(default)')} candidates sampled from the model "
            "(a sound uniform over the model's sounds, then an action from p(a | s)), ranked by "
            f"the model's confusion factor 1 - (p1 - p2), the {r.get('active_keep', '(default)')} "
            "most confusing kept (the counts and the sounds' distribution are open)")


def _simulation(r: dict) -> str:
    sim = r.get("simulate_draw") or r.get("kde_draw", "shared")
    return ("each kept candidate's sound simulated at the maximum-likelihood hypothesis and "
            "the whole posterior updated with the method's own term"
            + (f" (KDE samples of the simulated touches: {sim})" if _kde(r) else ""))


@STRATEGIES.register("paper-active", traits={
    "paper": True, "simulates": True, "options": PaperActiveOptions,
    "departures": {"candidates": _candidates, "simulation": _simulation}})
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
    simulated = ml_outcomes(ctx, kept)  # (k,)
    after = np.concatenate([post.entropies_after(_simulated_terms(ctx, kept[sel], simulated[sel]))
                            for sel in _chunks(len(kept), post.grid.size)])
    return kept[int(np.argmin(after))]


def _chunks(k: int, cells: int) -> list[slice]:
    """Slices of ``range(k)`` holding at most ``SIMULATED_CELLS`` cells of terms (at least one)."""
    step = max(1, SIMULATED_CELLS // max(cells, 1))
    return [slice(i, i + step) for i in range(0, k, step)]


def _simulated_terms(ctx: Context, actions: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """``(k, *grid.shape)`` the adapter's terms of simulated touches (together when it can)."""
    if ctx.simulate_many is not None:
        return ctx.simulate_many(actions, classes)
    return np.stack([ctx.simulate(a, int(c)) for a, c in zip(actions, classes, strict=True)])
