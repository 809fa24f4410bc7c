"""The paper's claims (Sect. IV-A, IV-B, IV-C) judged on the judged method, the others beside."""

from __future__ import annotations

from functools import partial

from kbcli.stages.artifact import Artifact
from kbcli.stages.report.judge import (
    beside,
    combine,
    entropy_claim,
    large_why,
    not_significant,
    restores,
    significance,
)
from kbcli.stages.report.source import Claim, check, compared, methods_of, others, short, upgrade

FIG6 = "active exhibits a quicker decrease in entropy than random (Fig. 6)"
#: Sect. IV-B per category: (category, source, the paper's words, rule), the rule being
#: ("sig", up to px, p bound) or ("ns",).
DISPLACEMENT_CLAIMS = (
    ("small", "Sect. IV-B, Fig. 7", "small displacements (<= 10 px): active beats random, "
     "p < 1e-5 for RMSE thresholds up to 10 px", ("sig", 10.0, 1e-5)),
    ("medium", "Sect. IV-B, Fig. 7", "medium displacements (<= 20 px): still significant, "
     "p < 1e-3 up to 8 px", ("sig", 8.0, 1e-3)),
    ("large", "Sect. IV-B, Fig. 7", "large displacements (<= 40 px): the improvement is not "
     "very significant", ("ns",)),
)
DYN_RESTORES = "with robot dynamics the robot adapts and restores its previous performance"
DYN_NS = ("with robot dynamics the differences between the strategies were not significant "
          "enough")


def claims(art: Artifact) -> list[Claim]:
    """The paper's claims (Sect. IV-A, IV-B, IV-C) judged on the judged method, others beside."""
    art = upgrade(art)
    check(art)
    modes = art.attrs["modes"]
    ideal = "ideal" if "ideal" in modes else None
    return [*_entropy_claims(art, ideal), *_displacement_claims(art, ideal),
            *_dynamics_claims(art)]


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
        out.append(Claim("Sect. IV-A, Fig. 6", FIG6, judged, opts, f"{s} vs {base}: {measured}",
                         verdict, others_))
    return out


def _rule(art: Artifact, mode: str, cat: str, rule: tuple):
    """The claim's rule as ``fn(method, strategy) -> (measured, verdict)``."""
    if rule[0] == "sig":
        return lambda x, s: significance(art, mode, x, cat, s, rule[1], rule[2])
    return lambda x, s: not_significant(art, mode, x, cat, s)


def _displacement_claims(art: Artifact, ideal: str | None) -> list[Claim]:
    judged, base = art.attrs["judged"], art.attrs["baseline"]
    opts = short(art, judged)
    out = []
    for cat, source, text, rule in DISPLACEMENT_CLAIMS:
        for s in compared(art, judged):
            if ideal is None or cat not in art.attrs["categories"]:
                out.append(Claim(source, text, judged, opts, f"{s}: not evaluated (needs ideal "
                                 f"mode and the {cat} category)", "not measured"))
                continue
            fn = _rule(art, ideal, cat, rule)
            measured, verdict = fn(judged, s)
            why = large_why(art, ideal) if cat == "large" else ""
            out.append(Claim(source, text, judged, opts, f"{s} vs {base}: {measured}", verdict,
                             beside(art, fn), why))
    return out


def _dynamics(art: Artifact, x: str, s: str) -> tuple[str, str]:
    """'Not significant' in dynamics mode over every category, one verdict."""
    parts, verdicts = [], []
    for cat in art.attrs["categories"]:
        m, v = not_significant(art, "dynamics", x, cat, s)
        if m == "not evaluated":
            continue
        parts.append(f"{cat}: {m}")
        verdicts.append(v)
    if not parts:
        return "not evaluated", "not measured"
    return "; ".join(parts), combine(verdicts)


def _dynamics_claims(art: Artifact) -> list[Claim]:
    judged, base = art.attrs["judged"], art.attrs["baseline"]
    opts = short(art, judged)
    if "dynamics" not in art.attrs["modes"]:
        return [Claim("Sect. IV-C", DYN_RESTORES, judged, opts, "dynamics mode not evaluated",
                      "not measured"),
                Claim("Sect. IV-C", DYN_NS, judged, opts, "dynamics mode not evaluated",
                      "not measured")]
    measured, verdict = restores(art, judged)
    others_ = "; ".join(f"{x}: {restores(art, x)[0]} [{restores(art, x)[1]}]"
                        for x in others(art) if "dynamics" in methods_of(art)[x]["modes"])
    out = [Claim("Sect. IV-C", DYN_RESTORES, judged, opts, measured, verdict, others_)]

    dyn = partial(_dynamics, art)
    for s in compared(art, judged):
        measured, verdict = dyn(judged, s)
        out.append(Claim("Sect. IV-C", DYN_NS, judged, opts, f"{s} vs {base}: {measured}",
                         verdict, beside(art, dyn)))
    return out
