"""Stage ``quality``: does a better model make active adaptation pay? (the paper's Sect. IV-C).

The paper blamed its robot result's lack of significance on "the model learned with the iCub
robot". This stage tests that:

1. **learn** a model for every exploration strategy x reach budget of ``[quality]`` with the
   configured arm, each from its own seed, scored against the simulator and self-estimated
   (:mod:`kbcli.core.model.reliability`);
2. **adapt** with every model, for every row (a strategy and its adapt options), to the paper's
   fixed displacements, ``experiments`` times each; the repetitions share their seeds across rows
   (a paired design), so each row is compared with the baseline by the Wilcoxon signed-rank test;
3. **assemble** the ``model_quality`` artifact: every run's error per step, and per model,
   category and row the final error, the touches to ``tau = 2 max(boundary error, 0.5 px)`` (never:
   ``max_steps + 1``) and the advantage over the baseline (median paired difference in those
   touches, positive when the row needs fewer) with its p-value.

Every experiment is seeded by a child of ``SeedSequence(seed)`` chosen by its place in the grid, so
results depend neither on the workers nor on the backend (:mod:`kbcli.io.runner`). :func:`report`
draws the advantage against the model's boundary error and says whether the paper's explanation
holds.
"""

from __future__ import annotations

from kbcli.stages.quality.assembly import assemble, fingerprint, paired_test, threshold, touches_to
from kbcli.stages.quality.config import (
    DEFAULT_ROWS,
    EXACT,
    FIXED,
    IDEAL_ROW,
    QualityConfig,
    adapt_config,
    baseline_of,
    compared_rows,
    model_names,
)
from kbcli.stages.quality.plan import ADAPT_KEY, LEARN_KEY, LearnTask, Task, learn_tasks, plan
from kbcli.stages.quality.readme import hypothesis, report, targets, verdict
from kbcli.stages.quality.workers import adapt_one, adapt_setup, learn_one, learn_setup

__all__ = ["ADAPT_KEY", "DEFAULT_ROWS", "EXACT", "FIXED", "IDEAL_ROW", "LEARN_KEY", "LearnTask",
           "QualityConfig", "Task", "adapt_config", "adapt_one", "adapt_setup", "assemble",
           "baseline_of", "compared_rows",
           "fingerprint", "hypothesis", "learn_one", "learn_setup", "learn_tasks", "model_names",
           "paired_test", "plan", "report", "targets", "threshold", "touches_to", "verdict"]
