"""Departures from the paper: each the paper's sentence, what the judged method does, and why.

:data:`DEPARTURES` is the one list of them; the report's section "Departures from the paper" is
generated from it (:func:`departures_table`). Each row quotes the paper verbatim (a test checks
every quote against the paper's text) and says what kbcli does with the judged method's resolved
options, read from the evaluation; a row whose ``does`` returns None is not a departure for that
method (e.g. the paper's stopping rule once the method sets ``stop_ml``) and is left out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from kbcli.stages.artifact import Artifact
from kbcli.stages.report.source import compared, robot


@dataclass(frozen=True)
class Departure:
    """One way the judged method departs from the paper's text."""

    source: str  # where the paper says it
    quote: str  # the paper's sentence, verbatim
    does: Callable[[dict, Artifact], str | None]  # (robot options, evaluation) -> what kbcli does
    why: str


def _opt(r: dict, key: str, default="(default)"):
    return r.get(key, default)


def _candidates(r: dict, art: Artifact) -> str | None:
    if "active" not in r.get("_strategies", ()):  # `paper-active` is Sect. III-E's own strategy
        return None
    return (f"`active` draws {_opt(r, 'candidates')} candidates uniformly over the working area "
            f"and ranks them by the entropy of the posterior predictive over "
            f"{_opt(r, 'active_hypotheses')} hypotheses, keeping the {_opt(r, 'active_keep')} "
            "most confusing; the model's own confusion factor (`LearnedModel.confusion`) is not "
            "used")


def _simulation(r: dict, art: Artifact) -> str | None:
    if "active" not in r.get("_strategies", ()):
        return None
    return ("each kept candidate is simulated with the model's likelihood table, not a KDE term "
            "of Algorithm 2; at the first step the best hypothesis of a flat posterior is the "
            "grid's first cell")


def _samples(r: dict, art: Artifact) -> str | None:
    if r.get("posterior") != "kde" or r.get("kde_draw") == "fresh":
        return None
    return (f"{_opt(r, 'kde_samples')} actions per sound are drawn once and shared by every "
            "experiment of the evaluation, so the runs of a cell share their Monte-Carlo noise")


def _floor(r: dict, art: Artifact) -> str | None:
    eps = r.get("kde_floor")
    if eps is None:  # None: the outlier rate (AdapterConfig.kde_eps)
        eps = r.get("outlier", 1e-3)
    if r.get("posterior") != "kde" or eps == 0:
        return None
    return (f"every KDE factor is mixed with eps = {eps:g} of the uniform prior (a floor); the "
            "samples of silence are restricted to the working area")


def _bandwidth(r: dict, art: Artifact) -> str | None:
    if r.get("posterior") != "kde":
        return None
    bw = r.get("kde_bandwidth")
    return ("a Gaussian kernel, its std " + ("by Scott's rule" if bw is None else f"{bw:g} px")
            + f"; the product is evaluated on a grid of {_opt(r, 'resolution')} px over "
            f"+-{_opt(r, 'prior_halfwidth')} px, not sampled")


def _ml(r: dict, art: Artifact) -> str | None:
    if r.get("estimator") != "ml" or r.get("ml_ties") == "random":
        return None
    return ("the maximum-likelihood cell; ties go to the lowest grid index (the corner and "
            "edges of the prior box), so every ML verdict is also read with the posterior mean "
            "of the same runs")


def _stop(r: dict, art: Artifact) -> str | None:
    if r.get("stop_ml") is not None:
        return None
    return f"off: every run takes {art.attrs['max_steps']} observations"


def _baseline(r: dict, art: Artifact) -> str | None:
    if r.get("random_actions") == "model":
        return (f"`{art.attrs['baseline']}` draws its touches from the model (a sound, then an "
                "action from p(a | s)): the paper leaves \"random selection\" open")
    return (f"`{art.attrs['baseline']}`: touches drawn uniformly over the working area")


def _model(r: dict, art: Artifact) -> str | None:
    if "dynamics" not in art.attrs["modes"]:
        return None
    return (f"the dynamics claims are judged with the evaluation's model "
            f"({art.attrs.get('model_strategy')}, file "
            f"{art.inputs.get('model', {}).get('file')}); a second evaluation with the robot's "
            "own learned model is reported beside it when given (`kbcli report --own-model`)")


def _categories(r: dict, art: Artifact) -> str | None:
    return ("four fixed displacements per category at spread-out directions, the category by the "
            "Euclidean norm of (dx, dy): (0, 10], (10, 20], (20, 40] px")


def _test(r: dict, art: Artifact) -> str | None:
    return ("the two-sided, tie-corrected normal approximation of the rank-sum test; a run that "
            f"never gets below a threshold counts as {int(art.attrs['max_steps']) + 1} "
            "observations")


DEPARTURES: tuple[Departure, ...] = (
    Departure("Sect. III-E", "After a number of candidate actions are sampled from the model, we "
              "compute their confusion factor, which is the uncertainty of the model over which "
              "sound is heard after executing that candidate action.", _candidates,
              "the first implementation ranked by the predictive entropy it could compute for "
              "any posterior; issue 26 adds the paper's ranking"),
    Departure("Sect. III-E", "We do this by first simulating the execution of the action given the "
              "best hypothesis so far.", _simulation,
              "a KDE term per simulated sound would cost one Algorithm 2 per candidate and step"),
    Departure("Sect. III-D, Algorithm 2", "We obtain a sample of the actions a required to obtain "
              "the perceived sound  $s_t$ .", _samples,
              "drawing 10,000 samples per observation made the KDE posterior too slow for 50 "
              "runs per cell"),
    Departure("Sect. III-D, Eq. 7-8", "Now, given a sequence of independent actions", _floor,
              "a product of KDEs from finite samples is zero wherever one factor's samples "
              "missed: one touch would rule the truth out for good; the floor keeps the product "
              "defined"),
    Departure("Sect. III-D, Eq. 7", "where K is the kernel function used for the estimation and "
              "its parameters.", _bandwidth,
              "the paper names neither the kernel nor its parameters; a grid evaluation is exact "
              "where the paper's sampling [10] is approximate"),
    Departure("Sect. III-D", "At each time-step, we can compute the parameters which have the "
              "maximum likelihood in the current hypotheses space", _ml,
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
    out = []
    for d in DEPARTURES:
        does = d.does(r, art)
        if does is not None:
            out.append((d, does))
    return out


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
