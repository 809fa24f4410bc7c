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

from kbcli.core.adapt_setup import KERNEL_REACH, MAX_BANDWIDTH
from kbcli.core.kde import ZERO_RTOL
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.runs import PAPER_STOP_ML
from kbcli.stages.report.source import compared, robot


@dataclass(frozen=True)
class Departure:
    """One way the judged method departs from the paper's text."""

    source: str  # where the paper says it
    quote: str  # the paper's sentence, verbatim
    does: Callable[[dict, Artifact], str]  # (robot options, evaluation) -> what kbcli does
    why: str


def _opt(r: dict, key: str, default="(default)"):
    return r.get(key, default)


def _uses_kde(r: dict) -> bool:
    return r.get("posterior") == "kde"


def _candidates(r: dict, art: Artifact) -> str:
    if "active" in r.get("_strategies", ()):
        return (f"`active` draws {_opt(r, 'candidates')} candidates uniformly over the working "
                "area and ranks them by the entropy of the posterior predictive over "
                f"{_opt(r, 'active_hypotheses')} hypotheses, keeping the "
                f"{_opt(r, 'active_keep')} most confusing; the model's own confusion factor is "
                "not used")
    if "paper-active" in r.get("_strategies", ()):
        return (f"`paper-active`: {_opt(r, 'candidates')} candidates sampled from the model (a "
                "sound uniform over the model's sounds, then an action from p(a | s)), ranked by "
                f"the model's confusion factor 1 - (p1 - p2), the {_opt(r, 'active_keep')} most "
                "confusing kept (the counts and the sounds' distribution are open)")
    return "no active strategy in this method"


def _simulation(r: dict, art: Artifact) -> str:
    if "active" in r.get("_strategies", ()):
        return ("each kept candidate is simulated with the model's likelihood table, not a KDE "
                "term of Algorithm 2; at the first step the best hypothesis of a flat posterior "
                "is the grid's first cell")
    if "paper-active" in r.get("_strategies", ()):
        sim = r.get("simulate_draw") or r.get("kde_draw", "shared")
        return ("each kept candidate's sound simulated at the maximum-likelihood hypothesis and "
                "the whole posterior updated with the method's own term"
                + (f" (KDE samples of the simulated touches: {sim})" if _uses_kde(r) else ""))
    return "no active strategy in this method"


def _samples(r: dict, art: Artifact) -> str:
    if not _uses_kde(r):
        return f"not a KDE posterior ({r.get('posterior')}): no samples are drawn"
    if r.get("kde_draw") == "fresh":
        return (f"Algorithm 2 as written: N = {_opt(r, 'kde_samples')} new actions per "
                f"observation (N is open), drawn from the model's "
                f"{_opt(r, 'kde_sampler')} sampler")
    return (f"{_opt(r, 'kde_samples')} actions per sound are drawn once and shared by every "
            "experiment of the evaluation, so the runs of a cell share their Monte-Carlo noise")


def _floor(r: dict, art: Artifact) -> str:
    if not _uses_kde(r):
        return f"not a KDE posterior ({r.get('posterior')})"
    eps = r.get("kde_floor")
    if eps is None:  # None: the outlier rate (AdapterConfig.kde_eps)
        eps = r.get("outlier", 1e-3)
    if eps == 0:
        return ("no floor (Eq. 7 as written): a hypothesis that no sample of a touch's sound "
                "supports is ruled out by that touch")
    return f"every KDE factor is mixed with eps = {eps:g} of the uniform prior (a floor)"


def _beyond(r: dict, art: Artifact) -> str:
    if not _uses_kde(r):
        return ("the likelihood table reads the pad beyond the working area as silent (the "
                "keyboard lies within it)")
    if r.get("kde_beyond", "unknown") == "silent":
        return ("kbcli's reading: the pad beyond the working area is silent, so silence's "
                "samples cover a ring beyond it as wide as a hypothesis can move a touch back "
                "(prior half-width plus a kernel's reach); a silent touch is never ruled out "
                "only because the samples stop at the area's edge (`kde_beyond = silent`)")
    return ("silence's samples stop at the working area's edge: a hypothesis that moves a "
            "silent touch beyond it gets no support" + (" (ruled out, no floor)"
                                                       if r.get("kde_floor") == 0 else "")
            + " (`kde_beyond = unknown`, made before issue 39 or set so)")


def _bandwidth(r: dict, art: Artifact) -> str:
    if not _uses_kde(r):
        return f"not a KDE posterior ({r.get('posterior')})"
    bw = r.get("kde_bandwidth")
    rule = (f"{bw:g} px" if bw is not None else
            "Scott's rule sigma n^(-1/6) with Silverman's robust spread min(std, IQR / 1.349), "
            f"clipped to [{_opt(r, 'resolution')}, {MAX_BANDWIDTH:g}] px")
    return (f"a Gaussian kernel, its std {rule}, cut at {KERNEL_REACH:g} std; without a floor, "
            f"densities below {ZERO_RTOL:g} of a term's peak are read as zero (the FFT's "
            f"rounding); the product is evaluated on a grid of {_opt(r, 'resolution')} px over "
            f"+-{_opt(r, 'prior_halfwidth')} px, not sampled")


def _ml(r: dict, art: Artifact) -> str:
    if r.get("estimator") != "ml":
        return f"the {r.get('estimator')} estimate, not the maximum-likelihood cell"
    if r.get("ml_ties") == "random":
        return ("the maximum-likelihood cell; ties broken uniformly at random (seeded), so no "
                "corner of the prior box is favoured")
    return ("the maximum-likelihood cell; ties go to the lowest grid index (the corner and "
            "edges of the prior box), so every ML verdict is also read with the posterior mean "
            "of the same runs")


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
    if "dynamics" not in art.attrs["modes"]:
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
    Departure("Sect. III-D, Algorithm 2", "We approximate this distribution by sampling from the "
              "model and represent the hypotheses space with a kernel density estimate.", _beyond,
              "the paper does not say what the robot knows beyond the area it explored; with "
              "samples that stop at its edge, a silent touch near the edge rules out every "
              "hypothesis that moves it beyond, the truth included (issue 39)"),
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
