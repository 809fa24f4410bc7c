"""The judging rules the paper does not state: kbcli's reading of each, and the plainest other.

The paper states its claims in words and a few numbers ("not so big", "restoring its previous
performance"); turning a sentence into a verdict takes rules it does not state. :data:`READINGS` is
the one list of them: the paper's words, kbcli's rule and the plainest other reading. The report
judges every claim under kbcli's rule and prints the verdict under each other reading beside it
(:class:`~kbcli.stages.report.source.Claim` ``readings``); the section "Judging rules" and the
departures table are generated from this list.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kbcli.errors import KbcliError
from kbcli.stages.artifact import Artifact


@dataclass(frozen=True)
class Reading:
    """One judging rule the paper does not state."""

    key: str
    name: str  # the other reading in a few words (the claims table's label)
    claims: str  # the claims it decides
    quote: str  # the paper's words, verbatim
    ours: str  # the rule kbcli applies
    other: str  # the plainest other reading, as a short label


READINGS: dict[str, Reading] = {r.key: r for r in (
    Reading("error", "RMSE per run", "every claim read on observations to an error threshold",
            "we also extracted how many samples are needed to obtain a root-mean-square error "
            "(RMSE) below a particular threshold",
            "a run's error is the Euclidean norm of its estimate's error in (dx, dy)",
            "a run's RMSE over the two coordinates, sqrt((ex^2 + ey^2) / 2)"),
    Reading("medium", "stated threshold alone", "medium displacements",
            "For medium displacements, the difference is not so big, although still significant",
            "significant up to 8 px (p < 1e-3) and a smaller advantage than on small displacements "
            "(one-sided test of the fall of A = P(fewer observations), DeLong's variance)",
            "its stated threshold alone: p < 1e-3 up to 8 px"),
    Reading("trend", "fall on the paper's thresholds", "the advantage across the three categories",
            "We obtained promising results, particularly when the magnitude of the displacement "
            "is small, compared to big displacements.",
            "A falls from each category to the next at every threshold informative in all three, "
            "and significantly from small to large at one of them",
            "on the thresholds the paper quotes (<= 10 px): a significant fall of A from small to "
            "large at one at least, a significant rise at none"),
    Reading("ns", "two-sided", "'not very significant' (large), 'not significant enough' (dynamics)",
            "However, for large displacements, the improvement is not very significant.",
            "no informative threshold with p < 0.01 in the strategy's favour (a strategy "
            "significantly slower than the baseline agrees)",
            "two-sided: no informative threshold with p < 0.01 either way"),
    Reading("restore", "restored by a test", "adaptation restores performance (dynamics)",
            "The robot correctly adapted to the perturbations introduced by the transforms, "
            "restoring its previous performance after the execution of the proposed algorithm.",
            "every strategy's median playing success after adaptation within 2 points of the "
            "median before the displacement",
            "a test: no strategy's playing success after adaptation significantly below the one "
            "before (one-sided Mann-Whitney, p < 0.01)"),
    Reading("entropy", "lower at every observation", "Fig. 6, the quicker decrease in entropy",
            "It can be seen how the active selection of samples exhibits a quicker decrease in "
            "the entropy",
            "the mean entropy below the baseline's at observations 5, 10 and 20",
            "the mean entropy below the baseline's at every observation"),
)}


#: One other reading's measurement of a claim: (label, measured text, verdict).
Alternative = tuple[str, str, str]


def reading(key: str, result: tuple[str, str] | None) -> Alternative:
    """One other reading's measurement of a claim (``result``: the rule's ``(text, verdict)``,
    None when the evaluation cannot be read so)."""
    label = READINGS[key].name
    if result is None:
        return label, "not measured (the evaluation holds no per-run errors)", "not measured"
    return label, result[0], result[1]


def join(*parts: Alternative) -> tuple[Alternative, ...]:
    return tuple(parts)


def as_text(alts) -> str:
    """Other readings in full: ``label: text [verdict]; ...``."""
    return " // ".join(f"{label}: {text} [{v}]" for label, text, v in alts)


def as_verdicts(alts) -> str:
    """Other readings in short: ``label: verdict; ...`` ('-' when none)."""
    return "; ".join(f"{label}: {v}" for label, _, v in alts) or "-"


def rms_view(art: Artifact) -> Artifact | None:
    """The evaluation read with each run's RMSE over the two coordinates instead of its
    Euclidean error (every error divided by sqrt(2), the summaries recomputed from the per-run
    records: :func:`kbcli.stages.evaluate.assembly.resummarise`); None when the evaluation
    cannot be re-read so (no per-run records, or a config this version does not read)."""
    from kbcli.stages.evaluate.assembly import resummarise

    try:
        return resummarise(art, error_scale=1 / math.sqrt(2))
    except (KbcliError, KeyError, ValueError):
        return None


def table() -> list[str]:
    """The section "Judging rules" (markdown lines)."""
    lines = ["## Judging rules the paper does not state", "",
             "Each claim's verdict is kbcli's reading of the paper's words; where the paper states "
             "no rule, the claims table also gives the verdict under the plainest other reading "
             "(column *other readings*), so that no verdict rests on an unstated rule unseen.", "",
             "| decides | the paper says | kbcli's rule | the plainest other reading |",
             "|---|---|---|---|"]
    lines += [f"| {r.claims} | \"{r.quote}\" | {r.ours} | *{r.name}*: {r.other} |"
              for r in READINGS.values()]
    return [*lines, ""]
