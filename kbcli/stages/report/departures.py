"""Departures from the paper: each the paper's sentence, what the judged method does, and why.

:data:`DEPARTURES` is the one list of them; the report's section "Departures from the paper" is
generated from it (:func:`departures_table`). Each row quotes the paper verbatim (a test checks
every quote against the paper's text) and says what kbcli does with the judged method's resolved
options, read from the evaluation. Every row is shown whatever the method's options (an option at its
default is a choice too); where the method follows the paper's text, the row says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.registry import Registry
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.runs import PAPER_STOP_ML
from kbcli.stages.report.source import compared, physical_mode, robot


@dataclass(frozen=True)
class Departure:
    """One way the judged method departs from the paper's text."""

    source: str  # where the paper says it
    quote: str  # the paper's sentence, verbatim
    does: Callable[[dict, Artifact], str]  # (robot options, evaluation) -> what kbcli does
    why: str


def _parts(r: dict) -> list[tuple[Registry, str]]:
    """The registered parts the method chose: its strategies, its posterior, its estimator."""
    return [*((STRATEGIES, s) for s in r.get("_strategies", ())),
            (POSTERIORS, r.get("posterior", "likelihood")), (ESTIMATORS, r.get("estimator", "mean"))]


def by_parts(key: str, default: Callable[[dict], str]) -> Callable[[dict, Artifact], str]:
    """What the method does where the paper says row ``key``: the text of the first of its parts
    that registered one (``traits={"departures": {key: fn(robot options) -> str}}``), else
    ``default(robot options)``."""
    def does(r: dict, art: Artifact) -> str:
        for reg, name in _parts(r):
            fn = reg.trait(name, "departures", {}).get(key) if name in reg else None
            if fn is not None:
                return fn(r)
        return default(r)
    return does


def _no_planner(r: dict) -> str:
    return "no active strategy in this method"


def _no_samples(r: dict) -> str:
    return f"not a KDE posterior ({r.get('posterior')}): no samples are drawn"


def _no_kde(r: dict) -> str:
    return f"not a KDE posterior ({r.get('posterior')})"


def _beyond(r: dict) -> str:
    return ("the likelihood table reads the pad beyond the working area as silent (the "
            "keyboard lies within it)")


def _estimate(r: dict) -> str:
    return f"the {r.get('estimator')} estimate, not the maximum-likelihood cell"


def _stop(r: dict, art: Artifact) -> str:
    T = art.attrs["max_steps"]
    if r.get("stop_ml") is None:
        return (f"not set for this method: every run takes {T} observations; the report applies "
                f"the paper's rule at {PAPER_STOP_ML:g} after the fact (section Stopping rules)")
    return (f"stop_ml = {r['stop_ml']:g} (the paper gives no number); every run still takes "
            f"{T} observations (Fig. 7's curves need one length), and the report applies the "
            "rule after the fact: touches to stop and the error at the stop (section Stopping "
            "rules)")


def _baseline(r: dict, art: Artifact) -> str:
    if r.get("random_actions") == "model":
        return (f"`{art.attrs['baseline']}` draws its touches from the model (a sound, then an "
                "action from p(a | s)): the paper leaves \"random selection\" open")
    return (f"`{art.attrs['baseline']}`: touches drawn uniformly over the working area")


def _model(r: dict, art: Artifact) -> str:
    if physical_mode(art.attrs["modes"]) is None:
        return "dynamics mode not evaluated"
    return (f"the dynamics claims are judged with the evaluation's model "
            f"({art.attrs.get('model_strategy')}, file "
            f"{art.inputs.get('model', {}).get('file')}); a second evaluation with the robot's "
            "own learned model is reported beside it when given (`kbcli report --own-model`)")


def _categories(r: dict, art: Artifact) -> str:
    return ("four fixed displacements per category at spread-out directions, the category by the "
            "Euclidean norm of (dx, dy): (0, 10], (10, 20], (20, 40] px")


def _test(r: dict, art: Artifact) -> str:
    return ("the two-sided, tie-corrected normal approximation of the rank-sum test; a run that "
            f"never gets below a threshold counts as {int(art.attrs['max_steps']) + 1} "
            "observations")


