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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kbcli.core import stats
from kbcli.errors import ArtifactError
from kbcli.stages.artifact import Artifact

#: Steps at which the RMSE table is read (those beyond max_steps are dropped).
RMSE_STEPS = (1, 2, 3, 5, 10, 20, 40)
#: Playing success after adaptation may be this much below the measured before (share, 2 points).
RESTORED_MARGIN = 0.02
NOT_SIGNIFICANT = 0.01
#: Observations at which Fig. 6's claim (active's entropy falls quicker) is read.
ENTROPY_STEPS = (5, 10, 20)
#: Robot options shown first in the methods table (the rest follow alphabetically).
KEY_OPTIONS = ("posterior", "estimator", "model_blur", "kde_samples", "kde_bandwidth", "outlier",
               "resolution", "prior_halfwidth")
VERDICTS = ("agrees", "differs", "underpowered", "not measured")


@dataclass(frozen=True)
class Claim:
    """One claim of the paper, what the judged method measured, and the others beside it."""

    source: str
    paper: str
    method: str  # the method the verdict is about
    options: str  # its options that matter for the claim
    measured: str
    verdict: str  # one of VERDICTS
    beside: str = ""  # the other methods' measurements
    why: str = ""  # a measured explanation of a difference


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


def _pct(v: float) -> str:
    return "n/a" if np.isnan(v) else f"{100 * v:.1f} %"


def _check(art: Artifact) -> None:
    if art.kind != "evaluation":
        raise ArtifactError(f"{art.path or 'artifact'}: is a {art.kind} artifact, expected evaluation")
    for k in ("curves", "pvalues", "entropy", "experiments"):
        if k not in art.data:
            raise ArtifactError(f"{art.path or 'artifact'}: evaluation artifact without {k!r}")


# -- schema 1 (before named methods) --------------------------------------------------------------
def upgrade(art: Artifact) -> Artifact:
    """A schema-1 evaluation (one unnamed method, derived playing success) in the current layout.

    Its runs become method ``kbcli`` (judged; options: its ``adapt`` table over the adapt stage's
    defaults of the time, which it did not record); its p-values are the untied rank-sum test it
    stored (``min_pvalue`` computed from its run counts); its playing success was computed, not
    measured, so it is dropped (NaN).
    """
    if (art.schema_version or 1) >= 2 or "methods" in art.attrs:
        return art
    _check(art)
    data = dict(art.data)
    name = "kbcli"
    exp = dict(data["experiments"])
    n = len(exp["mode"])
    exp["method"] = np.array([name] * n)
    for k in ("play_before", "play_unadapted", "play_adapted"):
        exp[k] = np.full(n, np.nan)
    data["experiments"] = exp
    pv = {}
    for m, by_c in data["pvalues"].items():
        pv[m] = {name: {}}
        for c, by_s in by_c.items():
            pv[m][name][c] = {}
            for s, entry in by_s.items():
                na = len(data["curves"][m][c][s]["samples_to_threshold"])
                nb = len(data["curves"][m][c][art.attrs["baseline"]]["samples_to_threshold"])
                pv[m][name][c][s] = {**entry,
                                     "min_pvalue": np.float64(stats.min_pvalue_unpaired(na, nb))}
    data["pvalues"] = pv
    data["curves"] = {m: {name: v} for m, v in data["curves"].items()}
    data["entropy"] = {m: {name: v} for m, v in data["entropy"].items()}
    data["examples"] = {m: {name: v} for m, v in data.get("examples", {}).items()}
    attrs = dict(art.attrs)
    attrs["methods"] = {name: {
        "strategies": list(attrs["strategies"]),
        "description": "the only method of a schema-1 evaluation (defaults of its kbcli version)",
        "modes": list(attrs["modes"]), "categories": list(attrs["categories"]),
        "options": {m: {s: {"robot": dict(art.config.get("adapt", {}))} for s in attrs["strategies"]}
                    for m in attrs["modes"]}}}
    attrs["judged"] = name
    attrs["method_order"] = [name]
    attrs.setdefault("play_notes", 0)
    return Artifact(kind=art.kind, config=art.config, seed=art.seed, data=data, attrs=attrs,
                    inputs=art.inputs, schema_version=art.schema_version,
                    kbcli_version=art.kbcli_version, sha256=art.sha256, path=art.path)


