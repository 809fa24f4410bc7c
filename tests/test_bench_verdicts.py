"""``kbcli bench verdicts``: a report's verdicts and a run's stage timings as a result file's tables
(what the documentation's results pages render for the paper's reproduction and the model-quality
sweep)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

from helpers import one_line_error

from kbcli.bench import verdicts
from kbcli.cli import app
from kbcli.io.artifact import read_artifact
from kbcli.stages import report as stage

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "data" / "golden"
_spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "tools" / "docs_hooks.py")
hooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hooks)

#: Bootstrap replicates of each claim that differs, on the golden evaluation: 2, not the default
#: 100 (still seeded, resampled and judged; 100 were most of these tests' time).
FEW_REPLICATES = ["--replicates", "2"]

#: What benchmarks/reproduce.sh writes to $OUT/timings.txt.
TIMINGS = """stage          wall s
keyboard          0.9
learn            41.3
evaluate        612.0
report           12.5
total           666.7
(config: pipelines/paper.toml; mode: ideal+dynamics; methods: all of the config; jobs 2; experiments per parametrization: config)
(load average, 1/5/15 min: 1.02 0.80 0.50 before, 2.10 1.90 1.20 after; 2 cores)
"""


def test_smallest_p_reads_measured_p_values_not_the_papers_bounds():
    assert verdicts.smallest_p("not at 8 px (p=1), 4 px (p=0.0012): p < 1e-05 needed") == "1.2e-03"
    assert verdicts.smallest_p("rho = -0.62, p = 3.1e-07; (p=1)") == "3.1e-07"
    assert verdicts.smallest_p("8 px: 0.00 -> 0.50 (p=1)") == "1"
    assert verdicts.smallest_p("no threshold with p < 0.01") == "-"
    assert verdicts.smallest_p("mean entropy t=5: 4.62 vs 6.32 nats") == "-"


def test_timings_table_reads_what_reproduce_sh_writes():
    stages, notes = verdicts.timings_table(TIMINGS)
    assert stages.columns == ("stage", "wall s")
    assert [r["stage"] for r in stages.rows] == ["keyboard", "learn", "evaluate", "report", "total"]
    assert stages.rows[2]["wall s"] == "612.0"
    assert {"note": "jobs 2"} in notes.rows and {"note": "2 cores"} in notes.rows
    assert notes.rows[0] == {"note": "config: pipelines/paper.toml"}
    empty, no_notes = verdicts.timings_table("")
    assert empty.rows == () and no_notes.rows == ()


def test_claim_table_has_one_row_per_claim_with_its_verdict():
    art = stage.upgrade(read_artifact(GOLDEN / "evaluation.h5", ("evaluation",)))
    claims = stage.claims(art)
    t = verdicts.claim_table(claims)
    assert t.columns == verdicts.CLAIM_COLUMNS and len(t.rows) == len(claims)
    for row, c in zip(t.rows, claims, strict=True):
        assert set(row) == set(t.columns)
        assert row["verdict"] == c.verdict in stage.VERDICTS
        assert row["the paper says"] == c.paper and row["kbcli measured"] == c.measured
    counts = verdicts.verdict_counts(claims)
    assert counts.columns[0] == "method" and set(counts.columns[1:]) <= set(stage.VERDICTS)
    (row,) = counts.rows
    assert sum(int(row[v]) for v in counts.columns[1:]) == len(claims)


def test_other_methods_are_cut_where_a_known_label_starts():
    """A claim's text has ``;`` and ``[verdict]`` of its own: only a known method label cuts it."""
    beside = ("kbcli active: significant: not at 8 px (p=0.2) [underpowered]; smaller: 8 px: "
              "0.4 -> 0.6 (p=0.7) [differs] [differs]; kbcli infogain: at 8 px (p=1e-06) [agrees]")
    labels = ("kbcli active", "kbcli infogain", "paper-v1 active")
    parts = verdicts.split_beside(beside, labels)
    assert [(x, v) for x, _, v in parts] == [("kbcli active", "differs"), ("kbcli infogain", "agrees")]
    assert parts[0][1].endswith("(p=0.7) [differs]") and parts[1][1] == "at 8 px (p=1e-06)"
    assert verdicts.split_beside("", labels) == [] and verdicts.split_beside(beside, ()) == []
    claim = stage.Claim("Sect. IV-B", "small: active beats random", "paper", "kde", "p=0.5",
                        "underpowered", beside)
    (row,) = verdicts.claim_table([claim], labels).rows
    assert row["other methods"] == "kbcli active: differs; kbcli infogain: agrees"
    others = verdicts.others_table([claim], labels)
    assert [(r["method"], r["verdict"], r["smallest p"]) for r in others.rows] == [
        ("kbcli active", "differs", "2.0e-01"), ("kbcli infogain", "agrees", "1.0e-06")]
    counts = verdicts.verdict_counts([claim, claim], labels)
    assert counts.columns == ("method", "agrees", "differs", "underpowered")
    assert counts.rows == ({"method": "paper", "agrees": "0", "differs": "0", "underpowered": "2"},
                           {"method": "kbcli active", "agrees": "0", "differs": "2",
                            "underpowered": "0"},
                           {"method": "kbcli infogain", "agrees": "2", "differs": "0",
                            "underpowered": "0"})


