"""Stage ``report``: the paper's claims against what an evaluation measured (Sect. IV, Figs. 5-7).

From an ``evaluation`` artifact this builds the text of ``report/README.md``: what was run (every
method and every option it resolved to), the claims table, and the tables behind it (observations
to each error threshold, p-values against the baseline, RMSE at chosen steps, measured playing
success, the large-displacement ablation). Figures are drawn by :mod:`kbcli.viz.report`; files are
written by the CLI. Pure: no I/O. Every number printed comes from the artifact or is labelled as
the paper's.

How each claim is judged, on the *judged* method (``paper``: the paper's own posterior, estimator
and strategies), with every other method shown beside it (stated in the README too):

- *significance up to X px* (Sect. IV-B): at every threshold <= X px that the compared strategy or
  the baseline reaches in at least half its runs, the tie-corrected Mann-Whitney p-value is below
  the paper's bound and the strategy needed fewer observations; *underpowered* instead of
  *differs* when a threshold misses the bound but the smallest p-value the number of runs can give
  at all is not below it; thresholds reached by neither in half their runs are uninformative;
- *not significant* (large displacements; dynamics mode): no informative threshold has p < 0.01 in
  the strategy's favour (*underpowered* when 0.01 is not attainable);
- *quicker entropy decrease* (Fig. 6): active's mean posterior entropy is below random's at
  observations 5, 10 and 20 (those within ``max_steps``);
- *adaptation restores performance* (Sect. IV-C, dynamics mode): for every strategy, the median
  playing success after adaptation (measured by replaying the melody with the final estimate) is
  at least the median measured before the displacement minus :data:`RESTORED_MARGIN`.

The package: :mod:`~kbcli.stages.report.source` (reading the artifact, the value types),
:mod:`~kbcli.stages.report.judge` (the rules), :mod:`~kbcli.stages.report.effects` (effect
sizes: medium's *not so big*, the trend across categories), :mod:`~kbcli.stages.report.paper` (the
claims), :mod:`~kbcli.stages.report.departures` (the departures from the paper's text),
:mod:`~kbcli.stages.report.ablation` (what explains each difference, from the ablation ladder),
:mod:`~kbcli.stages.report.tables`, :mod:`~kbcli.stages.report.captions` (the figures) and
:mod:`~kbcli.stages.report.readme` (:func:`build`).
"""

from __future__ import annotations

from kbcli.stages.report.captions import figures
from kbcli.stages.report.paper import claims
from kbcli.stages.report.readme import build
from kbcli.stages.report.source import (
    ENTROPY_STEPS,
    KEY_OPTIONS,
    NOT_SIGNIFICANT,
    RESTORED_MARGIN,
    RMSE_STEPS,
    VERDICTS,
    Claim,
    Figure,
    Report,
    method_names,
    ordered,
    prior_entropy,
    upgrade,
)

__all__ = ["ENTROPY_STEPS", "KEY_OPTIONS", "NOT_SIGNIFICANT", "RESTORED_MARGIN", "RMSE_STEPS",
           "VERDICTS", "Claim", "Figure", "Report", "build", "claims", "figures", "method_names",
           "ordered", "prior_entropy", "upgrade"]
