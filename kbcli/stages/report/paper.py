"""The paper's claims (Sect. IV-A, IV-B, IV-C) judged on the judged method, the others beside."""

from __future__ import annotations

from dataclasses import replace
from functools import partial

from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.effects import falls, shrinks
from kbcli.stages.report.judge import (
    beside,
    combine,
    entropy_claim,
    large_why,
    not_significant,
    restores,
    significance,
    whole,
)
from kbcli.stages.report.readings import join, reading, rms_view
from kbcli.stages.report.source import (
    Claim,
    check,
    compared,
    exact_mode,
    methods_of,
    others,
    physical_mode,
    robot,
    short,
    upgrade,
)

FIG6 = "active exhibits a quicker decrease in entropy than random (Fig. 6)"
#: Sect. IV-B per category: (category, source, the paper's words, rule), the rule being
#: ("sig", up to px, p bound) or ("ns",).
DISPLACEMENT_CLAIMS = (
    ("small", "Sect. IV-B, Fig. 7", "small displacements (<= 10 px): active beats random, "
     "p < 1e-5 for RMSE thresholds up to 10 px", ("sig", 10.0, 1e-5)),
    ("medium", "Sect. IV-B, Fig. 7", "medium displacements (<= 20 px): still significant, "
     "p < 1e-3 up to 8 px, but the difference is not so big (a smaller advantage than on small "
     "displacements)", ("sig", 8.0, 1e-3, "small")),
    ("large", "Sect. IV-B, Fig. 7", "large displacements (<= 40 px): the improvement is not "
     "very significant", ("ns",)),
)
#: The paper's trend across the categories (Sect. IV-B, Fig. 7), judged on effect sizes.
TREND = ("Sect. IV-B, Fig. 7", "the advantage shrinks as the displacement grows (small, then "
         "medium, then large displacements)")
#: The estimate a verdict is also read with when the judged method's is the ML cell (whose
#: tie rule could decide it): the posterior mean of the same runs.
OTHER_ESTIMATE = ("_mean", "the posterior mean of the same runs")
DYN_RESTORES = "with robot dynamics the robot adapts and restores its previous performance"
DYN_NS = ("with robot dynamics the differences between the strategies were not significant "
          "enough")


def claims(art: Artifact, own: Artifact | None = None) -> list[Claim]:
    """The paper's claims (Sect. IV-A, IV-B, IV-C) judged on the judged method, others beside;
    with ``own`` (the same protocol evaluated with the robot's own learned model) the Sect. IV-C
    claims once more on it, beside those on ``art``'s model."""
    art = upgrade(art)
    check(art)
    modes = art.attrs["modes"]
    ideal = exact_mode(modes)
    rms = rms_view(art)
    out = [*_entropy_claims(art, ideal), *_displacement_claims(art, ideal, rms),
           *_dynamics_claims(art, rms)]
    return out + (own_model_claims(own) if own is not None else [])


OWN_SOURCE = "Sect. IV-C, the robot's own model"


def own_model_claims(own: Artifact) -> list[Claim]:
    """The Sect. IV-C claims judged on an evaluation run with the robot's own learned model (the
    paper's "model learned with the iCub robot"), each measured text naming that model."""
    own = upgrade(own)
    check(own)
    model = own.inputs.get("model", {})
    label = (f"with the robot's own model ({own.attrs.get('model_strategy')}, file "
             f"{model.get('file')}, sha256 `{str(model.get('sha256'))[:16]}`)")
    return [replace(c, source=OWN_SOURCE, measured=f"{label}: {c.measured}")
            for c in _dynamics_claims(own, rms_view(own))]


def _entropy_claims(art: Artifact, ideal: str | None) -> list[Claim]:
    judged, base = art.attrs["judged"], art.attrs["baseline"]
    opts = short(art, judged)
    out = []
    for s in compared(art, judged):
        if ideal is None:
            out.append(Claim("Sect. IV-A, Fig. 6", FIG6, judged, opts, "ideal mode not evaluated",
                             "not measured"))
            continue
        measured, verdict = entropy_claim(art, ideal, judged, s)
        others_ = beside(art, lambda x, s2: entropy_claim(art, ideal, x, s2))
        alt = join(reading("entropy", entropy_claim(art, ideal, judged, s, every_step=True)))
        out.append(Claim("Sect. IV-A, Fig. 6", FIG6, judged, opts, f"{s} vs {base}: {measured}",
                         verdict, others_, readings=alt, mode=ideal, strategy=s))
    return out


