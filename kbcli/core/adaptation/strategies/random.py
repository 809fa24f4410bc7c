"""``random``, the paper's baseline ("random selection of samples"): uniform over the working area
(the model's ``area``: the keyboard's reference bounds plus the margin, where the displaced
keyboard can plausibly be), or an action sampled from the model (a sound, then an action from
p(action | sound))."""

from __future__ import annotations

from typing import Annotated, ClassVar

import numpy as np

from kbcli.core.adaptation.fields import choice
from kbcli.core.adaptation.strategies.base import STRATEGIES, Context
from kbcli.core.adaptation.strategies.candidates import model_actions, uniform_actions
from kbcli.core.config import Name
from kbcli.core.options import Options

#: Where the ``random`` strategy's actions come from (``random_actions``).
RANDOM_ACTIONS = ("area", "model")


class RandomOptions(Options):
    """``random``'s options.

    Parameters
    ----------
    random_actions : str
        ``area`` (uniform over the working area, the baseline) or ``model`` (a sound
        uniform over the model's sounds, then an action from p(action | sound), drawn as the
        adapter's ``kde_sampler`` says: the paper's "random selection of samples").
    """

    what: ClassVar[str] = "strategy random"
    random_actions: Annotated[Name, choice(*RANDOM_ACTIONS)] = "area"

    def samples_actions(self) -> bool:
        return self.random_actions == "model"


@STRATEGIES.register("random", traits={"options": RandomOptions})
def random_strategy(ctx: Context, rng: np.random.Generator) -> np.ndarray:
    """The paper's baseline, "random selection of samples": uniform over the working area
    (``random_actions = "area"``) or an action sampled from the model (``"model"``:
    :func:`model_actions`)."""
    if ctx.options.random_actions == "model":
        return model_actions(ctx, 1, rng)[0]
    return uniform_actions(ctx.area, 1, rng)[0]