# -- reading the artifact -------------------------------------------------------------------------
def method_names(art: Artifact) -> list[str]:
    """The methods in the config's order (``attrs["method_order"]``; artifacts without it, whose
    attributes were stored with sorted keys: the judged method first)."""
    names = list(art.attrs["methods"])
    order = art.attrs.get("method_order")
    if order:
        return [x for x in order if x in names]
    judged = art.attrs.get("judged")
    return ([judged] if judged in names else []) + [x for x in names if x != judged]


def _methods(art: Artifact) -> dict:
    """Method name -> its resolved options, in :func:`method_names` order."""
    info = art.attrs["methods"]
    return {x: info[x] for x in method_names(art)}


def _robot(art: Artifact, method: str) -> dict:
    """The robot options a method resolved to (those of its first mode and strategy, with the
    per-experiment strategy dropped)."""
    opts = _methods(art)[method]["options"]
    for by_s in opts.values():
        for d in by_s.values():
            r = dict(d.get("robot", {}))
            r.pop("strategy", None)
            return r
    return {}


def _short(art: Artifact, method: str) -> str:
    r = _robot(art, method)
    parts = [f"{k} {r[k]}" for k in ("posterior", "estimator") if k in r]
    if "model_blur" in r:
        parts.append(f"model_blur {r['model_blur']}")
    return ", ".join(parts) + f"; {' / '.join(_methods(art)[method]['strategies'])}"


def ordered(art: Artifact, key: str, mode: str):
    """``(method, category, strategy, value)`` of ``art.data[key][mode]`` (``curves`` or
    ``pvalues``) in the config's order of methods, categories and strategies (an artifact read
    back from HDF5 lists its groups alphabetically)."""
    tree = art.data[key].get(mode, {})
    for x, info in _methods(art).items():
        for c in art.attrs["categories"]:
            by_s = tree.get(x, {}).get(c)
            if by_s is None:
                continue
            for s in info["strategies"]:
                if s in by_s:
                    yield x, c, s, by_s[s]


def _cell(art: Artifact, mode: str, method: str, category: str):
    cur = art.data["curves"].get(mode, {}).get(method, {}).get(category)
    pv = art.data["pvalues"].get(mode, {}).get(method, {}).get(category)
    return cur, pv


def _compared(art: Artifact, method: str) -> list[str]:
    """The non-baseline strategies of a method."""
    base = art.attrs["baseline"]
    return [s for s in _methods(art)[method]["strategies"] if s != base]


def _significance(art: Artifact, mode: str, method: str, category: str, strategy: str,
                  upto: float, bound: float, sfx: str = "") -> tuple[str, str]:
    """(measured text, verdict) of 'p < bound up to `upto` px' for one strategy."""
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    cur, pvs = _cell(art, mode, method, category)
    if cur is None or strategy not in pvs:
        return "not evaluated", "not measured"
    pv = pvs[strategy]
    min_p = float(pv.get("min_pvalue", 0.0))
    ok, bad, weak, skipped = [], [], [], []
    for j, t in enumerate(thr):
        if t > upto:
            continue
        if max(cur[strategy][f"reached{sfx}"][j], cur[base][f"reached{sfx}"][j]) < 0.5:
            skipped.append(f"{t:g} px")
            continue
        p, stat = pv[f"pvalue{sfx}"][j], pv[f"statistic{sfx}"][j]
        txt = f"{t:g} px (p={_fmt_p(p)})"
        if p < bound and stat < 0:
            ok.append(txt)
        elif min_p >= bound:
            weak.append(txt)
        else:
            bad.append(txt)
    parts = []
    if ok:
        parts.append(f"p < {bound:g} at " + ", ".join(ok))
    if bad:
        parts.append("not at " + ", ".join(bad))
    if weak:
        parts.append(f"not at {', '.join(weak)}: too few runs to show p < {bound:g} (the "
                     f"smallest exact p-value of these sample sizes is {_fmt_p(min_p)})")
    if skipped:
        parts.append("uninformative (neither reaches it in half the runs): " + ", ".join(skipped))
    if not ok and not bad and not weak:
        return "; ".join(parts) or f"no threshold <= {upto:g} px", "not measured"
    verdict = "differs" if bad else "underpowered" if weak else "agrees"
    return "; ".join(parts), verdict


