"""The tables behind ``kbcli bench verdicts``: a report's verdicts as a result file's tables.

The documentation's results pages read result files (``benchmarks/results/NAME.json``, one
``{"title", "columns", "rows"}`` per table, each cell a string). These functions make them from an
evaluation (:func:`claim_table`), a model-quality sweep (:func:`hypothesis_table`,
:func:`models_table`) and ``benchmarks/reproduce.sh``'s stage timings (:func:`timings_table`).
Pure: no I/O.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from kbcli.stages import quality
from kbcli.stages import report as stage
from kbcli.stages.artifact import Artifact
from kbcli.stages.report import inputs, readings, reproduces, runs
from kbcli.stages.report.departures import departures
from kbcli.stages.report.readings import as_verdicts
from kbcli.stages.report.readme import power_texts
from kbcli.stages.report.source import VERDICTS, compared, methods_of, others, short

#: A p-value measured (``p=0.0012``, ``p = 3.1e-07``), not a bound quoted from the paper (``p <``).
_P = re.compile(r"\bp ?= ?(\d+(?:\.\d+)?(?:e[-+]?\d+)?)\b")


@dataclass(frozen=True)
class ResultTable:
    """One table of a result file: ``rows`` are ``{column: cell}`` of strings."""

    title: str
    columns: tuple[str, ...]
    rows: tuple[dict[str, str], ...]


def smallest_p(text: str) -> str:
    """The smallest p-value measured in a claim's text (``-`` when it quotes none)."""
    ps = [float(m.group(1)) for m in _P.finditer(text)]
    return _p(min(ps)) if ps else "-"


def _p(p: float) -> str:
    """A p-value as the report writes it (``1`` for 1, else two digits), ``-`` when undefined."""
    if p != p:  # NaN: not computed
        return "-"
    return "1" if p >= 0.9995 else f"{p:.1e}"


CLAIM_COLUMNS = ("claim", "the paper says", "judged on", "kbcli measured", "verdict", "smallest p",
                 "under the other readings", "other methods")
OTHER_COLUMNS = ("claim", "method", "kbcli measured", "verdict", "smallest p")


def other_labels(art: Artifact) -> tuple[str, ...]:
    """How a claim's text names each other method's strategy (``"kbcli infogain"``), or the
    method alone where a claim reads all its strategies at once (playing success: ``"kbcli"``)."""
    return tuple(f"{x} {s}" for x in others(art) for s in compared(art, x)) + tuple(others(art))


def split_beside(beside: str, labels: tuple[str, ...]) -> list[tuple[str, str, str]]:
    """A claim's other methods (``"kbcli active: TEXT [verdict]; kbcli infogain: ..."``) as
    ``(label, text, verdict)``, cut where a known label starts (a text has ``;`` of its own)."""
    if not beside or not labels:
        return []
    names = "|".join(re.escape(x) for x in sorted(labels, key=len, reverse=True))
    starts = list(re.finditer(rf"(?:^|; )({names}): ", beside))
    if not starts:
        return []
    out = []
    for m, nxt in zip(starts, [*starts[1:], None], strict=True):
        text = beside[m.end():nxt.start() if nxt else len(beside)]
        v = re.search(r" \[([^\]]+)\]$", text)
        out.append((m.group(1), text[:v.start()] if v else text, v.group(1) if v else "-"))
    return out


def claim_table(claims, labels: tuple[str, ...] = ()) -> ResultTable:
    """The paper's claims (:class:`kbcli.stages.report.Claim`) with their verdicts: where the paper
    says it, what it says, the method judged (its options: :func:`evaluation_table`), what was
    measured, the verdict, the smallest p-value measured for it, and the other methods' verdicts
    (their measurements: :func:`others_table`; ``labels`` from :func:`other_labels`)."""
    rows = []
    for c in claims:
        beside = split_beside(c.beside, labels)
        summary = ("; ".join(f"{x}: {v}" for x, _, v in beside) if beside else c.beside) or "-"
        rows.append({"claim": c.source, "the paper says": c.paper, "judged on": c.method,
                     "kbcli measured": c.measured, "verdict": c.verdict,
                     "smallest p": smallest_p(c.measured),
                     "under the other readings": as_verdicts(c.readings),
                     "other methods": summary})
    return ResultTable("The paper's claims, judged", CLAIM_COLUMNS, tuple(rows))


def others_table(claims, labels: tuple[str, ...]) -> ResultTable:
    """The same claims measured on every other method: one row per claim and method."""
    rows = tuple({"claim": f"{c.source}: {c.paper}", "method": x, "kbcli measured": text,
                  "verdict": v, "smallest p": smallest_p(text)}
                 for c in claims for x, text, v in split_beside(c.beside, labels))
    return ResultTable("The same claims on the other methods", OTHER_COLUMNS, rows)


