"""How likely the paper's verdict is at the paper's sample size, if the effect is the one we measured.

:func:`replication` draws replicates of our experiment at the paper's 50 runs per parametrization
(a stratified bootstrap of the runs), recomputes the evaluation's summaries for each
(:func:`kbcli.stages.evaluate.assembly.resummarise`) and judges the claim with its own rule: the
share of replicates that *agree* estimates how likely the paper's protocol, run on our system,
gives the paper's verdict.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.errors import KbcliError
from kbcli.stages.artifact import Artifact

#: Replicates drawn per claim (``kbcli report --replicates``).
REPLICATES = 100
#: Experiments per parametrization in the paper (Sect. IV-B).
PAPER_RUNS = 50
#: A difference is "not chance" when the probability of the paper's verdict is below this (its
#: 95 % upper bound); "within the noise" when its 95 % lower bound is above half of it.
NOT_CHANCE = 0.1


@dataclass(frozen=True)
class Replication:
    """The share of replicates of a claim that agree with the paper."""

    agree: int
    replicates: int
    runs: int  # experiments per parametrization in each replicate

    @property
    def share(self) -> float:
        return self.agree / self.replicates if self.replicates else float("nan")

    def text(self) -> str:
        """One sentence for the report."""
        upper = _upper(self.agree, self.replicates)
        lower = 1 - _upper(self.replicates - self.agree, self.replicates)
        if upper < NOT_CHANCE:
            why = "the difference is not chance at the paper's sample size"
        elif lower > NOT_CHANCE / 2:
            why = "the paper's verdict is within the noise of a protocol of this size"
        else:
            why = "too few replicates to tell (kbcli report --replicates)"
        return (f"at the paper's {self.runs} runs per parametrization, {self.agree} of "
                f"{self.replicates} bootstrap replicates of this evaluation agree with the paper "
                f"(probability {self.share:.2f}, 95 % interval {lower:.2f}-{upper:.2f}): {why}")


def _upper(k: int, n: int) -> float:
    """One-sided 95 % upper bound of a binomial proportion ``k / n`` (Clopper-Pearson); the
    lower bound is ``1 - _upper(n - k, n)``."""
    from scipy.stats import beta

    return 1.0 if k >= n else float(beta.ppf(0.95, k + 1, n - k))


def strata(art: Artifact, mode: str, method: str) -> list[np.ndarray]:
    """The experiment rows of ``mode`` and ``method``, one array per (category, parametrization,
    strategy)."""
    exp = art.data["experiments"]
    sel = (exp["mode"] == mode) & (exp["method"] == method)
    keys = np.array([f"{c}|{p}|{s}" for c, p, s in zip(exp["category"], exp["param_index"],
                                                        exp["strategy"], strict=True)])
    return [np.flatnonzero(sel & (keys == k)) for k in sorted(set(keys[sel]))]


def replication(art: Artifact, rule, mode: str, method: str, strategy: str, *,
                replicates: int = REPLICATES, runs: int = PAPER_RUNS,
                seed: int = 0) -> Replication | None:
    """The share of bootstrap replicates (``runs`` experiments per parametrization) in which
    ``rule`` gives *agrees*: ``rule(artifact) -> fn(method, strategy) -> (text, verdict)`` is the
    claim's rule (:func:`kbcli.stages.report.paper.claim_rules`). None when the evaluation cannot
    be resummarised (no per-run records).
    """
    from kbcli.stages.evaluate.assembly import resummarise

    exp, steps = art.data["experiments"], art.data.get("steps", {})
    if any(k not in exp for k in ("param_index", "category", "strategy")) or "errors" not in steps:
        return None  # an evaluation without per-run records cannot be resampled
    groups = strata(art, mode, method)
    if not groups:
        return None
    rng = np.random.default_rng(np.random.SeedSequence([seed, replicates, runs]))
    agree = 0
    for _ in range(replicates):
        rows = np.concatenate([g[rng.integers(len(g), size=runs)] for g in groups])
        try:
            rep = resummarise(art, rows, only=(mode, method))
        except (KbcliError, KeyError, ValueError):
            return None
        fn = rule(rep)
        if fn is None:
            return None
        agree += fn(method, strategy)[1] == "agrees"
    return Replication(agree, replicates, runs)
