"""Stage ``report``: the paper's claims against what an evaluation measured (Sect. IV, Figs. 5-7).

From an ``evaluation`` artifact this builds the text of ``report/README.md``: the tables
(observations needed to reach each error threshold, Wilcoxon rank-sum p-values against the baseline,
RMSE at chosen steps, playing success) and a side-by-side of each claim of the paper with our
measurement and a verdict. Figures are drawn by :mod:`kbcli.viz.report`; files are written by the
CLI. Pure: no I/O.

How each claim is judged (stated in the README too):

- *significance up to X px* (Sect. IV-B): at every threshold <= X px that the compared strategy
  reaches in at least half its runs, p is below the paper's bound and the strategy needed fewer
  observations than the baseline (rank-sum statistic < 0); thresholds reached by neither strategy
  in half their runs are listed as uninformative, not counted;
- *not significant* (large displacements): no informative threshold has p < 0.01 in favour of the
  strategy;
- *adaptation restores performance* (Sect. IV-C, dynamics mode): the median playing success with the
  final estimate is at least 95 % (it is 100 % before the perturbation by construction), for every
  strategy; *differences not significant* (dynamics mode) is judged like the large displacements,
  in every category.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kbcli.errors import ArtifactError
from kbcli.stages.artifact import Artifact

#: Steps at which the RMSE table is read (those beyond max_steps are dropped).
RMSE_STEPS = (1, 2, 3, 5, 10, 20, 40)
RESTORED = 0.95
NOT_SIGNIFICANT = 0.01


@dataclass(frozen=True)
class Claim:
    """One claim of the paper, what we measured and whether they agree."""

    source: str
    paper: str
    measured: str
    verdict: str  # "agrees", "differs" or "not measured"


@dataclass(frozen=True)
class Figure:
    name: str  # file name in the report folder
    title: str
    caption: str


@dataclass
class Report:
    """What ``kbcli report`` writes: the README text and the figures to draw."""

    readme: str
    claims: list[Claim]
    figures: list[Figure] = field(default_factory=list)


def _fmt_p(p: float) -> str:
    return "1" if p >= 0.9995 else f"{p:.1e}"


def _fmt_med(m: float) -> str:
    return "-" if np.isnan(m) else f"{m:g}"


def _check(art: Artifact) -> None:
    if art.kind != "evaluation":
        raise ArtifactError(f"{art.path or 'artifact'}: is a {art.kind} artifact, expected evaluation")
    for k in ("curves", "pvalues", "entropy", "experiments"):
        if k not in art.data:
            raise ArtifactError(f"{art.path or 'artifact'}: evaluation artifact without {k!r}")


def _significance(art: Artifact, mode: str, category: str, strategy: str, upto: float,
                  bound: float) -> tuple[str, str]:
    """(measured text, verdict) of 'p < bound up to `upto` px' for one strategy."""
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    cur = art.data["curves"][mode][category]
    pv = art.data["pvalues"][mode][category][strategy]
    ok, bad, skipped = [], [], []
    for j, t in enumerate(thr):
        if t > upto:
            continue
        if max(cur[strategy]["reached"][j], cur[base]["reached"][j]) < 0.5:
            skipped.append(f"{t:g} px")
            continue
        p, stat = pv["pvalue"][j], pv["statistic"][j]
        (ok if (p < bound and stat < 0) else bad).append(f"{t:g} px (p={_fmt_p(p)})")
    parts = []
    if ok:
        parts.append(f"p < {bound:g} at " + ", ".join(ok))
    if bad:
        parts.append("not at " + ", ".join(bad))
    if skipped:
        parts.append("uninformative (neither reaches it in half the runs): " + ", ".join(skipped))
    if not ok and not bad:
        return "; ".join(parts) or f"no threshold <= {upto:g} px", "not measured"
    return "; ".join(parts), "agrees" if not bad else "differs"


def _not_significant(art: Artifact, mode: str, category: str, strategy: str) -> tuple[str, str]:
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    cur = art.data["curves"][mode][category]
    pv = art.data["pvalues"][mode][category][strategy]
    sig = []
    informative = 0
    for j, t in enumerate(thr):
        if max(cur[strategy]["reached"][j], cur[base]["reached"][j]) < 0.5:
            continue
        informative += 1
        if pv["pvalue"][j] < NOT_SIGNIFICANT and pv["statistic"][j] < 0:
            sig.append(f"{t:g} px (p={_fmt_p(pv['pvalue'][j])})")
    if not informative:
        return "no informative threshold", "not measured"
    if sig:
        return f"significantly faster (p < {NOT_SIGNIFICANT:g}) at " + ", ".join(sig), "differs"
    return f"no threshold with p < {NOT_SIGNIFICANT:g} in its favour", "agrees"


def claims(art: Artifact) -> list[Claim]:
    """The paper's claims (Sect. IV-B, IV-C) side by side with this evaluation's measurements."""
    _check(art)
    modes = art.attrs["modes"]
    cats = art.attrs["categories"]
    base = art.attrs["baseline"]
    others = [s for s in art.attrs["strategies"] if s != base]
    out: list[Claim] = []
    ideal = "ideal" if "ideal" in modes else None
    paper = [
        ("small", "Sect. IV-B, Fig. 7", "small displacements (<= 10 px): active beats random, "
         "p < 1e-5 for RMSE thresholds up to 10 px", ("sig", 10.0, 1e-5)),
        ("medium", "Sect. IV-B, Fig. 7", "medium displacements (<= 20 px): still significant, "
         "p < 1e-3 up to 8 px", ("sig", 8.0, 1e-3)),
        ("large", "Sect. IV-B, Fig. 7", "large displacements (<= 40 px): the improvement is not "
         "very significant", ("ns",)),
    ]
    for cat, source, text, rule in paper:
        for s in others:
            if ideal is None or cat not in cats:
                out.append(Claim(source, text, f"{s}: not evaluated (needs ideal mode and the "
                                 f"{cat} category)", "not measured"))
                continue
            if rule[0] == "sig":
                measured, verdict = _significance(art, ideal, cat, s, rule[1], rule[2])
            else:
                measured, verdict = _not_significant(art, ideal, cat, s)
            out.append(Claim(source, text, f"{s} vs {base}: {measured}", verdict))
    dyn_text = "with robot dynamics the robot adapts and restores its previous performance"
    dyn_ns = ("with robot dynamics the differences between the strategies were not significant "
              "enough")
    if "dynamics" not in modes:
        out.append(Claim("Sect. IV-C", dyn_text, "dynamics mode not evaluated", "not measured"))
        out.append(Claim("Sect. IV-C", dyn_ns, "dynamics mode not evaluated", "not measured"))
    else:
        exp = art.data["experiments"]
        sel = exp["mode"] == "dynamics"
        parts, ok = [], True
        for s in art.attrs["strategies"]:
            m = sel & (exp["strategy"] == s)
            med = float(np.median(exp["play_adapted"][m]))
            ok &= med >= RESTORED
            parts.append(f"{s} {100 * med:.1f} %")
        before = float(np.median(exp["play_unadapted"][sel]))
        measured = (f"median playing success after adaptation: {', '.join(parts)} (100 % before the "
                    f"displacement, {100 * before:.1f} % after it without adaptation)")
        out.append(Claim("Sect. IV-C", dyn_text, measured, "agrees" if ok else "differs"))
        for s in others:
            parts, verdicts = [], []
            for cat in cats:
                measured, verdict = _not_significant(art, "dynamics", cat, s)
                parts.append(f"{cat}: {measured}")
                verdicts.append(verdict)
            verdict = ("differs" if "differs" in verdicts else
                       "agrees" if "agrees" in verdicts else "not measured")
            out.append(Claim("Sect. IV-C", dyn_ns, f"{s} vs {base}: " + "; ".join(parts), verdict))
    return out


def _threshold_table(art: Artifact, mode: str) -> list[str]:
    thr = art.array("thresholds")
    head = "| category | strategy | " + " | ".join(f"< {t:g} px" for t in thr) + " |"
    lines = [head, "|" + "---|" * (len(thr) + 2)]
    for c in art.attrs["categories"]:
        for s in art.attrs["strategies"]:
            cur = art.data["curves"][mode][c][s]
            cells = [f"{_fmt_med(m)} ({100 * r:.0f} %)" for m, r in
                     zip(cur["median_samples"], cur["reached"], strict=True)]
            lines.append(f"| {c} | {s} | " + " | ".join(cells) + " |")
    return lines


def _pvalue_table(art: Artifact, mode: str) -> list[str]:
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    head = "| category | test | " + " | ".join(f"< {t:g} px" for t in thr) + " |"
    lines = [head, "|" + "---|" * (len(thr) + 2)]
    for c in art.attrs["categories"]:
        for s, pv in art.data["pvalues"][mode][c].items():
            cells = []
            for p, stat in zip(pv["pvalue"], pv["statistic"], strict=True):
                sign = "" if p >= 0.05 else (" (faster)" if stat < 0 else " (slower)")
                cells.append(_fmt_p(p) + sign)
            lines.append(f"| {c} | {s} vs {base} | " + " | ".join(cells) + " |")
    return lines


def _rmse_table(art: Artifact, mode: str) -> list[str]:
    T = int(art.attrs["max_steps"])
    steps = [t for t in RMSE_STEPS if t <= T] or [T]
    head = "| category | strategy | " + " | ".join(f"t={t}" for t in steps) + " |"
    lines = [head, "|" + "---|" * (len(steps) + 2)]
    for c in art.attrs["categories"]:
        for s in art.attrs["strategies"]:
            r = art.data["curves"][mode][c][s]["rmse"]
            lines.append(f"| {c} | {s} | " + " | ".join(f"{r[t - 1]:.2f}" for t in steps) + " |")
    return lines


def _play_table(art: Artifact) -> list[str]:
    exp = art.data["experiments"]
    lines = ["| mode | category | without adaptation | " + " | ".join(art.attrs["strategies"])
             + " |", "|" + "---|" * (3 + len(art.attrs["strategies"]))]
    for m in art.attrs["modes"]:
        for c in art.attrs["categories"]:
            sel = (exp["mode"] == m) & (exp["category"] == c)
            cells = [f"{100 * np.median(exp['play_adapted'][sel & (exp['strategy'] == s)]):.1f} %"
                     for s in art.attrs["strategies"]]
            lines.append(f"| {m} | {c} | {100 * np.median(exp['play_unadapted'][sel]):.1f} % | "
                         + " | ".join(cells) + " |")
    return lines


def figures(art: Artifact) -> list[Figure]:
    """The figures of the report (file names and captions)."""
    modes = art.attrs["modes"]
    first = "ideal" if "ideal" in modes else modes[0]
    figs = []
    if any(art.data.get("examples", {}).get(m) for m in modes):
        figs.append(Figure("fig5_posterior.png", "Fig. 5: evolution of the posterior",
                           f"Posterior over the displacement (dx, dy) after 1, 2, 3, ... "
                           f"observations of one example run per strategy ({first} mode, first "
                           f"{art.config.get('example', '')} displacement); the cross is the "
                           "true displacement."))
    figs.append(Figure("fig6_entropy.png", "Fig. 6: entropy reduction",
                       "Posterior entropy (nats) against observations, mean over all experiments "
                       "of each strategy, with the interquartile range shaded; one panel per mode."))
    for m in modes:
        figs.append(Figure(f"fig7_error_{m}.png", f"Fig. 7: error against observations ({m} mode)",
                           "RMSE of the displacement estimate (px) over the experiments of each "
                           "category against the number of observations, log scale; shaded: the "
                           "interquartile range of the per-experiment error."))
    return figs


def build(art: Artifact) -> Report:
    """The report of an evaluation artifact: README text, claims and figures."""
    _check(art)
    cl = claims(art)
    figs = figures(art)
    base = art.attrs["baseline"]
    exp = art.data["experiments"]
    n = len(exp["mode"])
    model = art.inputs.get("model", {})
    lines = [
        "# Where is my keyboard? Reproduction report",
        "",
        f"Generated by `kbcli report` from `{art.path or 'an evaluation artifact'}` "
        f"(sha256 `{(art.sha256 or '?')[:16]}`, kbcli {art.kbcli_version}).",
        "",
        f"- {n} experiments: {int(art.config['experiments'])} per displacement, strategy and mode; "
        f"{art.attrs['max_steps']} observations each; seed {art.seed}.",
        f"- modes: {', '.join(art.attrs['modes'])}; strategies: "
        f"{', '.join(art.attrs['strategies'])} (baseline: {base}); transform family "
        f"{art.config.get('family', 'translation')}.",
        f"- model: {art.attrs.get('model_strategy')} (file {model.get('file')}, sha256 "
        f"`{str(model.get('sha256'))[:16]}`).",
        "- categories: " + "; ".join(
            f"{c} (<= {art.config['categories'][c]['limit']:g} px: "
            + ", ".join(f"({', '.join(f'{v:g}' for v in d)})"
                        for d in art.config['categories'][c]['displacements']) + ")"
            for c in art.attrs["categories"]),
        "",
        "## The paper's claims against our measurements",
        "",
        "| source | the paper says | we measured | verdict |",
        "|---|---|---|---|",
    ]
    for c in cl:
        lines.append(f"| {c.source} | {c.paper} | {c.measured} | **{c.verdict}** |")
    lines += [
        "",
        "How claims are judged: a significance claim *up to X px* agrees when, at every threshold "
        "<= X px that the strategy or the baseline reaches in at least half its runs, the two-sided "
        "Wilcoxon rank-sum p-value on the observations needed is below the paper's bound and the "
        "strategy needed fewer; thresholds reached by neither in half their runs are called "
        f"uninformative. *Not significant* agrees when no informative threshold has p < "
        f"{NOT_SIGNIFICANT:g} in the strategy's favour. *Restores performance* agrees when the median "
        f"playing success with the final estimate is at least {100 * RESTORED:.0f} % for every "
        "strategy. A run that never gets below a threshold counts as max_steps + 1 observations.",
        "",
        "Playing success: the robot aims at an even grid of points inside each key of its map, "
        "moved by the estimated displacement; a touch succeeds when it lands on the intended key of "
        "the displaced keyboard. It is 100 % before the displacement.",
        "",
    ]
    for f in figs:
        lines += [f"### {f.title}", "", f"![{f.title}]({f.name})", "", f.caption, ""]
    for m in art.attrs["modes"]:
        lines += [
            f"## Observations to reach each error threshold ({m} mode)", "",
            "Median observations until the error first drops below the threshold (in brackets: "
            "the share of runs that got there within max_steps; '-' when fewer than half did).", "",
            *_threshold_table(art, m), "",
            f"## Wilcoxon rank-sum p-values against {base} ({m} mode)", "",
            "Two-sided, on the observations each run needed to reach the threshold; "
            "'faster'/'slower' marks p < 0.05.", "",
            *_pvalue_table(art, m), "",
            f"## RMSE (px) after t observations ({m} mode)", "",
            *_rmse_table(art, m), "",
        ]
    lines += ["## Playing success after adaptation (median over runs)", "", *_play_table(art), ""]
    return Report(readme="\n".join(lines), claims=cl, figures=figs)