def verdict_counts(claims, labels: tuple[str, ...] = ()) -> ResultTable:
    """How many claims got each verdict (a column each): on the judged method, then on each other
    method's strategy (``labels`` from :func:`other_labels`)."""
    counts: dict[str, dict[str, int]] = {}
    for c in claims:
        for who, v in [(c.method, c.verdict),
                       *((x, v) for x, _, v in split_beside(c.beside, labels))]:
            counts.setdefault(who, {})[v] = counts.get(who, {}).get(v, 0) + 1
    seen = {v for by in counts.values() for v in by}
    verdicts = [v for v in VERDICTS if v in seen] + sorted(seen - set(VERDICTS))
    rows = tuple({"method": w, **{v: str(by.get(v, 0)) for v in verdicts}}
                 for w, by in counts.items())
    return ResultTable("Verdicts (claims per method)", ("method", *verdicts), rows)


EXPLAIN_COLUMNS = ("claim", "verdict along the ladder", "what flips it")


def evaluation_tables(art: Artifact, own: Artifact | None = None,
                      ladders: Sequence[Artifact] = (), *,
                      replicates: int = reproduces.REPLICATES,
                      rungs: Sequence[Artifact] = ()) -> list[ResultTable]:
    """Every table of an evaluation's verdicts, in the order the results page shows them: what
    reproduces, what ran, the verdict counts, the claims (and on the other methods), what
    explains each difference (with ``ladders``), what the evaluation's inputs change (with
    ``rungs`` or ``own``), the judging rules, the departures, the runs that ruled out the truth
    and the stopping rules."""
    art = stage.upgrade(art)
    claims = stage.claims(art, own)
    labels = other_labels(art)
    power = reproduces.powers(art, claims, own, replicates=replicates)
    texts = power_texts(claims, power)
    explained = []
    if ladders:
        from kbcli.stages.report.ablation import explained as ladder_rows

        explained = ladder_rows(claims, ladders, texts)
    on_inputs = [*rungs, *([own] if own is not None else [])]
    rung_rows = inputs.judged(claims, art, on_inputs, replicates=replicates)
    tables = [ResultTable("What reproduces", reproduces.COLUMNS,
                          tuple(reproduces.rows(claims, explained, power, rung_rows))),
              evaluation_table(art, own), verdict_counts(claims, labels),
              claim_table(claims, labels)]
    tables += [t for t in (others_table(claims, labels),) if t.rows]
    if ladders:
        tables.append(explain_table(claims, ladders, explained))
    if rung_rows:
        tables.append(ResultTable("What the evaluation's inputs change (each claim that differs, "
                                  "judged where the model or the reach noise is another)",
                                  inputs.COLUMNS, tuple(r.row() for r in rung_rows)))
    tables += [judging_table(), departures_table(art), *runs_tables(art)]
    return tables


def judging_table() -> ResultTable:
    """The judging rules the paper does not state: kbcli's and the plainest other reading."""
    cols = ("decides", "the paper says", "kbcli's rule", "the plainest other reading")
    return ResultTable("Judging rules the paper does not state", cols, tuple(
        dict(zip(cols, (r.claims, r.quote, r.ours, f"{r.name}: {r.other}"), strict=True))
        for r in readings.READINGS.values()))


def departures_table(art: Artifact) -> ResultTable:
    """Where the judged method departs from the paper's text or decides what it leaves open."""
    cols = ("source", "the paper says", "kbcli does", "why")
    return ResultTable(f"Departures from the paper (the judged method `{art.attrs['judged']}`)",
                       cols, tuple(dict(zip(cols, (d.source, d.quote.strip(), does, d.why),
                                            strict=True)) for d, does in departures(art)))


def runs_tables(art: Artifact) -> list[ResultTable]:
    """The final errors, the runs that ruled out the truth, and the stopping rules per mode (when
    recorded)."""
    out = []
    rows = runs.final_errors(art)
    if rows:
        out.append(ResultTable("Final error of every cell (RMSE over runs, and the largest)",
                               tuple(rows[0]), tuple(rows)))
    rows = runs.excluded(art)
    if rows:
        out.append(ResultTable(f"Runs that ruled out the truth (posterior at the truth below "
                               f"{runs.EXCLUDED:g} of its maximum at some step)",
                               tuple(rows[0]), tuple(rows)))
    for m in art.attrs["modes"]:
        rows = runs.stopping(art, m)
        if rows:
            out.append(ResultTable(f"Stopping rules applied to every run ({m} mode)",
                                   tuple(rows[0]), tuple(rows)))
    return out


