"""The verdicts: each claim's rule applied to one method of an evaluation.

The rules (:func:`significance`, :func:`not_significant`, :func:`entropy_claim`,
:func:`restores`) return ``(measured text, verdict)``, the verdict one of
:data:`~kbcli.stages.report.source.VERDICTS`; :func:`beside` gathers the other methods'
measurements of a claim and :func:`large_why` a measured account of the large-displacement claim.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.adaptation import stats
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.source import (
    ENTROPY_STEPS,
    NOT_SIGNIFICANT,
    RESTORED_MARGIN,
    cell,
    compared,
    fmt_p,
    methods_of,
    others,
    pct,
    physical_mode,
    played,
    readings,
    robot,
)


def _tested(art: Artifact, mode: str, method: str, category: str, strategy: str,
            sfx: str = "") -> tuple | None:
    """(thresholds, baseline name, the cell's curves, the strategy's tests) of one cell, or None
    when the strategy was not tested there."""
    cur, pvs = cell(art, mode, method, category)
    if cur is None or strategy not in pvs or f"pvalue{sfx}" not in pvs[strategy]:
        return None
    return art.array("thresholds"), art.attrs["baseline"], cur, pvs[strategy]


def _thresholds(tested: tuple, strategy: str, sfx: str = ""):
    """Each threshold of a tested cell as ``(px, p-value, statistic, informative)``: informative
    when the strategy or the baseline reaches it in half the runs or more."""
    thr, base, cur, pv = tested
    for j, t in enumerate(thr):
        reached = max(cur[strategy][f"reached{sfx}"][j], cur[base][f"reached{sfx}"][j])
        yield t, pv[f"pvalue{sfx}"][j], pv[f"statistic{sfx}"][j], not reached < 0.5


def _sorted_thresholds(tested: tuple, strategy: str, upto: float, bound: float, min_p: float,
                       sfx: str) -> tuple[list[str], ...]:
    """The thresholds up to ``upto`` px as texts, sorted: p < bound in the strategy's favour, not,
    not but underpowered (the smallest attainable p, ``min_p``, is not below ``bound``),
    uninformative."""
    ok, bad, weak, skipped = [], [], [], []
    for t, p, stat, informative in _thresholds(tested, strategy, sfx):
        if t > upto:
            continue
        if not informative:
            skipped.append(f"{t:g} px")
            continue
        txt = f"{t:g} px (p={fmt_p(p)})"
        (ok if p < bound and stat < 0 else weak if min_p >= bound else bad).append(txt)
    return ok, bad, weak, skipped


def significance(art: Artifact, mode: str, method: str, category: str, strategy: str,
                 upto: float, bound: float, sfx: str = "") -> tuple[str, str]:
    """(measured text, verdict) of 'p < bound up to `upto` px' for one strategy."""
    tested = _tested(art, mode, method, category, strategy, sfx)
    if tested is None:
        return "not evaluated", "not measured"
    min_p = float(tested[3].get("min_pvalue", 0.0))
    ok, bad, weak, skipped = _sorted_thresholds(tested, strategy, upto, bound, min_p, sfx)
    parts = [f"p < {bound:g} at " + ", ".join(ok) if ok else "",
             "not at " + ", ".join(bad) if bad else "",
             f"not at {', '.join(weak)}: too few runs to show p < {bound:g} (the smallest exact "
             f"p-value of these sample sizes is {fmt_p(min_p)})" if weak else "",
             "uninformative (neither reaches it in half the runs): " + ", ".join(skipped)
             if skipped else ""]
    text = "; ".join(x for x in parts if x)
    if not ok and not bad and not weak:
        return text or f"no threshold <= {upto:g} px", "not measured"
    return text, "differs" if bad else "underpowered" if weak else "agrees"


def not_significant(art: Artifact, mode: str, method: str, category: str,
                    strategy: str, sfx: str = "", *, two_sided: bool = False) -> tuple[str, str]:
    """(measured text, verdict) of 'no threshold has p < 0.01 in the strategy's favour' (kbcli's
    reading: a strategy significantly *slower* than the baseline agrees), or with ``two_sided``
    'no threshold has p < 0.01 either way' (the plainest other reading)."""
    tested = _tested(art, mode, method, category, strategy, sfx)
    if tested is None:
        return "not evaluated", "not measured"
    pv = tested[3]
    faster, slower = [], []
    informative = 0
    for t, p, stat, useful in _thresholds(tested, strategy, sfx):
        informative += useful
        if useful and p < NOT_SIGNIFICANT:
            (faster if stat < 0 else slower).append(f"{t:g} px (p={fmt_p(p)})")
    if not informative:
        return "no informative threshold", "not measured"
    sig = faster + (slower if two_sided else [])
    if sig:
        parts = [f"significantly {w} (p < {NOT_SIGNIFICANT:g}) at " + ", ".join(ts)
                 for w, ts in (("faster", faster), ("slower", slower if two_sided else []))
                 if ts]
        return "; ".join(parts), "differs"
    if float(pv.get("min_pvalue", 0.0)) >= NOT_SIGNIFICANT:
        return (f"no threshold with p < {NOT_SIGNIFICANT:g}, but too few runs to show one (the "
                f"smallest exact p-value of these sample sizes is {fmt_p(float(pv['min_pvalue']))})",
                "underpowered")
    text = f"no threshold with p < {NOT_SIGNIFICANT:g} " + ("either way" if two_sided
                                                           else "in its favour")
    if slower and not two_sided:
        text += " (significantly slower at " + ", ".join(slower) + ")"
    return text, "agrees"


def combine(verdicts: list[str]) -> str:
    """The verdict of several measurements of one claim: the worst of them."""
    for v in ("differs", "underpowered", "agrees"):
        if v in verdicts:
            return v
    return "not measured"


def whole(verdicts: list[str]) -> str:
    """The verdict of a claim made of several halves, each of which must hold: differs when one
    differs, not measured when one is not measured, then underpowered, then agrees."""
    for v in ("differs", "not measured", "underpowered"):
        if v in verdicts:
            return v
    return "agrees"


def entropy_claim(art: Artifact, mode: str, method: str, strategy: str, *,
                  every_step: bool = False) -> tuple[str, str]:
    """(measured text, verdict) of Fig. 6: the strategy's mean entropy below the baseline's, at
    :data:`ENTROPY_STEPS` (kbcli's reading), or with ``every_step`` at every observation."""
    ent = art.data["entropy"].get(mode, {}).get(method, {})
    base = art.attrs["baseline"]
    if strategy not in ent or base not in ent:
        return "not evaluated", "not measured"
    a, b = np.asarray(ent[strategy]["mean"]), np.asarray(ent[base]["mean"])
    if every_step:
        above = [t + 1 for t in range(len(a)) if not a[t] < b[t]]
        ok = not above
        text = (f"mean entropy {strategy} below {base} at every observation 1-{len(a)}" if ok else
                f"mean entropy {strategy} not below {base} at t = "
                + ", ".join(str(t) for t in above))
        return text, "agrees" if ok else "differs"
    steps = [t for t in ENTROPY_STEPS if t <= len(a)] or [len(a)]
    parts = [f"t={t}: {a[t - 1]:.2f} vs {b[t - 1]:.2f} nats" for t in steps]
    ok = all(a[t - 1] < b[t - 1] for t in steps)
    return f"mean entropy {strategy} vs {base}: " + "; ".join(parts), "agrees" if ok else "differs"


def restores(art: Artifact, method: str, *, test: bool = False) -> tuple[str, str]:
    """(measured text, verdict) of 'adaptation restores the playing success' (dynamics mode):
    kbcli's reading, every strategy's median after adaptation at least the median before minus
    :data:`RESTORED_MARGIN`; with ``test``, the plainest other reading: no strategy's playing
    success after adaptation significantly below the one before (one-sided Mann-Whitney,
    p < :data:`NOT_SIGNIFICANT`)."""
    exp = art.data["experiments"]
    sel = (exp["mode"] == physical_mode(art.attrs["modes"])) & (exp["method"] == method)
    first = methods_of(art)[method]["strategies"][0]
    # before and unadapted are shared by the rows of a displacement and repetition: count once
    before = played(art, sel & (exp["strategy"] == first), "play_before")
    if not sel.any() or len(before) == 0:
        return "playing success not measured in dynamics mode", "not measured"
    unadapted = played(art, sel & (exp["strategy"] == first), "play_unadapted")
    b = float(np.median(before))
    parts, ok = [], True
    for s in methods_of(art)[method]["strategies"]:
        after = played(art, sel & (exp["strategy"] == s), "play_adapted")
        if len(after) == 0:
            return f"{s}: playing success after adaptation not measured", "not measured"
        med = float(np.median(after))
        eff, p = stats.mannwhitney_pvalues(after[:, None], before[:, None])
        # one-sided p of 'after below before' from the two-sided test (eff < 0: after lower)
        below = float(p[0]) / 2 if eff[0] < 0 else 1 - float(p[0]) / 2
        ok &= (below >= NOT_SIGNIFICANT) if test else (med >= b - RESTORED_MARGIN)
        parts.append(f"{s} {pct(med)} (IQR {pct(np.quantile(after, 0.25))}-"
                     f"{pct(np.quantile(after, 0.75))}; "
                     + (f"one-sided p of a fall {fmt_p(below)})" if test
                        else f"vs before p={fmt_p(float(p[0]))})"))
    measured = (f"median playing success ({art.attrs.get('play_notes')} notes of Algorithm 1) "
                f"before the displacement {pct(b)} (IQR {pct(np.quantile(before, 0.25))}-"
                f"{pct(np.quantile(before, 0.75))}), after it without adaptation "
                f"{pct(float(np.median(unadapted)))}; after adaptation: " + ", ".join(parts))
    return measured, "agrees" if ok else "differs"


def beside(art: Artifact, fn) -> str:
    """The other methods' measurement of one claim, ``fn(method, strategy) -> (text, verdict)``."""
    parts = []
    for x in others(art):
        for s in compared(art, x):
            text, verdict = fn(x, s)
            if text != "not evaluated":
                parts.append(f"{x} {s}: {text} [{verdict}]")
    return "; ".join(parts)


def _best_p(art: Artifact, mode: str, method: str, category: str, strategy: str,
            sfx: str = "") -> tuple[float, float] | None:
    """(smallest p in the strategy's favour over the informative thresholds, its threshold px),
    or None when no threshold is informative (reached by either in half the runs)."""
    tested = _tested(art, mode, method, category, strategy, sfx)
    if tested is None:
        return None
    best = None
    for t, p, stat, informative in _thresholds(tested, strategy, sfx):
        p = 1.0 if stat >= 0 else float(p)  # 1: not in the strategy's favour
        if informative and (best is None or p < best[0]):
            best = (p, float(t))
    return best


def large_why(art: Artifact, mode: str) -> str:
    """A measured account of the large-displacement claim: representation, estimator, strategy.

    Every method's runs on the large displacements, read with its own estimator and (same runs)
    with the other one: which of them separate a strategy from the baseline (p < 0.01)?
    """
    judged = art.attrs["judged"]
    if "large" not in art.attrs["categories"]:
        return ""
    sig, calm = [], []
    judged_sig = None
    for x in methods_of(art):
        posterior = robot(art, x).get("posterior", "?")
        for (est, sfx), s in ((r, s) for r in readings(art, x) for s in compared(art, x)):
            best = _best_p(art, mode, x, "large", s, sfx)
            if best is None:
                continue
            same = ", same runs" if sfx else ""
            (sig if best[0] < NOT_SIGNIFICANT else calm).append(
                f"{x} ({posterior} posterior, {est} estimate{same}, {s}): p={fmt_p(best[0])} at "
                f"{best[1]:g} px")
            if x == judged and not sfx and STRATEGIES.trait(s, "paper", False):
                judged_sig = best[0] < NOT_SIGNIFICANT
    if not sig and not calm:
        return ""
    return (f"Large displacements, {mode} mode, each variant's smallest p-value against "
            f"{art.attrs['baseline']} over the informative thresholds: separated "
            f"(p < {NOT_SIGNIFICANT:g}): " + ("; ".join(sig) or "none") + ". Not separated: "
            + ("; ".join(calm) or "none") + _large_moral(judged, judged_sig, bool(sig)))


def _large_moral(judged: str, judged_sig: bool | None, any_sig: bool) -> str:
    """What the large-displacement account says of the judged method's own reading."""
    if judged_sig is True:
        return (f". So the paper's own representation, estimator and strategy (`{judged}`) "
                "already separate active from random here: the difference from the paper's "
                "'not very significant' lies in neither of them")
    if judged_sig is False and any_sig:
        return (f". So `{judged}` does not separate active from random here; the variants that "
                "do are listed above: what they change from it is what matters")
    return ""