def _not_significant(art: Artifact, mode: str, method: str, category: str,
                     strategy: str) -> tuple[str, str]:
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    cur, pvs = _cell(art, mode, method, category)
    if cur is None or strategy not in pvs:
        return "not evaluated", "not measured"
    pv = pvs[strategy]
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
    if float(pv.get("min_pvalue", 0.0)) >= NOT_SIGNIFICANT:
        return (f"no threshold with p < {NOT_SIGNIFICANT:g}, but too few runs to show one (the "
                f"smallest exact p-value of these sample sizes is {_fmt_p(float(pv['min_pvalue']))})",
                "underpowered")
    return f"no threshold with p < {NOT_SIGNIFICANT:g} in its favour", "agrees"


def _combine(verdicts: list[str]) -> str:
    for v in ("differs", "underpowered", "agrees"):
        if v in verdicts:
            return v
    return "not measured"


def _others(art: Artifact) -> list[str]:
    return [m for m in _methods(art) if m != art.attrs["judged"]]


def _entropy_claim(art: Artifact, mode: str, method: str, strategy: str) -> tuple[str, str]:
    ent = art.data["entropy"].get(mode, {}).get(method, {})
    base = art.attrs["baseline"]
    if strategy not in ent or base not in ent:
        return "not evaluated", "not measured"
    a, b = np.asarray(ent[strategy]["mean"]), np.asarray(ent[base]["mean"])
    steps = [t for t in ENTROPY_STEPS if t <= len(a)] or [len(a)]
    parts = [f"t={t}: {a[t - 1]:.2f} vs {b[t - 1]:.2f} nats" for t in steps]
    ok = all(a[t - 1] < b[t - 1] for t in steps)
    return f"mean entropy {strategy} vs {base}: " + "; ".join(parts), "agrees" if ok else "differs"


def _play(art: Artifact, sel: np.ndarray, key: str) -> np.ndarray:
    v = np.asarray(art.data["experiments"][key], float)[sel]
    return v[~np.isnan(v)]


def _restores(art: Artifact, method: str) -> tuple[str, str]:
    exp = art.data["experiments"]
    sel = (exp["mode"] == "dynamics") & (exp["method"] == method)
    first = _methods(art)[method]["strategies"][0]
    # before and unadapted are shared by the rows of a displacement and repetition: count once
    before = _play(art, sel & (exp["strategy"] == first), "play_before")
    if not sel.any() or len(before) == 0:
        return "playing success not measured in dynamics mode", "not measured"
    unadapted = _play(art, sel & (exp["strategy"] == first), "play_unadapted")
    b = float(np.median(before))
    parts, ok = [], True
    for s in _methods(art)[method]["strategies"]:
        after = _play(art, sel & (exp["strategy"] == s), "play_adapted")
        if len(after) == 0:
            return f"{s}: playing success after adaptation not measured", "not measured"
        med = float(np.median(after))
        ok &= med >= b - RESTORED_MARGIN
        _, p = stats.mannwhitney_pvalues(after[:, None], before[:, None])
        parts.append(f"{s} {_pct(med)} (IQR {_pct(np.quantile(after, 0.25))}-"
                     f"{_pct(np.quantile(after, 0.75))}; vs before p={_fmt_p(float(p[0]))})")
    measured = (f"median playing success ({art.attrs.get('play_notes')} notes of Algorithm 1) "
                f"before the displacement {_pct(b)} (IQR {_pct(np.quantile(before, 0.25))}-"
                f"{_pct(np.quantile(before, 0.75))}), after it without adaptation "
                f"{_pct(float(np.median(unadapted)))}; after adaptation: " + ", ".join(parts))
    return measured, "agrees" if ok else "differs"


def _beside(art: Artifact, fn) -> str:
    """The other methods' measurement of one claim, ``fn(method, strategy) -> (text, verdict)``."""
    parts = []
    for x in _others(art):
        for s in _compared(art, x):
            text, verdict = fn(x, s)
            if text != "not evaluated":
                parts.append(f"{x} {s}: {text} [{verdict}]")
    return "; ".join(parts)


def _best_p(art: Artifact, mode: str, method: str, category: str, strategy: str,
            sfx: str = "") -> tuple[float, float] | None:
    """(smallest p in the strategy's favour over the informative thresholds, its threshold px),
    or None when no threshold is informative (reached by either in half the runs)."""
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    cur, pvs = _cell(art, mode, method, category)
    if cur is None or strategy not in pvs or f"pvalue{sfx}" not in pvs[strategy]:
        return None
    best = None
    for j, t in enumerate(thr):
        if max(cur[strategy][f"reached{sfx}"][j], cur[base][f"reached{sfx}"][j]) < 0.5:
            continue
        p = float(pvs[strategy][f"pvalue{sfx}"][j])
        if pvs[strategy][f"statistic{sfx}"][j] >= 0:
            p = 1.0  # not in the strategy's favour
        if best is None or p < best[0]:
            best = (p, float(t))
    return best