def explain_table(claims, ablations: Artifact | Sequence[Artifact],
                  explained_rows: Sequence[tuple[str, str, str]] | None = None) -> ResultTable:
    """The report's "What explains each difference" as a result table: every claim marked
    *differs* on the judged method, judged on each rung of the ablation ladder ``ablations`` (an
    evaluation, or several: one per mode), and the rungs whose changes flip it
    (:func:`kbcli.stages.report.ablation.explained`; ``explained_rows``: those rows, computed
    already)."""
    from kbcli.stages.report.ablation import as_ladders, explained

    if explained_rows is None:
        explained_rows = explained(claims, ablations)
    rows = tuple(dict(zip(EXPLAIN_COLUMNS, r, strict=True)) for r in explained_rows)
    where = "; ".join(f"{a.path}, {len(a.data['experiments']['mode'])} experiments, "
                      f"{int(a.config['experiments'])} per cell, modes {', '.join(a.attrs['modes'])}"
                      for a in as_ladders(ablations))
    return ResultTable(f"What explains each difference (the ablation ladder {where})",
                       EXPLAIN_COLUMNS, rows)


def evaluation_table(art: Artifact, own: Artifact | None = None) -> ResultTable:
    """What the evaluation ran: its file, experiments, modes, methods (each with its posterior,
    estimator and strategies), model and seed; with ``own``, what the evaluation with the robot's
    own model ran (its file, experiments, modes, methods and model)."""
    a, cfg = art.attrs, art.config
    model = art.inputs.get("model", {})
    rows = (("evaluation", f"{art.path} (sha256 {(art.sha256 or '?')[:16]}, kbcli "
                           f"{art.kbcli_version})"),
            ("experiments", f"{len(art.data['experiments']['mode'])}: {int(cfg['experiments'])} per "
                            "displacement, method, strategy and mode"),
            ("observations per experiment", str(a["max_steps"])),
            ("modes", ", ".join(a["modes"])),
            *((f"method {x}", f"{short(art, x)}" + (f" ({v['description']})"
                                                     if v.get("description") else ""))
              for x, v in methods_of(art).items()),
            ("judged method", str(a["judged"])),
            ("model", f"{a.get('model_strategy')} (file {model.get('file')}, sha256 "
                      f"{str(model.get('sha256'))[:16]})"),
            ("seed", str(art.seed)),
            *(() if own is None else (("with the robot's own model", _own_row(own)),)))
    return ResultTable("The evaluation", ("what", "value"),
                       tuple({"what": k, "value": v} for k, v in rows))


def _own_row(own: Artifact) -> str:
    """The evaluation with the robot's own model in one line."""
    model = own.inputs.get("model", {})
    return (f"{own.path} (sha256 {(own.sha256 or '?')[:16]}): "
            f"{len(own.data['experiments']['mode'])} experiments, "
            f"{int(own.config['experiments'])} per displacement, method, strategy and mode; modes "
            f"{', '.join(own.attrs['modes'])}; methods {', '.join(methods_of(own))}; model "
            f"{own.attrs.get('model_strategy')} (file {model.get('file')}, sha256 "
            f"{str(model.get('sha256'))[:16]})")


def timings_table(text: str) -> tuple[ResultTable, ResultTable]:
    """The stage timings ``benchmarks/reproduce.sh`` writes (``stage  wall s`` lines, then notes
    in parentheses): the stages' wall times, and how the run was made (config, workers, load)."""
    stages, notes = [], []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("(") and line.endswith(")"):
            notes += [p.strip() for p in line[1:-1].split(";") if p.strip()]
            continue
        parts = line.split()
        if len(parts) == 2 and _number(parts[1]):
            stages.append({"stage": parts[0], "wall s": parts[1]})
    return (ResultTable("Wall time of each stage", ("stage", "wall s"), tuple(stages)),
            ResultTable("How it ran", ("note",), tuple({"note": n} for n in notes)))


def _number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def hypothesis_table(art: Artifact) -> ResultTable:
    """The paper's Sect. IV-C explanation tested on every row of a model-quality sweep but the
    baseline (:func:`kbcli.stages.quality.hypothesis`)."""
    a = art.attrs
    rows = []
    for r in a["rows"]:
        if r not in quality.compared_rows(a):
            continue
        h = quality.hypothesis(art, r)
        rows.append({"row": _vs(a, r, ""), "Spearman rho": "-" if h["rho"] != h["rho"] else f"{h['rho']:.2f}",
                     "p": _p(h["p"]),
                     "significant advantage, better half": f"{h['significant_good']} of {h['good']}",
                     "worse half": f"{h['significant_bad']} of {h['bad']}",
                     "verdict": quality.verdict(h)})
    cols = ("row", "Spearman rho", "p", "significant advantage, better half", "worse half",
            "verdict")
    return ResultTable("The paper's explanation (advantage over random against the model's "
                       "boundary error), tested", cols, tuple(rows))


