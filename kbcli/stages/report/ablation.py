"""What explains each difference: the claims along an ablation ladder (``pipelines/ablations.toml``).

The ladder is an evaluation whose methods go from the paper's method to ours one factor at a time.
For every claim the main report marks *differs*, :func:`explain` judges it on every rung with the
same rule (:func:`kbcli.stages.report.paper.claim_rules`; a rung's last non-baseline strategy) and
names the options whose change flips the verdict, computed from the artifact. A ladder run per
mode (``make reproduce-ablations MODE=...``) comes as several evaluations: each claim is explained
by the first that measures it.
"""

from __future__ import annotations

from collections.abc import Sequence

from kbcli.stages.artifact import Artifact
from kbcli.stages.report.paper import claim_rules
from kbcli.stages.report.source import Claim, compared, method_names, methods_of, upgrade
from kbcli.stages.report.tables import NOT_APPLICABLE, applicable


def rung_strategy(art: Artifact, method: str) -> str | None:
    """The strategy a rung is judged on: its last non-baseline strategy."""
    s = compared(art, method)
    return s[-1] if s else None


def changes(art: Artifact, before: str, after: str) -> list[str]:
    """What changes from rung ``before`` to ``after``: each differing robot option that applies
    to both (one that applies to only one follows from another change, e.g. ``kde_samples`` from
    ``posterior``) and the judged strategy, as ``'key a -> b'``."""
    a, b = applicable(art, before), applicable(art, after)
    out = [f"{k} {a.get(k, '(default)')} -> {b.get(k, '(default)')}"
           for k in sorted(set(a) | set(b))
           if str(a.get(k)) != str(b.get(k)) and NOT_APPLICABLE not in (a.get(k), b.get(k))]
    sa, sb = rung_strategy(art, before), rung_strategy(art, after)
    if sa != sb:
        out.append(f"strategy {sa} -> {sb}")
    for k in ("modes", "categories"):
        if methods_of(art)[before][k] != methods_of(art)[after][k]:
            out.append(f"{k} {', '.join(methods_of(art)[before][k])} -> "
                       f"{', '.join(methods_of(art)[after][k])}")
    return out


def ladder(ablations: Artifact, claim: str) -> list[tuple[str, str, str]] | None:
    """``(rung, strategy, verdict)`` of one claim (its paper text) along the ladder, or None when
    the ladder's artifact has no rule for it."""
    rules = claim_rules(ablations)
    if claim not in rules:
        return None
    out = []
    for x in method_names(ablations):
        s = rung_strategy(ablations, x)
        if s is None:
            continue
        out.append((x, s, rules[claim](x, s)[1]))
    return out


#: What the section "What explains each difference" says before its table.
INTRO = ("Every claim marked *differs*, judged with the same rule on each rung of the ablation "
         "ladder ({path}, its methods in order, each changing some options of the one before; a "
         "rung is judged on its last strategy other than the baseline). A flip is a rung whose "
         "verdict leaves or returns to *differs*; what flips it is what that rung changes.")


def explained(claims: list[Claim], ablations: Artifact | Sequence[Artifact],
              power: dict[str, str] | None = None) -> list[tuple[str, str, str]]:
    """``(claim, verdict along the ladder, what flips it)`` for every claim marked *differs* (its
    paper text once), as the section's table rows (:func:`explain`; ``kbcli bench verdicts
    --ablations`` keeps them as a result table). With several ladder evaluations (one per mode),
    each claim is read on the first that measures it on some rung. ``power``: by claim text, the
    replication statement (:mod:`.power`) a claim that no rung flips is given."""
    ladders = [upgrade(a) for a in as_ladders(ablations)]
    rows = []
    seen = set()
    for c in claims:
        if c.verdict != "differs" or c.paper in seen:
            continue
        seen.add(c.paper)
        found = next(((a, st) for a in ladders if (st := ladder(a, c.paper))
                      and any(v != "not measured" for _, _, v in st)), None)
        if found is None:
            rows.append((c.paper, "not measured by the ladder", "-"))
            continue
        art, steps = found
        path = " -> ".join(f"`{x}` ({s}) {v}" for x, s, v in steps)
        if len(ladders) > 1:
            path = f"{art.path or 'the ladder'}: {path}"
        flips = _flips(art, steps)
        if flips.startswith("no rung flips it: it differs") and (power or {}).get(c.paper):
            flips = f"{flips}; {power[c.paper]}"
        rows.append((c.paper, path, flips))
    return rows


def as_ladders(ablations: Artifact | Sequence[Artifact]) -> list[Artifact]:
    """The ladder's evaluations as a list (one artifact, or several: one per mode)."""
    return [ablations] if isinstance(ablations, Artifact) else list(ablations)


def explain(claims: list[Claim], ablations: Artifact | Sequence[Artifact],
            power: dict[str, str] | None = None) -> list[str]:
    """The section "What explains each difference" (markdown lines): for every claim marked
    *differs*, its verdict on every rung and the changes that flip it."""
    where = " and ".join(f"`{a.path or 'an ablation evaluation'}`" for a in as_ladders(ablations))
    lines = ["## What explains each difference", "", INTRO.format(path=where), ""]
    rows = explained(claims, ablations, power)
    if not rows:
        return [*lines, "No claim is marked *differs*.", ""]
    lines += ["| claim | verdict along the ladder | what flips it |", "|---|---|---|"]
    lines += [f"| {claim} | {path} | {flips} |" for claim, path, flips in rows]
    return [*lines, ""]


def _flips(art: Artifact, steps: list[tuple[str, str, str]]) -> str:
    """The rungs at which a verdict leaves (or returns to) *differs*, with what they change."""
    measured = [st for st in steps if st[2] != "not measured"]
    flips = []
    for (x0, _, v0), (x1, _, v1) in zip(measured, measured[1:], strict=False):
        if (v0 == "differs") != (v1 == "differs"):
            what = "; ".join(changes(art, x0, x1)) or "nothing in the resolved options"
            flips.append(f"`{x0}` -> `{x1}` ({v0} -> {v1}): {what}")
    if flips:
        return "; ".join(flips)
    if measured and all(v == "differs" for _, _, v in measured):
        return "no rung flips it: it differs on every rung"
    return "no rung flips it: it does not differ on any measured rung of the ladder"