def _large_why(art: Artifact, mode: str) -> str:
    """A measured account of the large-displacement claim: representation, estimator, strategy.

    Every method's runs on the large displacements, read with its own estimator and (same runs)
    with the other one: which of them separate a strategy from the baseline (p < 0.01)?
    """
    judged = art.attrs["judged"]
    if "large" not in art.attrs["categories"]:
        return ""
    base = art.attrs["baseline"]
    sig, calm = [], []
    judged_sig = None
    for x in _methods(art):
        r = _robot(art, x)
        for est, sfx in ((r.get("estimator", "?"), ""), ("ml", "_ml"), ("mean", "_mean")):
            if sfx and est == r.get("estimator"):
                continue
            for s in _compared(art, x):
                best = _best_p(art, mode, x, "large", s, sfx)
                if best is None:
                    continue
                label = (f"{x} ({r.get('posterior', '?')} posterior, {est} estimate"
                         + (", same runs" if sfx else "") + f", {s})")
                txt = f"{label}: p={_fmt_p(best[0])} at {best[1]:g} px"
                (sig if best[0] < NOT_SIGNIFICANT else calm).append(txt)
                if x == judged and not sfx and s == "active":
                    judged_sig = best[0] < NOT_SIGNIFICANT
    if not sig and not calm:
        return ""
    text = (f"Large displacements, {mode} mode, each variant's smallest p-value against {base} "
            f"over the informative thresholds: separated (p < {NOT_SIGNIFICANT:g}): "
            + ("; ".join(sig) or "none") + ". Not separated: " + ("; ".join(calm) or "none"))
    if judged_sig is True:
        text += (f". So the paper's own representation, estimator and strategy (`{judged}`) "
                 "already separate active from random here: the difference from the paper's "
                 "'not very significant' lies in neither of them")
    elif judged_sig is False and sig:
        text += (f". So `{judged}` does not separate active from random here; the variants that "
                 "do are listed above: what they change from it is what matters")
    return text


def claims(art: Artifact) -> list[Claim]:
    """The paper's claims (Sect. IV-A, IV-B, IV-C) judged on the judged method, others beside."""
    art = upgrade(art)
    _check(art)
    modes = art.attrs["modes"]
    cats = art.attrs["categories"]
    judged = art.attrs["judged"]
    base = art.attrs["baseline"]
    out: list[Claim] = []
    ideal = "ideal" if "ideal" in modes else None
    opts = _short(art, judged)
    compared = _compared(art, judged)

    # Fig. 6
    text = "active exhibits a quicker decrease in entropy than random (Fig. 6)"
    for s in compared:
        if ideal is None:
            out.append(Claim("Sect. IV-A, Fig. 6", text, judged, opts, "ideal mode not evaluated",
                             "not measured"))
            continue
        measured, verdict = _entropy_claim(art, ideal, judged, s)
        beside = _beside(art, lambda x, s2: _entropy_claim(art, ideal, x, s2))
        out.append(Claim("Sect. IV-A, Fig. 6", text, judged, opts, f"{s} vs {base}: {measured}",
                         verdict, beside))

    paper = [
        ("small", "Sect. IV-B, Fig. 7", "small displacements (<= 10 px): active beats random, "
         "p < 1e-5 for RMSE thresholds up to 10 px", ("sig", 10.0, 1e-5)),
        ("medium", "Sect. IV-B, Fig. 7", "medium displacements (<= 20 px): still significant, "
         "p < 1e-3 up to 8 px", ("sig", 8.0, 1e-3)),
        ("large", "Sect. IV-B, Fig. 7", "large displacements (<= 40 px): the improvement is not "
         "very significant", ("ns",)),
    ]
    for cat, source, text, rule in paper:
        for s in compared:
            if ideal is None or cat not in cats:
                out.append(Claim(source, text, judged, opts, f"{s}: not evaluated (needs ideal "
                                 f"mode and the {cat} category)", "not measured"))
                continue
            if rule[0] == "sig":
                def fn(x, s2, cat=cat, rule=rule):
                    return _significance(art, ideal, x, cat, s2, rule[1], rule[2])
            else:
                def fn(x, s2, cat=cat):
                    return _not_significant(art, ideal, x, cat, s2)
            measured, verdict = fn(judged, s)
            why = _large_why(art, ideal) if cat == "large" else ""
            out.append(Claim(source, text, judged, opts, f"{s} vs {base}: {measured}", verdict,
                             _beside(art, fn), why))

    dyn_text = "with robot dynamics the robot adapts and restores its previous performance"
    dyn_ns = ("with robot dynamics the differences between the strategies were not significant "
              "enough")
    if "dynamics" not in modes:
        out.append(Claim("Sect. IV-C", dyn_text, judged, opts, "dynamics mode not evaluated",
                         "not measured"))
        out.append(Claim("Sect. IV-C", dyn_ns, judged, opts, "dynamics mode not evaluated",
                         "not measured"))
        return out
    measured, verdict = _restores(art, judged)
    beside = "; ".join(f"{x}: {_restores(art, x)[0]} [{_restores(art, x)[1]}]"
                       for x in _others(art) if "dynamics" in _methods(art)[x]["modes"])
    out.append(Claim("Sect. IV-C", dyn_text, judged, opts, measured, verdict, beside))

    def dyn(x: str, s: str) -> tuple[str, str]:
        parts, verdicts = [], []
        for cat in cats:
            m, v = _not_significant(art, "dynamics", x, cat, s)
            if m == "not evaluated":
                continue
            parts.append(f"{cat}: {m}")
            verdicts.append(v)
        if not parts:
            return "not evaluated", "not measured"
        return "; ".join(parts), _combine(verdicts)

    for s in compared:
        measured, verdict = dyn(judged, s)
        out.append(Claim("Sect. IV-C", dyn_ns, judged, opts, f"{s} vs {base}: {measured}",
                         verdict, _beside(art, dyn)))
    return out


