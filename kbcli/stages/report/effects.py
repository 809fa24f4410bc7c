"""Effect sizes: how big a strategy's advantage over the baseline is, and whether it shrinks.

The paper's Sect. IV-B says that on medium displacements "the difference is not so big", and that
the advantage shrinks as the displacement grows: claims about the *size* of the effect, tested on
the observations each run needed to reach each error threshold:

- the advantage at a threshold is the probability of superiority
  ``A = P(strategy needs fewer) + P(tie) / 2``, the Mann-Whitney U over ``n m`` (0.5: none);
- its variance is DeLong's, so the difference of two categories' advantages has a one-sided normal
  test (zero variance, both saturated: p = 1).

The counts are the method estimator's ``samples_to_threshold``, or for another estimator of the
same runs (``_ml``, ``_mean``) recomputed from the per-step errors.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from kbcli.core.adaptation import stats
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.source import fmt_p

#: One-sided level at which a difference of advantages counts as shown.
EFFECT_LEVEL = 0.05
#: The per-step error of each estimator (the suffix of its keys in the artifact).
STEP_ERRORS = {"": "errors", "_ml": "ml_errors", "_mean": "mean_errors"}


def counts(art: Artifact, mode: str, method: str, category: str, strategy: str,
           sfx: str = "") -> np.ndarray | None:
    """(n, k) observations each run of one cell needed to reach each threshold, or None when the
    artifact does not hold them."""
    cur = art.data["curves"].get(mode, {}).get(method, {}).get(category, {}).get(strategy)
    if cur is None:
        return None
    if not sfx and "samples_to_threshold" in cur:
        return np.asarray(cur["samples_to_threshold"], float)
    steps, exp = art.data.get("steps", {}), art.data["experiments"]
    if STEP_ERRORS[sfx] not in steps:
        return None
    sel = ((exp["mode"] == mode) & (exp["method"] == method) & (exp["category"] == category)
           & (exp["strategy"] == strategy))
    errors = np.nan_to_num(np.asarray(steps[STEP_ERRORS[sfx]], float)[sel], nan=np.inf)
    return stats.samples_to_threshold(errors, art.array("thresholds")).astype(float)


def superiority(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Probability of superiority of ``a`` (n, k) over ``b`` (m, k), observations to each of ``k``
    thresholds of two independent samples: (k,) ``A = P(a < b) + P(a = b) / 2`` and (k,) its
    DeLong variance ``var_i(V10) / n + var_j(V01) / m``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    psi = (a[:, None, :] < b[None, :, :]) + 0.5 * (a[:, None, :] == b[None, :, :])  # (n, m, k)
    v10, v01 = psi.mean(axis=1), psi.mean(axis=0)
    var = np.zeros(a.shape[1])
    if len(a) > 1:
        var = var + v10.var(axis=0, ddof=1) / len(a)
    if len(b) > 1:
        var = var + v01.var(axis=0, ddof=1) / len(b)
    return psi.mean(axis=(0, 1)), var


def smaller_pvalue(big: tuple[float, float], small: tuple[float, float]) -> float:
    """One-sided p-value of 'the ``small`` advantage is below the ``big`` one', each given as
    ``(A, var)`` of independent samples."""
    diff = big[0] - small[0]
    sd = float(np.sqrt(big[1] + small[1]))
    if sd == 0:
        return 0.0 if diff > 0 else 1.0
    return float(ndtr(-diff / sd))


def advantages(art: Artifact, mode: str, method: str, category: str, strategy: str,
               sfx: str = "") -> dict | None:
    """The strategy's advantage over the baseline in one category: ``A``, ``var`` (k,), and
    ``informative`` (k,) bool (strategy or baseline reaches the threshold in half its runs), or
    None when the counts are not in the artifact."""
    base = art.attrs["baseline"]
    a = counts(art, mode, method, category, strategy, sfx)
    b = counts(art, mode, method, category, base, sfx)
    if a is None or b is None or not len(a) or not len(b):
        return None
    T = int(art.attrs["max_steps"])
    informative = np.maximum(stats.reached(a, T), stats.reached(b, T)) >= 0.5
    A, var = superiority(a, b)
    return {"A": A, "var": var, "informative": informative}


def shrinks(art: Artifact, mode: str, method: str, strategy: str, cats: list[str],
            upto: float = np.inf, sfx: str = "") -> tuple[str, str]:
    """(measured text, verdict) of 'the advantage shrinks along ``cats``' (each category's
    advantage below the previous one's).

    Read at every threshold <= ``upto`` px informative in every category: agrees when at each of
    them the advantage falls from each category to the next, and the fall from the first to the
    last is significant (one-sided p < :data:`EFFECT_LEVEL`) at one of them at least; differs
    otherwise.
    """
    thr = art.array("thresholds")
    adv = {c: advantages(art, mode, method, c, strategy, sfx) for c in cats}
    if any(v is None for v in adv.values()):
        return "per-run counts not in this evaluation", "not measured"
    common = np.all([adv[c]["informative"] for c in cats], axis=0) & (thr <= upto)
    if not common.any():
        return f"no threshold <= {upto:g} px informative in every category", "not measured"
    parts, falls, shown = [], True, False
    for j in np.flatnonzero(common):
        seq = [float(adv[c]["A"][j]) for c in cats]
        p = smaller_pvalue((seq[0], float(adv[cats[0]]["var"][j])),
                           (seq[-1], float(adv[cats[-1]]["var"][j])))
        falls &= all(x > y for x, y in zip(seq, seq[1:], strict=False))
        shown |= p < EFFECT_LEVEL
        parts.append(f"{thr[j]:g} px: " + " -> ".join(f"{x:.2f}" for x in seq) + f" (p={fmt_p(p)})")
    verdict = "agrees" if falls and shown else "differs"
    text = (f"advantage A = P({strategy} needs fewer observations) over "
            f"{' -> '.join(cats)}, one-sided p of the fall {cats[0]} -> {cats[-1]}: "
            + "; ".join(parts))
    return text, verdict


#: The thresholds the paper quotes its significance up to (Sect. IV-B: "up to 10 pixels" for small
#: displacements, "up to 8 pixels" for medium): the other reading of the trend reads these.
PAPER_UPTO = 10.0


def falls(art: Artifact, mode: str, method: str, strategy: str, cats: list[str],
          upto: float = PAPER_UPTO, sfx: str = "") -> tuple[str, str]:
    """(measured text, verdict) of the plainest other reading of 'the advantage shrinks along
    ``cats``': on the thresholds <= ``upto`` px informative in the first and last category, the
    advantage in the last is significantly below the first's at one of them at least (one-sided
    p < :data:`EFFECT_LEVEL`) and significantly above it at none."""
    thr = art.array("thresholds")
    first, last = cats[0], cats[-1]
    adv = {c: advantages(art, mode, method, c, strategy, sfx) for c in (first, last)}
    if any(v is None for v in adv.values()):
        return "per-run counts not in this evaluation", "not measured"
    common = adv[first]["informative"] & adv[last]["informative"] & (thr <= upto)
    if not common.any():
        return f"no threshold <= {upto:g} px informative in {first} and {last}", "not measured"
    fell, rose, parts = [], [], []
    for j in np.flatnonzero(common):
        a0, a1 = (float(adv[first]["A"][j]), float(adv[first]["var"][j])), \
            (float(adv[last]["A"][j]), float(adv[last]["var"][j]))
        p_fall, p_rise = smaller_pvalue(a0, a1), smaller_pvalue(a1, a0)
        if p_fall < EFFECT_LEVEL:
            fell.append(f"{thr[j]:g} px")
        if p_rise < EFFECT_LEVEL:
            rose.append(f"{thr[j]:g} px")
        parts.append(f"{thr[j]:g} px: {a0[0]:.2f} -> {a1[0]:.2f}")
    verdict = "agrees" if fell and not rose else "differs"
    text = (f"A over {first} -> {last} at the thresholds <= {upto:g} px: " + "; ".join(parts)
            + f"; significant fall (p < {EFFECT_LEVEL:g}) at " + (", ".join(fell) or "none")
            + ", significant rise at " + (", ".join(rose) or "none"))
    return text, verdict
