"""Rungs on the evaluation's inputs: each claim that differs, judged again where the robot is
given something else, not told to reason otherwise.

A rung is an evaluation of the same protocol in which the judged method keeps its options while
an input the paper blames (Sect. IV-C) changes: the model (``make reproduce-own-model``) or the
arm's landing scatter (``make reproduce-reach-noise``). Each claim that *differs* is judged on every
rung with the same rule (:func:`.paper.claim_rules`) and replicated at the paper's sample size
(:mod:`.power`); a rung *flips* a claim that agrees in most replicates. What a rung changes is
computed from the two artifacts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from kbcli.stages.artifact import Artifact
from kbcli.stages.report.paper import OWN_SOURCE, claim_rules
from kbcli.stages.report.power import REPLICATES, Replication, replication
from kbcli.stages.report.source import Claim, method_names, upgrade

#: The columns of the table (the report's section and ``kbcli bench verdicts``).
COLUMNS = ("claim", "rung", "what the rung changes", "runs per cell", "verdict",
           "at the paper's 50 runs")


@dataclass(frozen=True)
class InputRung:
    """One claim judged on one rung."""

    claim: str  # the paper's text
    rung: str  # the rung's file
    changes: str  # what differs from the main evaluation's inputs
    runs: int  # experiments per parametrization in the rung
    verdict: str
    replicated: Replication | None

    @property
    def flips(self) -> bool:
        """The claim agrees on this rung at the paper's sample size (most replicates agree)."""
        if self.replicated is not None:
            return self.replicated.share >= 0.5
        return self.verdict == "agrees"

    def said(self) -> str:
        """The rung's verdict in a few words: ``'reach noise ...: agrees at 10 runs per cell, 0
        of 100 replicates at the paper's 50'``."""
        rep = self.replicated
        at = (f" at {self.runs} runs per cell, {rep.agree} of {rep.replicates} replicates agree "
              f"at the paper's {rep.runs}" if rep is not None else "")
        return f"{self.changes}: {self.verdict}{at}"

    def row(self) -> dict[str, str]:
        rep = self.replicated
        share = (f"{rep.agree} of {rep.replicates} replicates agree" if rep is not None else "-")
        return dict(zip(COLUMNS, (self.claim, self.rung, self.changes, str(self.runs),
                                  self.verdict, share), strict=True))


def inputs_of(art: Artifact) -> dict[str, str]:
    """What the robot was given, by name: the model, and each evaluated mode's arm preset and
    extra landing scatter (reach noise)."""
    model = art.inputs.get("model", {})
    out = {"model": f"{model.get('file')} (sha256 {str(model.get('sha256'))[:16]})"}
    for m in art.attrs["modes"]:
        arm = art.config.get("arm", {}).get(m, {})
        out[f"arm ({m})"] = str(arm.get("preset", arm) if isinstance(arm, dict) else arm)
        out[f"reach noise ({m})"] = f"{float(art.config.get('reach_noise', {}).get(m, 0.0)):g} px"
    return out


def changes(main: Artifact, rung: Artifact, mode: str | None = None) -> list[str]:
    """Each input of ``rung`` that differs from ``main``'s, as ``'name a -> b'`` (modes that only
    one of them evaluates are left out; with ``mode``, those of the other modes too: a claim is
    judged on its own mode)."""
    a, b = inputs_of(main), inputs_of(rung)
    return [f"{k} {a[k]} -> {b[k]}" for k in b if k in a and a[k] != b[k]
            and (mode is None or "(" not in k or k.endswith(f"({mode})"))]


def judged_on(claim: Claim, main: Artifact, rung: Artifact, *,
              replicates: int = REPLICATES) -> InputRung | None:
    """``claim`` (marked *differs* on ``main``) judged on ``rung``, or None when the rung does
    not measure it (another mode, no rule for it, or no method of the judged method's name)."""
    rung = upgrade(rung)
    rule = claim_rules(rung).get(claim.paper)
    if (rule is None or claim.mode not in rung.attrs["modes"]
            or claim.method not in method_names(rung)):
        return None
    verdict = rule(claim.method, claim.strategy)[1]
    rep = (replication(rung, lambda r: claim_rules(r).get(claim.paper), claim.mode, claim.method,
                       claim.strategy, replicates=replicates) if replicates > 0 else None)
    return InputRung(claim.paper, rung.path or "a rung", "; ".join(changes(main, rung, claim.mode))
                     or "nothing in its recorded inputs", int(rung.config["experiments"]),
                     verdict, rep)


def judged(claims: Sequence[Claim], main: Artifact, rungs: Sequence[Artifact], *,
           replicates: int = REPLICATES) -> list[InputRung]:
    """Every claim the main evaluation marks *differs* (once per paper text; not the claims
    judged on the robot's own model, which is itself a rung) judged on every rung that measures
    it."""
    out, seen = [], set()
    for c in claims:
        if c.verdict != "differs" or not c.mode or c.source == OWN_SOURCE or c.paper in seen:
            continue
        seen.add(c.paper)
        out += [r for rung in rungs
                if (r := judged_on(c, main, rung, replicates=replicates)) is not None]
    return out


def why(claim: Claim, rows: Sequence[InputRung]) -> str | None:
    """What the input rungs say of a claim that differs, in one clause (None: no rung measured
    it)."""
    mine = [r for r in rows if r.claim == claim.paper]
    if not mine or claim.source == OWN_SOURCE:
        return None
    flips = [r for r in mine if r.flips]
    if flips:
        return ("it agrees on an input rung: " + "; ".join(f"{r.said()} ({r.rung})" for r in flips))
    return "no input rung flips it (" + "; ".join(r.said() for r in mine) + ")"


def section(rows: Sequence[InputRung]) -> list[str]:
    """The report's section "What the evaluation's inputs change" (markdown lines)."""
    lines = ["## What the evaluation's inputs change", "",
             "Every claim marked *differs*, judged with the same rule on evaluations of the same "
             "protocol in which the judged method is unchanged and an input is not: the model "
             "(the robot's own learned model) or the arm's landing scatter (reach noise), the "
             "two reasons the paper gives for its robot's results (Sect. IV-C). Each is also "
             "replicated at the paper's 50 runs per parametrization, as the main evaluation's "
             "differences are.", ""]
    if not rows:
        return [*lines, "No rung measures a claim marked *differs*.", ""]
    lines += ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(r.row()[k] for k in COLUMNS) + " |" for r in rows]
    return [*lines, ""]