# -- tables ---------------------------------------------------------------------------------------
def _methods_table(art: Artifact) -> list[str]:
    """Every resolved option of every method (rows), methods as columns; differing rows marked."""
    meths = list(_methods(art))
    robots = {x: _robot(art, x) for x in meths}
    keys = [k for k in KEY_OPTIONS if any(k in r for r in robots.values())]
    keys += sorted({k for r in robots.values() for k in r} - set(keys))
    lines = ["| option | " + " | ".join(f"`{x}`" for x in meths) + " |",
             "|" + "---|" * (len(meths) + 1)]
    info = _methods(art)
    lines.append("| strategies | " + " | ".join(", ".join(info[x]["strategies"]) for x in meths)
                 + " |")
    lines.append("| modes | " + " | ".join(", ".join(info[x]["modes"]) for x in meths) + " |")
    lines.append("| categories | " + " | ".join(", ".join(info[x]["categories"]) for x in meths)
                 + " |")
    for k in keys:
        vals = [robots[x].get(k, "(default)") for x in meths]
        name = f"**{k}**" if len({str(v) for v in vals}) > 1 else k
        lines.append(f"| {name} | " + " | ".join(str(v) for v in vals) + " |")
    loop = {}
    for x in meths:
        for mode, by_s in info[x]["options"].items():
            for d in by_s.values():
                for k, v in d.items():
                    if k in ("robot", "mode", "reach_noise", "arm"):
                        continue
                    loop.setdefault(k, {})[x] = v
                loop.setdefault("reach_noise (px)", {}).setdefault(x, {})[mode] = d.get(
                    "reach_noise")
                arm = d.get("arm")
                loop.setdefault("arm (preset)", {}).setdefault(x, {})[mode] = (
                    arm.get("preset", "?") if isinstance(arm, dict) else "ideal")
                break
    for k in ("redundancy_radius", "robust_blurs", "robust_eta"):  # as the model resolved them
        if any(k in info[x].get("from_model", {}) for x in meths):
            vals = [info[x].get("from_model", {}).get(k, "") for x in meths]
            vals = [(", ".join(f"{v:g}" for v in val) or "none (not robust)")
                    if isinstance(val, list) else
                    (f"{val:.2f}" if isinstance(val, float) else str(val)) for val in vals]
            unit = "" if k == "robust_eta" else " (px)"
            lines.append(f"| {k}, resolved from the model{unit} | " + " | ".join(vals) + " |")
    for k, by_x in loop.items():
        vals = []
        for x in meths:
            v = by_x.get(x, "")
            if isinstance(v, dict):
                v = ", ".join(f"{m} {n:g}" if isinstance(n, (int, float)) else f"{m} {n}"
                              for m, n in v.items() if n is not None)
            vals.append(str(v))
        lines.append(f"| {k} | " + " | ".join(vals) + " |")
    return lines