def test_bench_verdicts_writes_a_result_file_that_regenerates_identically(tmp_path, runner,
                                                                         monkeypatch):
    """Two runs write the same tables and the same page (the machine's load, which the page
    prints beside the machine, held still: it is the one thing a rerun may change)."""
    from kbcli.cli import record

    monkeypatch.setattr(record.os, "getloadavg", lambda: (1.5, 1.0, 0.5))
    (tmp_path / "timings.txt").write_text(TIMINGS)
    pages, tables = [], []
    for i in range(2):
        out = tmp_path / f"r{i}" / "reproduce.json"
        r = runner.invoke(app, ["bench", "--json", str(out), "verdicts",
                                str(GOLDEN / "evaluation.h5"), "--timings",
                                str(tmp_path / "timings.txt"), *FEW_REPLICATES])
        assert r.exit_code == 0, r.output
        d = json.loads(out.read_text())
        assert d["command"].startswith("kbcli") and d["kbcli_version"] and d["machine"]
        tables.append(d["tables"])
        pages.append(hooks.results_markdown("reproduce", out.parent,
                                            only=("Verdicts", "Wall time", "The paper's claims")))
    assert tables[0] == tables[1]
    assert pages[0] == pages[1]
    titles = [t["title"] for t in tables[0]]
    assert titles == ["What reproduces", "The evaluation", "Verdicts (claims per method)",
                      "The paper's claims, judged", "Judging rules the paper does not state",
                      "Departures from the paper (the judged method `kbcli`)",
                      *titles[6:-2], "Wall time of each stage", "How it ran"]
    # the golden evaluation records its runs' errors, the stopping rules' readings and the
    # truth's place: their tables follow
    assert all(t.startswith(("Final error of every cell", "Runs that ruled out the truth",
                             "Stopping rules")) for t in titles[6:-2]) and titles[6:-2]
    assert "| evaluate | 612.0 |" in pages[0] and "| method | agrees |" in pages[0]
    assert "The evaluation" not in pages[0]


def test_bench_verdicts_on_a_model_quality_sweep(tmp_path, runner):
    out = tmp_path / "model-quality.json"
    r = runner.invoke(app, ["bench", "--json", str(out), "verdicts",
                            str(GOLDEN / "model_quality.h5")])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    sweep, hyp, models, plateau = d["tables"]
    assert hyp["title"].startswith("The paper's explanation") and hyp["rows"][0]["row"] == "infogain"
    art = read_artifact(GOLDEN / "model_quality.h5", ("model_quality",))
    assert len(models["rows"]) == len(art.attrs["models"])
    assert "infogain advantage" in models["columns"] and "nan" not in json.dumps(d["tables"])


def test_bench_verdicts_refuses_bad_input_in_one_line(tmp_path, runner, monkeypatch):
    r = runner.invoke(app, ["bench", "verdicts", str(GOLDEN / "model_quality.h5"),
                            "--own-model", str(GOLDEN / "evaluation.h5")])
    one_line_error(r, "--own-model")
    r = runner.invoke(app, ["bench", "verdicts", str(GOLDEN / "model_quality.h5"),
                            "--ablations", str(GOLDEN / "evaluation.h5")])
    one_line_error(r, "--ablations")
    r = runner.invoke(app, ["bench", "verdicts", str(GOLDEN / "model.h5")])
    one_line_error(r, "model.h5")
    from kbcli.bench import verdicts

    def judged(*_, **__):  # a missing --timings file is refused before any judging
        raise AssertionError("judged the claims before reading --timings")

    monkeypatch.setattr(verdicts, "evaluation_tables", judged)
    r = runner.invoke(app, ["bench", "verdicts", str(GOLDEN / "evaluation.h5"), "--timings",
                            str(tmp_path / "missing.txt"), *FEW_REPLICATES])
    one_line_error(r, "missing.txt")


def test_timed_sh_writes_what_timings_table_reads(tmp_path):
    """benchmarks/timed.sh (make model-quality's stage timer) appends in reproduce.sh's format."""
    import subprocess

    path = tmp_path / "t.txt"
    for name in ("quality", "report"):
        subprocess.run([str(ROOT / "benchmarks" / "timed.sh"), str(path), name, "true"], check=True)
    failed = subprocess.run([str(ROOT / "benchmarks" / "timed.sh"), str(path), "x", "false"])
    assert failed.returncode == 1  # a failing stage fails the recipe and is not timed
    stages, _ = verdicts.timings_table(path.read_text())
    assert [r["stage"] for r in stages.rows] == ["quality", "report"]
    assert all(float(r["wall s"]) >= 0 for r in stages.rows)


