"""Stage ``report``: the paper's claims against what an evaluation measured (Sect. IV, Figs. 5-7).

From an ``evaluation`` artifact this builds the text of ``report/README.md``: what was run, the
claims table and the tables behind it. Figures are :mod:`kbcli.viz.report`'s; files are written by
the CLI. Pure: no I/O. Every number printed comes from the artifact or is labelled as the paper's.

How each claim is judged, on the *judged* method (``paper``), every other method beside it:

- *significance up to X px* (Sect. IV-B): at every threshold <= X px that the strategy or the
  baseline reaches in at least half its runs, the tie-corrected Mann-Whitney p-value is below the
  paper's bound and the strategy needed fewer observations (*underpowered* when the smallest
  p-value the runs can give is not below it);
- *not significant* (large displacements; dynamics mode): no informative threshold has p < 0.01 in
  the strategy's favour (*underpowered* when 0.01 is not attainable);
- *quicker entropy decrease* (Fig. 6): active's mean posterior entropy is below random's at
  observations 5, 10 and 20;
- *adaptation restores performance* (Sect. IV-C, dynamics mode): for every strategy, the median
  playing success after adaptation is at least the median before the displacement minus
  :data:`RESTORED_MARGIN`.
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