def _threshold_table(art: Artifact, mode: str) -> list[str]:
    thr = art.array("thresholds")
    head = ("| method | category | strategy | " + " | ".join(f"< {t:g} px" for t in thr) + " |")
    lines = [head, "|" + "---|" * (len(thr) + 3)]
    for x, c, s, cur in ordered(art, "curves", mode):
        cells = [f"{_fmt_med(m)} ({100 * r:.0f} %)" for m, r in
                 zip(cur["median_samples"], cur["reached"], strict=True)]
        lines.append(f"| {x} | {c} | {s} | " + " | ".join(cells) + " |")
    return lines


def _pvalue_table(art: Artifact, mode: str) -> list[str]:
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    head = ("| method | category | test | smallest attainable p | "
            + " | ".join(f"< {t:g} px" for t in thr) + " |")
    lines = [head, "|" + "---|" * (len(thr) + 4)]
    for x, c, s, pv in ordered(art, "pvalues", mode):
        cells = []
        for p, stat in zip(pv["pvalue"], pv["statistic"], strict=True):
            sign = "" if p >= 0.05 else (" (faster)" if stat < 0 else " (slower)")
            cells.append(_fmt_p(p) + sign)
        mp = float(pv.get("min_pvalue", np.nan))
        mp_txt = "< 1e-300" if mp == 0 else _fmt_p(mp)
        lines.append(f"| {x} | {c} | {s} vs {base} | {mp_txt} | " + " | ".join(cells) + " |")
    return lines


def _rmse_table(art: Artifact, mode: str) -> list[str]:
    T = int(art.attrs["max_steps"])
    steps = [t for t in RMSE_STEPS if t <= T] or [T]
    head = "| method | category | strategy | " + " | ".join(f"t={t}" for t in steps) + " |"
    lines = [head, "|" + "---|" * (len(steps) + 3)]
    for x, c, s, cur in ordered(art, "curves", mode):
        r = cur["rmse"]
        lines.append(f"| {x} | {c} | {s} | " + " | ".join(f"{r[t - 1]:.2f}" for t in steps)
                     + " |")
    return lines


def _iqr(v: np.ndarray) -> str:
    if len(v) == 0:
        return "not measured"
    q = np.quantile(v, [0.25, 0.5, 0.75])
    return f"{100 * q[1]:.1f} % ({100 * q[0]:.1f}-{100 * q[2]:.1f})"


def _play_table(art: Artifact) -> list[str]:
    exp = art.data["experiments"]
    lines = ["| mode | method | category | before the displacement | after it, not adapted | "
             "after adaptation, per strategy |", "|---|---|---|---|---|---|"]
    for m in art.attrs["modes"]:
        for x in [x for x in _methods(art) if x in art.data["curves"].get(m, {})]:
            for c in [c for c in art.attrs["categories"] if c in art.data["curves"][m][x]]:
                sel = (exp["mode"] == m) & (exp["method"] == x) & (exp["category"] == c)
                after = "; ".join(f"{s} {_iqr(_play(art, sel & (exp['strategy'] == s), 'play_adapted'))}"
                                  for s in _methods(art)[x]["strategies"])
                lines.append(f"| {m} | {x} | {c} | {_iqr(_play(art, sel, 'play_before'))} | "
                             f"{_iqr(_play(art, sel, 'play_unadapted'))} | {after} |")
    return lines


