"""Stage ``quality``: does a better model make active adaptation pay? (the paper's Sect. IV-C).

The paper's robot result was not significant, and the authors blamed "the model learned with the
iCub robot", asking for "more experiments to confirm this hypothesis". This stage runs them:

1. **learn** a model for every exploration strategy x reach budget of ``[quality]`` (e.g. active
   and random exploration, 100 to 1600 reaches) with the configured arm (``realistic`` by default),
   each from its own seed; its quality is measured against the simulator (accuracy, boundary
   error) and self-estimated (:mod:`kbcli.core.model.reliability`);
2. **adapt** with every model, for every row (a strategy and its adapt options: random, active and
   infogain with the robust posterior, and infogain with the plain posterior for reference), to
   the paper's fixed displacements (small / medium / large), ``experiments`` times each. The
   repetitions share their seeds across rows (a paired design: the same displacement, the same
   arm noise draws where the touches coincide), so each row is compared with the baseline by the
   Wilcoxon signed-rank test;
3. **assemble** the ``model_quality`` artifact: every run's error per step, and per model, category
   and row: the final error (after ``max_steps`` touches), the touches to the model's threshold
   ``tau = 2 max(boundary error, 0.5 px)`` (runs that never get there count ``max_steps + 1``), and
   the advantage over the baseline (median of the paired differences in touches to ``tau``,
   positive when the row needs fewer) with its p-value.

Every experiment is one call of the adapt stage's ``experiment`` (the robot's side never reads the
truth), seeded by a child of ``SeedSequence(seed)`` chosen by its place in the grid, so results do
not depend on the number of workers or the backend (:mod:`kbcli.io.runner`). The report
(:func:`report`) draws the advantage against the model's boundary error and says, from the data,
whether the paper's explanation holds.

The package: :mod:`~kbcli.stages.quality.config` (the ``[quality]`` table),
:mod:`~kbcli.stages.quality.plan` (the tasks and their seeds), :mod:`~kbcli.stages.quality.workers`
(learning one model, running one adaptation), :mod:`~kbcli.stages.quality.assembly` (the
artifact) and :mod:`~kbcli.stages.quality.readme` (the report's text).
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