def rule_fn(art: Artifact, mode: str, cat: str, rule: tuple, sfx: str = ""):
    """The claim's rule as ``fn(method, strategy) -> (measured, verdict)``; ``sfx`` reads another
    estimate of the same runs. A rule with a fourth element (a category) is judged whole: also
    'the advantage is smaller than on that category' (:func:`~kbcli.stages.report.effects.shrinks`)."""
    if rule[0] != "sig":
        return lambda x, s: not_significant(art, mode, x, cat, s, sfx)
    sig = partial(significance, art, mode, upto=rule[1], bound=rule[2], sfx=sfx, category=cat)
    if len(rule) < 4:
        return lambda x, s: sig(method=x, strategy=s)

    def both(x: str, s: str) -> tuple[str, str]:
        m1, v1 = sig(method=x, strategy=s)
        if m1 == "not evaluated":
            return m1, v1
        m2, v2 = shrinks(art, mode, x, s, [rule[3], cat], upto=rule[1], sfx=sfx)
        return (f"significant: {m1} [{v1}]; smaller than on {rule[3]} displacements: {m2} "
                f"[{v2}]"), whole([v1, v2])
    return both


def _trend_fn(art: Artifact, mode: str, sfx: str = ""):
    cats = [c for c, *_ in DISPLACEMENT_CLAIMS]
    return lambda x, s: shrinks(art, mode, x, s, cats, sfx=sfx)


def _other_estimate(art: Artifact, method: str, fn_of_sfx, s: str, verdict: str) -> str:
    """The same claim read with the posterior mean when ``method`` estimates by the ML cell (so
    that no verdict rests on its tie rule unseen), or ''."""
    if not ESTIMATORS.trait(robot(art, method).get("estimator", "mean"), "ties", False):
        return ""
    sfx, label = OTHER_ESTIMATE
    text, v = fn_of_sfx(sfx)(method, s)
    if v == "not measured":  # e.g. an artifact without that estimate's records
        return ""
    note = "" if v == verdict else (" (this verdict differs from the ML estimate's: the "
                                    "claim's verdict rests on the estimate)")
    return f"; {label}: {text} [{v}]{note}"


def _alternatives(art: Artifact, rms: Artifact | None, mode: str, cat: str, rule: tuple,
                  method: str, strategy: str) -> tuple:
    """A displacement claim under the plainest other reading of each unstated rule it rests on
    (:mod:`.readings`)."""
    parts = [reading("error", rule_fn(rms, mode, cat, rule)(method, strategy)
                     if rms is not None else None)]
    if len(rule) > 3:  # medium: its stated threshold alone
        parts.append(reading("medium", rule_fn(art, mode, cat, rule[:3])(method, strategy)))
    if rule[0] == "ns":
        parts.append(reading("ns", not_significant(art, mode, method, cat, strategy,
                                                   two_sided=True)))
    return join(*parts)


def _displacement_claims(art: Artifact, ideal: str | None,
                         rms: Artifact | None = None) -> list[Claim]:
    judged, base = art.attrs["judged"], art.attrs["baseline"]
    opts = short(art, judged)
    out = []
    for cat, source, text, rule in DISPLACEMENT_CLAIMS:
        for s in compared(art, judged):
            if ideal is None or cat not in art.attrs["categories"]:
                out.append(Claim(source, text, judged, opts, f"{s}: not evaluated (needs ideal "
                                 f"mode and the {cat} category)", "not measured"))
                continue
            fn = rule_fn(art, ideal, cat, rule)
            measured, verdict = fn(judged, s)
            measured += _other_estimate(art, judged, partial(rule_fn, art, ideal, cat, rule), s,
                                        verdict)
            why = large_why(art, ideal) if cat == "large" else ""
            out.append(Claim(source, text, judged, opts, f"{s} vs {base}: {measured}", verdict,
                             beside(art, fn), why,
                             _alternatives(art, rms, ideal, cat, rule, judged, s), ideal, s))
    return out + _trend_claims(art, ideal, rms)


