"""Learning and adapting on every layout, as tables and figures (issue 11; ``make reproduce-layouts``).

For each layout of ``pipelines/layouts.toml`` (its keyboard from ``pipelines/layouts/<layout>.toml``):

1. the learning benchmark (:mod:`kbcli.bench.learn`): every model class and exploration strategy,
   ``seeds`` runs each up to the largest budget, the accuracy on a 1 px grid at each budget, the
   reaches to 97 % and 99 %, the boundary error and the fit time (runs are kept in ``OUT/cache``);
2. the adaptation model: ``kbcli learn`` (active exploration, seed ``seed``) with the class that has
   the best median accuracy at the adaptation budget (or the one named), ``OUT/models/<layout>.h5``;
3. the adaptation benchmark (:mod:`kbcli.bench.adapt`, sections ``learned`` and ``learned-rigid``)
   with that model: median touches to 4, 2, 1 and 0.5 px per strategy and displacement category;
4. the report, ``OUT/report/``: ``README.md`` (the tables, each target of the issue with the measured
   figure beside it, every resolved setting), ``<layout>.png`` (the layout, the adaptation model's
   map, the learning curves and the adaptation curves) and ``results.json`` (the rows).

Every number in the report is measured by this run; the targets are the issue's.
"""

from kbcli.bench.layouts.config import LayoutResult, LayoutsConfig
from kbcli.bench.layouts.pipeline import Pipeline
from kbcli.bench.layouts.report import render, targets

__all__ = ["LayoutsConfig", "LayoutResult", "Pipeline", "render", "targets"]