def models_table(art: Artifact) -> ResultTable:
    """Each model of a model-quality sweep: accuracy, boundary error, threshold, and each row's
    advantage over the baseline (median touches saved to tau, all categories, with its p)."""
    a = art.attrs
    others = quality.compared_rows(a)
    models = sorted(a["models"].items(), key=lambda kv: (str(kv[1].get("exploration", "")),
                                                         float(kv[1].get("budget", 0)), kv[0]))
    rows = []
    for m, mi in models:
        row = {"model": m, "accuracy": f"{100 * mi['accuracy']:.1f} %",
               "boundary error px": f"{mi['boundary_error']:.2f}", "tau px": f"{mi['threshold']:.2f}"}
        for r in others:
            s = a["summary"][m]["all"][r]
            row[_vs(a, r, "advantage")] = f"{s['advantage']:+g} (p {_p(s['pvalue'])})"
        rows.append(row)
    cols = ("model", "accuracy", "boundary error px", "tau px",
            *(_vs(a, r, "advantage") for r in others))
    return ResultTable("Models and each row's advantage over " + a["baseline"]
                       + " (median touches saved to tau; a row with its own baseline names it)",
                       cols, tuple(rows))


def _vs(a: dict, row: str, what: str) -> str:
    """A row's column: ``"ROW WHAT"``, with ``vs BASE`` when the row has its own baseline."""
    base = quality.baseline_of(a, row)
    return " ".join(p for p in (row, what, f"vs {base}" if base != a["baseline"] else "") if p)


#: A model's boundary error "levels off" within this fraction above the largest budget's.
PLATEAU = 0.2


def plateau_budget(budgets, errors, within: float = PLATEAU) -> int:
    """The smallest budget whose boundary error is within ``within`` (a fraction) above the
    boundary error of the largest budget: where more reaches stop making the model better."""
    pairs = sorted(zip((int(b) for b in budgets), (float(e) for e in errors), strict=True))
    if not pairs:
        raise ValueError("no budget to choose from")
    bound = (1 + within) * pairs[-1][1]
    return next(b for b, e in pairs if e <= bound)


def plateau_table(art: Artifact, within: float = PLATEAU) -> ResultTable:
    """Per exploration of a model-quality sweep, the budget where the boundary error levels off
    (:func:`plateau_budget`) with its model's accuracy, boundary error and advantages: the budget
    ``make reproduce-own-model`` learns the robot's own model with (``OWN_BUDGET``)."""
    a = art.attrs
    others = quality.compared_rows(a)
    by: dict[str, list[tuple[int, str, dict]]] = {}
    for m, mi in a["models"].items():
        by.setdefault(str(mi.get("exploration", "")), []).append((int(mi["budget"]), m, mi))
    rows = []
    for ex, models in sorted(by.items()):
        models.sort()
        b = plateau_budget([x[0] for x in models], [x[2]["boundary_error"] for x in models], within)
        _, m, mi = next(x for x in models if x[0] == b)
        top = models[-1]
        row = {"exploration": ex, "budget": str(b), "model": m,
               "accuracy": f"{100 * mi['accuracy']:.1f} %",
               "boundary error px": f"{mi['boundary_error']:.2f}",
               "at the largest budget": f"{top[2]['boundary_error']:.2f} px ({top[0]})"}
        for r in others:
            row[_vs(a, r, "touches saved")] = f"{a['summary'][m]['all'][r]['advantage']:+g}"
        rows.append(row)
    cols = ("exploration", "budget", "model", "accuracy", "boundary error px", "at the largest budget",
            *(_vs(a, r, "touches saved") for r in others))
    return ResultTable(f"Where learning levels off: the smallest budget whose boundary error is "
                       f"within {100 * within:.0f} % of the largest budget's (touches saved: "
                       f"median, to tau, over {a['baseline']})", cols, tuple(rows))


def sweep_table(art: Artifact) -> ResultTable:
    """What the model-quality sweep ran."""
    a, cfg = art.attrs, art.config
    rows = (("sweep", f"{art.path} (sha256 {(art.sha256 or '?')[:16]}, kbcli {art.kbcli_version})"),
            ("models", f"{len(a['models'])}: {', '.join(cfg['explorations'])} exploration x "
                       f"{', '.join(str(b) for b in cfg['budgets'])} reaches"),
            ("adaptations", str(a["n_experiments"])),
            ("mode, arm", f"{cfg['mode']}, {cfg['arm']['preset']}"),
            ("rows", ", ".join(a["rows"])),
            ("repetitions per displacement", str(cfg["experiments"])),
            ("touches per adaptation", str(a["max_steps"])),
            ("seed", str(art.seed)))
    return ResultTable("The sweep", ("what", "value"), tuple({"what": k, "value": v} for k, v in rows))
