"""Learning and adapting on every layout, as tables and figures (``make reproduce-layouts``).

For each layout of ``pipelines/layouts.toml``: the learning benchmark (:mod:`kbcli.bench.learn`,
runs cached in ``OUT/cache``); an adaptation model (``kbcli learn`` with the class of best median
accuracy, or the one named, ``OUT/models/<layout>.h5``); the adaptation benchmark
(:mod:`kbcli.bench.adapt`, sections ``learned`` and ``learned-rigid``) with it; and the report,
``OUT/report/`` (``README.md`` with each target against the measured figure, ``<layout>.png``,
``results.json``). Every number in the report is measured by this run.
"""

from kbcli.bench.layouts.config import LayoutResult, LayoutsConfig
from kbcli.bench.layouts.pipeline import Pipeline
from kbcli.bench.layouts.report import render, targets

__all__ = ["LayoutsConfig", "LayoutResult", "Pipeline", "render", "targets"]