DEPARTURES: tuple[Departure, ...] = (
    Departure("Sect. III-E", "After a number of candidate actions are sampled from the model, we "
              "compute their confusion factor, which is the uncertainty of the model over which "
              "sound is heard after executing that candidate action.", by_parts("candidates", _no_planner),
              "the first implementation ranked by the predictive entropy it could compute for "
              "any posterior; issue 26 adds the paper's ranking"),
    Departure("Sect. III-E", "We do this by first simulating the execution of the action given the "
              "best hypothesis so far.", by_parts("simulation", _no_planner),
              "a KDE term per simulated sound would cost one Algorithm 2 per candidate and step"),
    Departure("Sect. III-D, Algorithm 2", "We obtain a sample of the actions a required to obtain "
              "the perceived sound  $s_t$ .", by_parts("samples", _no_samples),
              "drawing 10,000 samples per observation made the KDE posterior too slow for 50 "
              "runs per cell"),
    Departure("Sect. III-D, Eq. 7-8", "Now, given a sequence of independent actions", by_parts("floor", _no_kde),
              "a product of KDEs from finite samples is zero wherever one factor's samples "
              "missed: one touch would rule the truth out for good; the floor keeps the product "
              "defined"),
    Departure("Sect. III-D, Algorithm 2", "We approximate this distribution by sampling from the "
              "model and represent the hypotheses space with a kernel density estimate.",
              by_parts("beyond", _beyond),
              "the paper does not say what the robot knows beyond the area it explored; with "
              "samples that stop at its edge, a silent touch near the edge rules out every "
              "hypothesis that moves it beyond, the truth included (issue 39)"),
    Departure("Sect. III-D, Eq. 7", "where K is the kernel function used for the estimation and "
              "its parameters.", by_parts("bandwidth", _no_kde),
              "the paper names neither the kernel nor its parameters; a grid evaluation is exact "
              "where the paper's sampling [10] is approximate"),
    Departure("Sect. III-D", "At each time-step, we can compute the parameters which have the "
              "maximum likelihood in the current hypotheses space",
              by_parts("ml", _estimate),
              "the paper does not say how ties are broken; `argmax` takes the first"),
    Departure("Sect. III-D", "stop the process when it reaches a certain threshold", _stop,
              "the paper gives no threshold, and Fig. 7's curves need every run to the same "
              "length"),
    Departure("Sect. IV-A", "a baseline strategy, consisting in the random selection of samples",
              _baseline, "the paper does not say from what distribution the samples are drawn"),
    Departure("Sect. IV-B", "These categories refer to displacements up to 10, 20 and 40 pixels, "
              "respectively.", _categories,
              "the paper lists neither its parametrizations nor the norm"),
    Departure("Sect. IV-B", "we ran a Wilcoxon rank sum test", _test,
              "the paper states neither the variant nor how a run that never gets there counts"),
    Departure("Sect. IV-C", "the model learned with the iCub robot was not accurate enough",
              _model, "the near-exact default model isolates the dynamics from the model's "
              "quality; the robot's own model tests the paper's explanation"),
)


def departures(art: Artifact, method: str | None = None) -> list[tuple[Departure, str]]:
    """The departures in force for ``method`` (default: the judged one) with what it does."""
    name = method or art.attrs["judged"]
    r = {**robot(art, name), "_strategies": tuple(compared(art, name))}
    return [(d, d.does(r, art)) for d in DEPARTURES]


def departures_table(art: Artifact) -> list[str]:
    """The section "Departures from the paper" (markdown lines)."""
    judged = art.attrs["judged"]
    rows = departures(art)
    lines = ["## Departures from the paper", "",
             f"Where the judged method `{judged}` departs from the paper's text (quoted) or "
             "decides what it leaves open, with its resolved options.", "",
             "| source | the paper says | kbcli does | why |", "|---|---|---|---|"]
    for d, does in rows:
        lines.append(f"| {d.source} | \"{d.quote.strip()}\" | {does} | {d.why} |")
    if not rows:
        lines.append("| - | - | none for this method | - |")
    return [*lines, ""]