def _ablation_table(art: Artifact, mode: str, category: str = "large") -> list[str]:
    """Large displacements: each method and estimator, the baseline against the others."""
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    js = [j for j, t in enumerate(thr) if t in (4.0, 2.0, 1.0)] or list(range(len(thr)))
    T = int(art.attrs["max_steps"])
    head = ("| method | posterior | estimator | strategy | RMSE at t=" + str(T) + " | "
            + " | ".join(f"obs. to < {thr[j]:g} px" for j in js)
            + " | " + " | ".join(f"p vs {base} (< {thr[j]:g} px)" for j in js) + " |")
    lines = [head, "|" + "---|" * (5 + 2 * len(js))]
    for x in _methods(art):
        cur, pvs = _cell(art, mode, x, category)
        if cur is None:
            continue
        r = _robot(art, x)
        ests = [(r.get("estimator", "?"), "")] + [(e, f"_{e}") for e in ("ml", "mean")
                                                  if e != r.get("estimator")]
        for est, sfx in ests:
            if sfx and f"rmse{sfx}" not in cur[base]:
                continue
            label = x if not sfx else f"{x} (same runs)"
            for s in [s for s in _methods(art)[x]["strategies"] if s in cur]:
                c = cur[s]
                rm = c["rmse" if not sfx else f"rmse{sfx}"][-1]
                meds = [f"{_fmt_med(c[f'median_samples{sfx}'][j])} "
                        f"({100 * c[f'reached{sfx}'][j]:.0f} %)" for j in js]
                ps = ["" if s == base else _fmt_p(pvs[s][f"pvalue{sfx}"][j]) for j in js]
                lines.append(f"| {label} | {r.get('posterior', '?')} | {est} | {s} | {rm:.2f} | "
                             + " | ".join(meds) + " | " + " | ".join(ps) + " |")
    return lines


def figures(art: Artifact) -> list[Figure]:
    """The figures of the report (file names and captions)."""
    art = upgrade(art)
    modes = art.attrs["modes"]
    first = "ideal" if "ideal" in modes else modes[0]
    figs = []
    ex = art.data.get("examples", {}).get(first, {})
    if any(any("snapshots" in e for e in by_s.values()) for by_s in ex.values()):
        figs.append(Figure("fig5_posterior.png", "Fig. 5: evolution of the posterior",
                           f"Posterior over the displacement (dx, dy) in px after 1, 2, 3, ... "
                           f"observations of one example run per method and strategy ({first} "
                           f"mode, first {art.config.get('example', '')} displacement; the same "
                           "displacement for every row), each panel scaled to its own maximum "
                           "(colour bar); the cross is the true displacement."))
    figs.append(Figure("fig6_entropy.png", "Fig. 6: entropy reduction",
                       "Posterior entropy (nats) against observations, mean over all experiments "
                       "of each method and strategy, with the interquartile range shaded; one "
                       "panel per mode. Entropies of different posteriors (KDE, likelihood) are "
                       "on the same grid but not of the same model: compare strategies within "
                       "a method."))
    for m in modes:
        figs.append(Figure(f"fig7_error_{m}.png", f"Fig. 7: error against observations ({m} mode)",
                           "RMSE of the displacement estimate (px) over the experiments of each "
                           "category against the number of observations, log scale, one row per "
                           "method; shaded: the interquartile range of the per-experiment error."))
    return figs