def _trend_claims(art: Artifact, ideal: str | None, rms: Artifact | None = None) -> list[Claim]:
    judged, base = art.attrs["judged"], art.attrs["baseline"]
    opts = short(art, judged)
    cats = [c for c, *_ in DISPLACEMENT_CLAIMS]
    out = []
    for s in compared(art, judged):
        if ideal is None or any(c not in art.attrs["categories"] for c in cats):
            out.append(Claim(*TREND, judged, opts, f"{s}: not evaluated (needs ideal mode and "
                             "every category)", "not measured"))
            continue
        fn = _trend_fn(art, ideal)
        measured, verdict = fn(judged, s)
        measured += _other_estimate(art, judged, partial(_trend_fn, art, ideal), s, verdict)
        alt = join(reading("error", _trend_fn(rms, ideal)(judged, s) if rms is not None else None),
                   reading("trend", falls(art, ideal, judged, s, cats)))
        out.append(Claim(*TREND, judged, opts, f"{s} vs {base}: {measured}", verdict,
                         beside(art, fn), readings=alt, mode=ideal, strategy=s))
    return out


def _dynamics(art: Artifact, x: str, s: str, sfx: str = "", *,
              two_sided: bool = False) -> tuple[str, str]:
    """'Not significant' in dynamics mode over every category, one verdict."""
    parts, verdicts = [], []
    for cat in art.attrs["categories"]:
        m, v = not_significant(art, physical_mode(art.attrs["modes"]), x, cat, s, sfx,
                               two_sided=two_sided)
        if m == "not evaluated":
            continue
        parts.append(f"{cat}: {m}")
        verdicts.append(v)
    if not parts:
        return "not evaluated", "not measured"
    return "; ".join(parts), combine(verdicts)


def _dynamics_claims(art: Artifact, rms: Artifact | None = None) -> list[Claim]:
    judged, base = art.attrs["judged"], art.attrs["baseline"]
    opts = short(art, judged)
    mode = physical_mode(art.attrs["modes"])
    if mode is None:
        return [Claim("Sect. IV-C", DYN_RESTORES, judged, opts, "dynamics mode not evaluated",
                      "not measured"),
                Claim("Sect. IV-C", DYN_NS, judged, opts, "dynamics mode not evaluated",
                      "not measured")]
    measured, verdict = restores(art, judged)
    others_ = "; ".join(f"{x}: {restores(art, x)[0]} [{restores(art, x)[1]}]"
                        for x in others(art) if physical_mode(methods_of(art)[x]["modes"]))
    out = [Claim("Sect. IV-C", DYN_RESTORES, judged, opts, measured, verdict, others_,
                 readings=join(reading("restore", restores(art, judged, test=True))),
                 mode=mode)]

    dyn = partial(_dynamics, art)
    for s in compared(art, judged):
        measured, verdict = dyn(judged, s)
        measured += _other_estimate(art, judged, lambda sfx: partial(_dynamics, art, sfx=sfx), s,
                                    verdict)
        alt = join(reading("error", _dynamics(rms, judged, s) if rms is not None else None),
                   reading("ns", _dynamics(art, judged, s, two_sided=True)))
        out.append(Claim("Sect. IV-C", DYN_NS, judged, opts, f"{s} vs {base}: {measured}",
                         verdict, beside(art, dyn), readings=alt, mode=mode, strategy=s))
    return out


def claim_rules(art: Artifact) -> dict:
    """Each claim's rule by its paper text, ``fn(method, strategy) -> (measured, verdict)``, for
    judging a claim on any method of ``art`` (the ablation ladder: :mod:`.ablation`)."""
    art = upgrade(art)
    modes = art.attrs["modes"]
    rules: dict = {}
    ideal = exact_mode(modes)
    if ideal is not None:
        rules[FIG6] = lambda x, s: entropy_claim(art, ideal, x, s)
        for cat, _, text, rule in DISPLACEMENT_CLAIMS:
            if cat in art.attrs["categories"]:
                rules[text] = rule_fn(art, ideal, cat, rule)
        if all(c in art.attrs["categories"] for c, *_ in DISPLACEMENT_CLAIMS):
            rules[TREND[1]] = _trend_fn(art, ideal)
    if physical_mode(modes) is not None:
        rules[DYN_RESTORES] = lambda x, s: restores(art, x)
        rules[DYN_NS] = partial(_dynamics, art)
    return rules
