"""What reproduces: each claim, its verdict on the paper's method, and one line of why.

The line is measured, never written by hand: for a claim that agrees, whether it still agrees under
every other reading of the rules the paper does not state (:mod:`.readings`); for one that
differs, the rung of the ablation ladder that flips it (:mod:`.ablation`), or else how likely the
paper's verdict is at the paper's sample size if the effect is ours (:mod:`.power`), and what the
rungs on the evaluation's inputs say of it (:mod:`.inputs`: the model, the reach noise).
"""

from __future__ import annotations

from collections.abc import Sequence

from kbcli.stages.artifact import Artifact
from kbcli.stages.report.inputs import InputRung
from kbcli.stages.report.inputs import why as on_the_inputs
from kbcli.stages.report.paper import OWN_SOURCE, claim_rules
from kbcli.stages.report.power import REPLICATES, Replication, replication
from kbcli.stages.report.source import Claim

#: The columns of the table.
COLUMNS = ("claim", "the paper says", "verdict on the paper's method", "why")


def powers(art: Artifact, claims: Sequence[Claim], own: Artifact | None = None, *,
           replicates: int = REPLICATES) -> dict[int, Replication | None]:
    """For every claim that differs (by its index in ``claims``), the share of bootstrap
    replicates at the paper's sample size that agree (:func:`.power.replication`; ``own``: the
    evaluation the own-model claims were judged on). ``replicates`` 0: none computed."""
    out: dict[int, Replication | None] = {}
    if replicates <= 0:
        return out
    for i, c in enumerate(claims):
        if c.verdict != "differs" or not c.mode:
            continue
        src = own if c.source == OWN_SOURCE else art
        if src is None:
            continue
        out[i] = replication(src, lambda rep, c=c: claim_rules(rep).get(c.paper), c.mode,
                             c.method, c.strategy, replicates=replicates)
    return out


def _flip(claim: Claim, explained: Sequence[tuple[str, str, str]]) -> str | None:
    """The ladder's flip of a claim (its "what flips it" cell), when a rung flips it."""
    for text, _, flips in explained:
        if text == claim.paper and not flips.startswith("no rung flips it") and flips != "-":
            return flips
    return None


def why(claim: Claim, explained: Sequence[tuple[str, str, str]] = (),
        power: Replication | None = None, rungs: Sequence[InputRung] = ()) -> str:
    """One line of why a claim got its verdict (``rungs``: the claims judged on the rungs on
    the evaluation's inputs)."""
    odd = [label for label, _, v in claim.readings if v not in (claim.verdict, "not measured")]
    if claim.verdict == "agrees":
        return ("agrees under every other reading of the rules the paper does not state"
                if not odd else "agrees; under another reading it would not: " + ", ".join(odd))
    if claim.verdict == "differs":
        flip = _flip(claim, explained)
        parts = [f"the ablation ladder flips it: {flip}" if flip else
                 (power.text() if power is not None else
                  "no rung of the ablation ladder flips it, and no replication was computed")]
        if odd:
            parts.append("it would agree under another reading: " + ", ".join(odd))
        if (on_inputs := on_the_inputs(claim, rungs)) is not None:
            parts.append(on_inputs)
        return "; ".join(parts)
    if claim.verdict == "underpowered":
        return "too few runs to show the paper's p-value at all"
    return "not measured by this evaluation (" + claim.measured[:80] + ")"


def rows(claims: Sequence[Claim], explained: Sequence[tuple[str, str, str]] = (),
         power: dict[int, Replication | None] | None = None,
         rungs: Sequence[InputRung] = ()) -> list[dict[str, str]]:
    """The table's rows: one per claim (each strategy its own row)."""
    power = power or {}
    out = []
    for i, c in enumerate(claims):
        who = f"{c.method} {c.strategy}".strip()
        out.append({"claim": c.source, "the paper says": c.paper,
                    "verdict on the paper's method": f"{c.verdict} ({who})",
                    "why": why(c, explained, power.get(i), rungs)})
    return out


def table(claims: Sequence[Claim], explained: Sequence[tuple[str, str, str]] = (),
          power: dict[int, Replication | None] | None = None,
          rungs: Sequence[InputRung] = ()) -> list[str]:
    """The section "What reproduces" (markdown lines)."""
    lines = ["## What reproduces", "",
             "Each claim of the paper, its verdict on the paper's method as kbcli runs it, and "
             "one measured line of why (details in the sections below).", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(r[k] for k in COLUMNS) + " |"
              for r in rows(claims, explained, power, rungs)]
    return [*lines, ""]