def build(art: Artifact) -> Report:
    """The report of an evaluation artifact: README text, claims and figures."""
    art = upgrade(art)
    _check(art)
    cl = claims(art)
    figs = figures(art)
    base = art.attrs["baseline"]
    judged = art.attrs["judged"]
    exp = art.data["experiments"]
    n = len(exp["mode"])
    model = art.inputs.get("model", {})
    info = _methods(art)
    sizes = {c: [float(np.hypot(*d[-2:])) for d in art.config['categories'][c]['displacements']]
             for c in art.attrs["categories"]}
    lines = [
        "# Where is my keyboard? Reproduction report",
        "",
        f"Generated by `kbcli report` from `{art.path or 'an evaluation artifact'}` "
        f"(sha256 `{(art.sha256 or '?')[:16]}`, kbcli {art.kbcli_version}, schema "
        f"{art.schema_version}).",
        "",
        f"- {n} experiments: {int(art.config['experiments'])} per displacement, method, strategy "
        f"and mode; {art.attrs['max_steps']} observations each; seed {art.seed}.",
        f"- modes: {', '.join(art.attrs['modes'])}; baseline strategy: {base}; transform family "
        f"{art.config.get('family', 'translation')}.",
        "- methods: " + "; ".join(f"`{x}` ({v.get('description') or 'no description'})"
                                  for x, v in info.items())
        + f". The paper's claims are judged on `{judged}`.",
        f"- model: {art.attrs.get('model_strategy')} (file {model.get('file')}, sha256 "
        f"`{str(model.get('sha256'))[:16]}`).",
        "- size categories (the Euclidean norm of the displacement): " + "; ".join(
            f"{c} (<= {art.config['categories'][c]['limit']:g} px: "
            + ", ".join(f"{v:.1f}" for v in sizes[c]) + " px)" for c in art.attrs["categories"]),
    ]
    if art.attrs.get("play_notes"):
        lines.append(f"- playing success: {art.attrs['play_notes']} touches of Algorithm 1 "
                     f"(melody `{art.attrs.get('melody')}`, actions sampled from the model, the "
                     "mode's arm and noise) before the displacement, after it without adaptation "
                     "(both once per displacement and repetition) and after each adaptation with "
                     "its final estimate as the correction.")
    else:
        lines.append("- playing success: not measured in this evaluation.")
    if (art.schema_version or 1) < 2:
        lines.append("- schema-1 artifact: one unnamed method (shown as `kbcli`), p-values from "
                     "the rank-sum test without tie correction, no measured playing success.")
    lines += [
        "",
        "## The paper's claims against our measurements",
        "",
        "| source | the paper says | judged on | options | we measured | verdict | beside it "
        "(other methods) |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in cl:
        lines.append(f"| {c.source} | {c.paper} | `{c.method}` | {c.options} | {c.measured} | "
                     f"**{c.verdict}** | {c.beside or '-'} |")
    whys = [c.why for c in cl if c.why]
    if whys:
        lines += ["", *[f"{w}." for w in whys]]
    lines += [
        "",
        "How claims are judged: a significance claim *up to X px* agrees when, at every threshold "
        "<= X px that the strategy or the baseline reaches in at least half its runs, the "
        "two-sided Mann-Whitney U test (tie-corrected normal approximation; the runs of the two "
        "strategies have their own seeds) on the observations needed is below the paper's bound "
        "and the strategy needed fewer; a threshold that misses the bound counts as "
        "*underpowered*, not *differs*, when the smallest p-value that many runs can give at all "
        "(`2 / C(n + m, n)`) is not below the bound; thresholds reached by neither in half their "
        "runs are called uninformative. *Not significant* agrees when no informative threshold "
        f"has p < {NOT_SIGNIFICANT:g} in the strategy's favour. Fig. 6's claim agrees when the "
        "strategy's mean entropy is below the baseline's at observations "
        + ", ".join(str(t) for t in ENTROPY_STEPS) + ". *Restores performance* agrees when, for "
        "every strategy, the median measured playing success after adaptation is at least the "
        f"median measured before the displacement minus {100 * RESTORED_MARGIN:.0f} points. A run "
        "that never gets below a threshold counts as max_steps + 1 observations.",
        "",
        "## Methods: every resolved option",
        "",
        "Options that differ between methods are in bold; `strategy`, `mode`, `max_steps`, "
        "`family` and `reach_noise` are set per experiment by the protocol.",
        "",
        *_methods_table(art),
        "",
    ]
    for f in figs:
        lines += [f"### {f.title}", "", f"![{f.title}]({f.name})", "", f.caption, ""]
    if "ideal" in art.attrs["modes"] and "large" in art.attrs["categories"]:
        lines += ["## Large displacements: representation, estimator or strategy? (ideal mode)", "",
                  "Each method's runs on the large displacements; rows marked *same runs* read the "
                  "other estimate (maximum-likelihood cell or posterior mean) of the same runs, "
                  "which every run records at every step. In brackets: the share of runs that got "
                  "below the threshold within max_steps.", "",
                  *_ablation_table(art, "ideal"), ""]
    for m in art.attrs["modes"]:
        lines += [
            f"## Observations to reach each error threshold ({m} mode)", "",
            "Median observations until the error first drops below the threshold (in brackets: "
            "the share of runs that got there within max_steps; '-' when fewer than half did).", "",
            *_threshold_table(art, m), "",
            f"## Mann-Whitney U p-values against {base} ({m} mode)", "",
            "Two-sided, tie-corrected, on the observations each run needed to reach the threshold; "
            "'faster'/'slower' marks p < 0.05; the smallest attainable p is that of the most "
            "extreme ranking of the two samples.", "",
            *_pvalue_table(art, m), "",
            f"## RMSE (px) after t observations ({m} mode)", "",
            *_rmse_table(art, m), "",
        ]
    lines += ["## Playing success (measured; median and interquartile range over runs)", "",
              *_play_table(art), ""]
    return Report(readme="\n".join(lines), claims=cl, figures=figs)