def test_a_claim_that_names_other_methods_alone_is_split_by_method():
    """Playing success reads a method's strategies at once ("kbcli: median ..."): cut there too;
    a text naming no known label gives no rows (it crashed the real reproduction's verdicts)."""
    beside = ("paper-v1: median 88.0 % (IQR 86.5 %-89.5 %; vs before p=5.1e-01) [differs]; "
              "kbcli: median 88.0 % [agrees]")
    labels = ("paper-v1 active", "kbcli infogain", "paper-v1", "kbcli")
    parts = verdicts.split_beside(beside, labels)
    assert [(x, v) for x, _, v in parts] == [("paper-v1", "differs"), ("kbcli", "agrees")]
    assert "vs before p=5.1e-01" in parts[0][1]
    assert verdicts.split_beside("nobody: 3 [agrees]", labels) == []


def test_the_evaluation_table_names_the_own_model_evaluation_when_given():
    """The own model's verdicts come from another evaluation: its size and model are named."""
    art = read_artifact(GOLDEN / "evaluation.h5", ("evaluation",))
    plain = {r["what"]: r["value"] for r in verdicts.evaluation_table(art).rows}
    both = {r["what"]: r["value"] for r in verdicts.evaluation_table(art, art).rows}
    assert "with the robot's own model" not in plain
    row = both.pop("with the robot's own model")
    assert both == plain
    n = len(art.data["experiments"]["mode"])
    assert f"{n} experiments, {int(art.config['experiments'])} per displacement" in row
    assert "evaluation.h5" in row and "model " in row


def test_bench_verdicts_keeps_what_explains_each_difference(tmp_path, runner):
    """--ablations adds the report's section "What explains each difference" as a table (here the
    evaluation is its own ladder: its methods in order)."""
    out = tmp_path / "reproduce.json"
    r = runner.invoke(app, ["bench", "--json", str(out), "verdicts", str(GOLDEN / "evaluation.h5"),
                            "--ablations", str(GOLDEN / "evaluation.h5"), *FEW_REPLICATES])
    assert r.exit_code == 0, r.output
    tables = {t["title"].split(" (")[0]: t for t in json.loads(out.read_text())["tables"]}
    table = tables["What explains each difference"]
    assert table["columns"] == list(verdicts.EXPLAIN_COLUMNS)
    art = stage.upgrade(read_artifact(GOLDEN / "evaluation.h5", ("evaluation",)))
    differs = {c.paper for c in stage.claims(art) if c.verdict == "differs"}
    assert {row["claim"] for row in table["rows"]} == differs


def test_plateau_budget_is_the_smallest_within_the_bound_of_the_largest():
    assert verdicts.plateau_budget([100, 400, 800, 1600], [6.9, 1.6, 0.99, 0.87]) == 800
    assert verdicts.plateau_budget([1600, 100, 800], [1.09, 6.8, 1.82]) == 1600  # any order
    assert verdicts.plateau_budget([100, 200], [1.0, 1.0]) == 100  # flat from the start
    assert verdicts.plateau_budget([100, 200], [1.3, 1.0], within=0.3) == 100
    assert verdicts.plateau_budget([100, 200], [1.31, 1.0], within=0.3) == 200


def test_the_sweep_names_the_budget_where_learning_levels_off(tmp_path, runner):
    out = tmp_path / "model-quality.json"
    r = runner.invoke(app, ["bench", "--json", str(out), "verdicts",
                            str(GOLDEN / "model_quality.h5")])
    assert r.exit_code == 0, r.output
    (table,) = [t for t in json.loads(out.read_text())["tables"]
                if t["title"].startswith("Where learning levels off")]
    art = read_artifact(GOLDEN / "model_quality.h5", ("model_quality",))
    explorations = {str(m["exploration"]) for m in art.attrs["models"].values()}
    assert {row["exploration"] for row in table["rows"]} == explorations
    for row in table["rows"]:
        mine = {int(m["budget"]): m["boundary_error"] for m in art.attrs["models"].values()
                if str(m["exploration"]) == row["exploration"]}
        assert int(row["budget"]) == verdicts.plateau_budget(list(mine), list(mine.values()))


def test_bench_verdicts_judges_each_difference_on_a_rung_of_the_inputs(tmp_path, runner):
    """--rung adds "What the evaluation's inputs change": every claim that differs, judged on the
    rung (here the evaluation itself: nothing changes, and every verdict stays *differs*)."""
    out = tmp_path / "reproduce.json"
    golden = str(GOLDEN / "evaluation.h5")
    r = runner.invoke(app, ["bench", "--json", str(out), "verdicts", golden, "--rung", golden,
                            *FEW_REPLICATES])
    assert r.exit_code == 0, r.output
    tables = {t["title"].split(" (")[0]: t for t in json.loads(out.read_text())["tables"]}
    table = tables["What the evaluation's inputs change"]
    art = stage.upgrade(read_artifact(GOLDEN / "evaluation.h5", ("evaluation",)))
    differs = {c.paper for c in stage.claims(art) if c.verdict == "differs" and c.mode}
    assert {row["claim"] for row in table["rows"]} == differs
    assert {row["verdict"] for row in table["rows"]} == {"differs"}
    assert {row["what the rung changes"] for row in table["rows"]} == \
        {"nothing in its recorded inputs"}
    bad = runner.invoke(app, ["bench", "verdicts", golden, "--rung", str(tmp_path / "no.h5")])
    one_line_error(bad, "no.h5")
