"""The report: claims judged against known p-values, README tables, figures, bad input (issue 6)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_evaluate import FAKE, small_config

from kbcli.cli import app
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import evaluate as evaluate_stage
from kbcli.stages import report as stage
from kbcli.stages.artifact import Artifact
from kbcli.stages.models import exact_artifact
from kbcli.stages.report.ablation import explained

#: Observations to each threshold (10 runs x 3 thresholds) per category, (active, random): the
#: advantage A = P(active needs fewer) is 1 on small, about 0.8 on medium, 0.5 on large.
SHRINKING = {"small": (np.ones((10, 3)), np.full((10, 3), 6.0)),
             "medium": (np.tile([1.0, 2, 3, 4, 5], (3, 2)).T, np.tile([3.0, 4, 5, 6, 6], (3, 2)).T),
             "large": (np.tile([2.0, 3, 4, 5, 6], (3, 2)).T, np.tile([2.0, 3, 4, 5, 6], (3, 2)).T)}


def _evaluation(pvalues: dict, stats_sign: float = -1.0, reached: float = 1.0,
                play: float = 1.0, modes=("ideal",), min_p: float = 1e-30,
                before: float = 0.99, entropy_active=None, counts=None) -> Artifact:
    """A hand-made evaluation artifact: methods ``paper`` (judged) and ``kbcli`` with random and
    active; thresholds 10, 8, 4 px; ``paper``'s p-values per category as given, ``kbcli``'s all
    1e-9; playing success after adaptation ``play``, before ``before``; per-run observations to
    each threshold ``counts`` (category -> (active, random); default :data:`SHRINKING`)."""
    counts = SHRINKING if counts is None else counts
    thr = np.array([10.0, 8.0, 4.0])
    cats = ["small", "medium", "large"]
    strategies = ["random", "active"]
    methods = ["paper", "kbcli"]
    T = 5
    curve = {"rmse": np.linspace(10, 1, T), "q25": np.ones(T), "q75": np.ones(T) * 3,
             "median_samples": np.array([1.0, 2.0, 3.0]), "reached": np.full(3, reached)}
    rows = [(m, x, c, s) for m in modes for c in cats for x in methods for s in strategies]
    n = len(rows)
    exp = {
        "mode": np.array([r[0] for r in rows]), "method": np.array([r[1] for r in rows]),
        "category": np.array([r[2] for r in rows]), "strategy": np.array([r[3] for r in rows]),
        "play_adapted": np.full(n, play), "play_unadapted": np.full(n, 0.5),
        "play_before": np.full(n, before), "params": np.zeros((n, 2)),
    }

    def pv(x, c):
        p = pvalues[c] if x == "paper" else [1e-9] * 3
        return {"active": {"pvalue": np.asarray(p, float), "statistic": np.full(3, stats_sign),
                           "min_pvalue": np.float64(min_p)}}

    ent_active = np.arange(T, 0, -1.0) - 0.5 if entropy_active is None else entropy_active
    data = {
        "thresholds": thr,
        "experiments": exp,
        "curves": {m: {x: {c: {s: {**curve, "samples_to_threshold": counts[c][i]}
                               for i, s in enumerate(("active", "random"))} for c in cats}
                       for x in methods} for m in modes},
        "pvalues": {m: {x: {c: pv(x, c) for c in cats} for x in methods} for m in modes},
        "entropy": {m: {x: {"random": {"mean": np.arange(T, 0, -1.0), "q25": np.zeros(T),
                                       "q75": np.ones(T)},
                            "active": {"mean": np.asarray(ent_active, float), "q25": np.zeros(T),
                                       "q75": np.ones(T)}} for x in methods} for m in modes},
        "examples": {m: {} for m in modes},
    }
    cfg = {"experiments": 1, "example": "small", "family": "translation",
           "categories": {c: {"limit": lim, "displacements": [[1.0, 1.0]]}
                          for c, lim in zip(cats, (10.0, 20.0, 40.0), strict=True)}}
    opts = {"paper": {"posterior": "kde", "estimator": "ml"},
            "kbcli": {"posterior": "likelihood", "estimator": "mean"}}
    attrs = {"modes": list(modes), "categories": cats, "strategies": strategies,
             "baseline": "random", "max_steps": T, "model_strategy": "exact", "judged": "paper",
             "method_order": methods,
             "play_notes": 200, "melody": "A:1",
             "methods": {x: {"strategies": strategies, "description": f"{x} method",
                             "modes": list(modes), "categories": cats,
                             "options": {m: {s: {"robot": {**opts[x], "strategy": s},
                                                 "mode": m, "feedback": "landed"}
                                             for s in strategies} for m in modes}}
                         for x in methods}}
    return Artifact(kind="evaluation", config=cfg, seed=1, data=data, attrs=attrs)


PAPER_LIKE = {"small": [1e-7, 1e-6, 1e-6], "medium": [0.5, 1e-4, 1e-4], "large": [0.3, 0.2, 0.9]}


def _key(claim) -> str:
    if claim.paper.startswith("the advantage shrinks"):
        return "trend"
    if claim.source.startswith("Sect. IV-B"):
        return claim.paper.split(" ")[0]  # small, medium, large
    if claim.source.startswith("Sect. IV-A"):
        return "entropy"
    return "restores" if "restores" in claim.paper else "dynamics_ns"


def _verdicts(art):
    return {_key(c): c.verdict for c in stage.claims(art)}


def test_claims_agree_with_paper_like_numbers():
    v = _verdicts(_evaluation(PAPER_LIKE))
    # medium: p at 10 px is 0.5 but the claim is only "up to 8 px"
    assert v == {"entropy": "agrees", "small": "agrees", "medium": "agrees", "large": "agrees",
                 "trend": "agrees", "restores": "not measured", "dynamics_ns": "not measured"}
    # every claim row names the method it judged and its options
    for c in stage.claims(_evaluation(PAPER_LIKE)):
        assert c.method == "paper"
        if c.verdict != "not measured":
            assert "posterior kde" in c.options and "estimator ml" in c.options


def test_claims_differ_when_measurements_do():
    v = _verdicts(_evaluation({"small": [1e-7, 1e-3, 1e-6], "medium": PAPER_LIKE["medium"],
                               "large": [1e-4, 0.2, 0.9]}))
    assert v["small"] == "differs" and v["large"] == "differs" and v["medium"] == "agrees"
    # significant but in the baseline's favour is not the paper's claim
    assert _verdicts(_evaluation(PAPER_LIKE, stats_sign=1.0))["small"] == "differs"
    # active's entropy above random's at some step: Fig. 6's claim differs
    flat = np.full(5, 10.0)
    assert _verdicts(_evaluation(PAPER_LIKE, entropy_active=flat))["entropy"] == "differs"


def test_underpowered_rather_than_differs():
    """With too few runs to reach the paper's bound at all, a miss is 'underpowered'."""
    weak = {"small": [1e-3, 1e-3, 1e-3], "medium": [0.02] * 3, "large": [0.3, 0.2, 0.9]}
    v = _verdicts(_evaluation(weak, min_p=1e-4))  # 1e-5 not attainable, 1e-3 attainable
    assert v["small"] == "underpowered" and v["medium"] == "differs"
    v = _verdicts(_evaluation(weak, min_p=2 / 924))  # 6 + 6 runs: no p below 2.2e-3
    assert v["small"] == "underpowered" and v["medium"] == "underpowered"
    assert _verdicts(_evaluation(weak, min_p=0.02))["large"] == "underpowered"
    assert _verdicts(_evaluation(weak))["small"] == "differs"  # enough runs: a real difference
    text = stage.build(_evaluation(weak, min_p=2 / 924)).readme
    assert "the smallest exact p-value of these sample sizes is 2.2e-03" in text


def test_uninformative_thresholds_are_not_counted():
    art = _evaluation(PAPER_LIKE, reached=0.2)
    cl = {_key(c): c for c in stage.claims(art)}
    assert cl["small"].verdict == "not measured" and "uninformative" in cl["small"].measured


def test_dynamics_claims_compare_with_the_measured_before():
    both = ("ideal", "dynamics")
    v = _verdicts(_evaluation(PAPER_LIKE, modes=both, play=0.99))
    assert v["restores"] == "agrees"
    assert v["dynamics_ns"] == "differs"  # PAPER_LIKE is significant in small and medium
    assert _verdicts(_evaluation(PAPER_LIKE, modes=both, play=0.6))["restores"] == "differs"
    # the same 90 % after adaptation restores an arm that played 91 % before, not one at 99 %
    assert _verdicts(_evaluation(PAPER_LIKE, modes=both, play=0.9, before=0.91))["restores"] == \
        "agrees"
    assert _verdicts(_evaluation(PAPER_LIKE, modes=both, play=0.9, before=0.99))["restores"] == \
        "differs"
    calm = {c: [0.3, 0.2, 0.9] for c in PAPER_LIKE}
    assert _verdicts(_evaluation(calm, modes=both))["dynamics_ns"] == "agrees"
    restores = next(c for c in stage.claims(_evaluation(PAPER_LIKE, modes=both, play=0.97,
                                                         before=0.985)) if _key(c) == "restores")
    assert "before the displacement 98.5 %" in restores.measured and "97.0 %" in restores.measured
    assert "100 %" not in restores.measured


def test_readme_has_every_table_and_claim():
    rep = stage.build(_evaluation(PAPER_LIKE, modes=("ideal", "dynamics")))
    text = rep.readme
    for heading in ("The paper's claims", "Observations to reach each error threshold (ideal mode)",
                    "Mann-Whitney U p-values against random (dynamics mode)",
                    "RMSE (px) after t observations", "Playing success",
                    "Methods: every option that applies",
                    "Large displacements: representation, estimator or strategy?"):
        assert heading in text
    assert "p < 1e-05 at 10 px (p=1.0e-07)" in text
    claims = text.split("## The paper's claims against")[1].split("### What each verdict")[0]
    assert claims.count("| Sect. IV-") == 7
    reproduces = text.split("## What reproduces")[1].split("## The paper's claims")[0]
    assert reproduces.count("| Sect. IV-") == 7
    # the other method beside the judged one, and the options that differ in bold
    assert "kbcli active:" in text and "| **posterior** | kde | likelihood |" in text
    assert [f.name for f in rep.figures] == ["fig6_entropy.png", "fig7_error_ideal.png",
                                             "fig7_error_dynamics.png"]  # no snapshots: no Fig. 5


def test_schema_1_artifacts_are_still_read():
    """An evaluation written before named methods: one method, its derived play numbers dropped."""
    thr = np.array([10.0, 4.0])
    cats, strategies, T = ["small"], ["random", "active"], 3
    cnt = np.array([[1, 2], [2, 3]])
    curve = {"rmse": np.ones(T), "q25": np.ones(T), "q75": np.ones(T),
             "median_samples": np.array([1.0, 2.0]), "reached": np.ones(2),
             "samples_to_threshold": cnt}
    art = Artifact(
        kind="evaluation", schema_version=1, seed=1,
        config={"experiments": 1, "example": "small", "adapt": {},
                "categories": {"small": {"limit": 10.0, "displacements": [[1.0, 1.0]]}}},
        data={"thresholds": thr,
              "experiments": {"mode": np.array(["ideal"] * 2), "category": np.array(["small"] * 2),
                              "strategy": np.array(strategies), "params": np.zeros((2, 2)),
                              "play_adapted": np.ones(2), "play_unadapted": np.ones(2)},
              "curves": {"ideal": {"small": {s: dict(curve) for s in strategies}}},
              "pvalues": {"ideal": {"small": {"active": {"pvalue": np.array([0.3, 0.3]),
                                                          "statistic": np.array([-1.0, -1.0])}}}},
              "entropy": {"ideal": {s: {"mean": np.ones(T), "q25": np.ones(T), "q75": np.ones(T)}
                                    for s in strategies}},
              "examples": {"ideal": {}}},
        attrs={"modes": ["ideal"], "categories": cats, "strategies": strategies,
               "baseline": "random", "max_steps": T, "model_strategy": "exact"})
    rep = stage.build(art)
    assert "schema-1 artifact" in rep.readme and "`kbcli`" in rep.readme
    # 2 runs against 2: no p below 2 / C(4, 2) = 0.33 is attainable
    up = stage.upgrade(art)
    assert up.data["pvalues"]["ideal"]["kbcli"]["small"]["active"]["min_pvalue"] == \
        pytest.approx(1 / 3)
    assert np.isnan(up.data["experiments"]["play_adapted"]).all()  # derived, not measured


def test_report_cli_from_an_evaluation(runner, tmp_path, monkeypatch):
    from kbcli.core.instrument.keyboard import KeyboardConfig
    from kbcli.stages import keyboard as keyboard_stage

    cfg = small_config(modes=["ideal", "dynamics"])
    art = evaluate_stage.run(cfg, exact_artifact(keyboard_stage.run(KeyboardConfig())), FAKE)
    write_artifact(art, tmp_path / "eval.h5")
    r = runner.invoke(app, ["report", str(tmp_path / "eval.h5"), "-o", str(tmp_path / "rep")])
    assert r.exit_code == 0, r.output
    names = sorted(p.name for p in (tmp_path / "rep").iterdir())
    assert names == ["README.md", "fig5_posterior.png", "fig6_entropy.png",
                     "fig7_error_dynamics.png", "fig7_error_ideal.png"]
    for n in names[1:]:
        assert (tmp_path / "rep" / n).read_bytes()[:4] == b"\x89PNG"
    readme = (tmp_path / "rep" / "README.md").read_text()
    assert "![Fig. 5: evolution of the posterior](fig5_posterior.png)" in readme
    assert any(f"[{v}]" in r.output for v in stage.VERDICTS)


@pytest.mark.parametrize("case", ["wrong kind", "missing", "output is a file"])
def test_report_cli_bad_input(runner, tmp_path, kb_path, case):
    out = tmp_path / "rep"
    src = tmp_path / "nope.h5" if case == "missing" else kb_path
    if case == "output is a file":
        src = tmp_path / "eval.h5"
        write_artifact(_evaluation(PAPER_LIKE), src)
        out.write_text("x")
    r = runner.invoke(app, ["report", str(src), "-o", str(out)])
    assert r.exit_code == 1
    lines = [ln for ln in r.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), r.output
    assert case == "output is a file" or not out.exists()


def test_report_reads_back_written_artifact(tmp_path):
    path = tmp_path / "e.h5"
    write_artifact(_evaluation(PAPER_LIKE), path)
    rep = stage.build(read_artifact(path, "evaluation"))
    assert "sha256" in rep.readme and rep.claims[0].verdict == "agrees"
    assert "| option | `paper` | `kbcli` |" in rep.readme  # the config's order survives HDF5
    assert [c.verdict for c in rep.claims] == [c.verdict for c in stage.claims(_evaluation(PAPER_LIKE))]


def test_point_labels_never_overlap():
    """place_labels: five labels on a crowded spot take different places or are left out; no two
    drawn labels overlap."""
    import matplotlib.pyplot as plt

    from kbcli.viz.common import place_labels

    fig, ax = plt.subplots(figsize=(4, 3))
    xy = np.array([[1.0, 0.0], [1.02, 0.0], [1.04, 0.01], [2.0, 5.0], [1.01, 0.02]])
    ax.scatter(*xy.T)
    ax.set_xlim(0, 3)
    ax.set_ylim(-1, 6)
    skipped = place_labels(ax, xy, ["100", "150", "200", "800", "1600"])
    boxes = [t.get_window_extent() for t in ax.texts]
    assert len(boxes) == 5 - skipped >= 4
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b)
    plt.close(fig)
    fig, ax = plt.subplots()  # a point that is not finite loses its label, not the others theirs
    ax.set_xlim(0, 6)
    ax.set_ylim(0, 6)
    assert place_labels(ax, np.array([[1.0, 1.0], [5.0, 5.0], [np.nan, 3.0]]), list("abc")) == 1
    assert [t.get_text() for t in ax.texts] == ["a", "b"]
    plt.close(fig)


def test_medium_is_judged_whole_and_the_trend_on_effect_sizes():
    """Medium agrees only when its advantage is also smaller than on small displacements; the
    trend row agrees only when the advantage falls small -> medium -> large (known counts)."""
    same = {c: SHRINKING["small"] for c in SHRINKING}  # A = 1 everywhere: nothing shrinks
    v = _verdicts(_evaluation(PAPER_LIKE, counts=same))
    assert v["medium"] == "differs" and v["trend"] == "differs" and v["small"] == "agrees"
    medium = next(c for c in stage.claims(_evaluation(PAPER_LIKE, counts=same))
                  if _key(c) == "medium")
    assert "significant: p < 0.001" in medium.measured and "[agrees]" in medium.measured
    assert "1.00 -> 1.00" in medium.measured and medium.measured.endswith("[differs]")
    inverted = {"small": SHRINKING["large"], "medium": SHRINKING["medium"],
                "large": SHRINKING["small"]}  # the advantage grows with the displacement
    assert _verdicts(_evaluation(PAPER_LIKE, counts=inverted))["trend"] == "differs"
    trend = next(c for c in stage.claims(_evaluation(PAPER_LIKE)) if _key(c) == "trend")
    assert "1.00 -> 0.82 -> 0.50" in trend.measured and trend.verdict == "agrees"


def test_an_ml_verdict_is_shown_with_the_posterior_mean_too():
    """The judged method estimates by the ML cell: each verdict that reads an estimate also gives
    the posterior mean's reading of the same runs, and says when the two disagree."""
    art = _evaluation(PAPER_LIKE)
    for x in ("paper", "kbcli"):
        for c in art.data["curves"]["ideal"][x].values():
            for cur in c.values():
                cur["reached_mean"] = cur["reached"]
        for c in art.data["pvalues"]["ideal"][x].values():
            c["active"]["pvalue_mean"] = np.full(3, 0.5)
            c["active"]["statistic_mean"] = np.full(3, -0.1)
    small = next(c for c in stage.claims(art) if _key(c) == "small")
    assert small.verdict == "agrees"
    assert "the posterior mean of the same runs: not at 10 px (p=5.0e-01)" in small.measured
    assert "[differs] (this verdict differs from the ML estimate's" in small.measured


PAPER_TEXT = Path(__file__).resolve().parents[1] / ".." / "shared" / "paper" / \
    "where-is-my-keyboard.md"


def test_departures_quote_the_paper_and_follow_the_options():
    from kbcli.stages.report.departures import DEPARTURES, departures

    if PAPER_TEXT.exists():  # the paper sits beside the clone in the project's workspace
        paper = PAPER_TEXT.read_text(encoding="utf-8")
        for d in DEPARTURES:
            assert d.quote in paper, d.quote
    art = _evaluation(PAPER_LIKE)
    rows = {d.quote: does for d, does in departures(art)}
    assert len(rows) == len(DEPARTURES)  # every rule listed, whatever the options
    assert any("ties go to the lowest grid index" in v for v in rows.values())
    assert any("not set for this method: every run takes 5 observations" in v
               for v in rows.values())
    # a method that sets the paper's stopping rule and a floorless KDE: the rows say what it does
    for by_s in art.attrs["methods"]["paper"]["options"].values():
        for d in by_s.values():
            d["robot"].update(stop_ml=0.9, kde_floor=0.0)
    rows = {d.quote: does for d, does in departures(art)}
    assert len(rows) == len(DEPARTURES)
    assert any(v.startswith("stop_ml = 0.9 (the paper gives no number)") for v in rows.values())
    assert any(v.startswith("no floor (Eq. 7 as written)") for v in rows.values())
    text = stage.build(_evaluation(PAPER_LIKE)).readme
    assert "## Departures from the paper" in text
    assert '| Sect. IV-A | "a baseline strategy, consisting in the random selection of samples" |' \
        in text



def _ladder(rungs, mode: str = "ideal") -> Artifact:
    """A synthetic ablation ladder in one mode: rungs ``(name, robot options, small p-values)``
    built on :func:`_evaluation` (every other claim as PAPER_LIKE)."""
    import copy

    art = _evaluation(PAPER_LIKE, modes=(mode,))
    base = art.attrs["methods"]["paper"]
    methods, order = {}, []
    for tree in ("curves", "pvalues", "entropy"):
        paper = art.data[tree][mode]["paper"]
        art.data[tree][mode] = {}
        for name, _, small in rungs:
            t = copy.deepcopy(paper)
            if tree == "pvalues":
                t["small"]["active"]["pvalue"] = np.asarray(small, float)
            art.data[tree][mode][name] = t
    for name, opts, _ in rungs:
        m = copy.deepcopy(base)
        for by_s in m["options"].values():
            for s, d in by_s.items():
                d["robot"] = {**opts, "strategy": s}
        methods[name] = m
        order.append(name)
    art.attrs.update(methods=methods, method_order=order, judged=order[0])
    return art


def test_what_explains_each_difference_on_a_known_ladder():
    """The small claim differs with the KDE and agrees once the posterior is the likelihood: the
    section names the posterior (and only it) as what flips it, computed from the options."""
    bad, good = [1e-7, 1e-3, 1e-6], [1e-9] * 3
    kde = {"posterior": "kde", "estimator": "ml", "model_blur": 0.0}
    rungs = [("paper", kde, bad), ("r-estimator", {**kde, "estimator": "mean"}, bad),
             ("r-posterior", {**kde, "estimator": "mean", "posterior": "likelihood"}, good),
             ("kbcli", {"posterior": "likelihood", "estimator": "mean"}, good)]
    main = _evaluation({**PAPER_LIKE, "small": bad})
    rep = stage.build(main, ablations=_ladder(rungs))
    section = rep.readme.split("## What explains each difference")[1].split("\n## ")[0]
    row = next(r for r in section.splitlines() if r.startswith("| small displacements"))
    assert "`paper` (active) differs -> `r-estimator` (active) differs -> `r-posterior` " \
        "(active) agrees -> `kbcli` (active) agrees" in row
    assert "`r-estimator` -> `r-posterior` (differs -> agrees): posterior kde -> likelihood |" \
        in row
    # a difference no rung removes is said to be explained by none of the factors
    rungs = [(n, o, bad) for n, o, _ in rungs]
    rep = stage.build(main, ablations=_ladder(rungs))
    assert "no rung flips it: it differs on every rung" in rep.readme
    assert "What explains each difference" not in stage.build(main).readme


def test_a_ladder_run_one_mode_at_a_time_explains_the_claims_of_both_modes():
    """Two ladder evaluations, ideal and dynamics (make reproduce-ablations MODE=...): the small
    claim is explained by the ideal ladder (the posterior flips it), the dynamics claim by the
    dynamics ladder (the estimator flips it); with the ideal ladder alone, the dynamics claim is
    not measured."""
    bad, good, flat = [1e-7, 1e-3, 1e-6], [1e-9] * 3, [0.5] * 3
    kde = {"posterior": "kde", "estimator": "ml", "model_blur": 0.0}
    ideal = _ladder([("paper", kde, bad), ("r-posterior", {**kde, "posterior": "likelihood"}, good)])
    dyn = _ladder([("paper", kde, bad), ("r-estimator", {**kde, "estimator": "mean"}, flat)],
                  mode="dynamics")
    for c in ("medium", "large"):  # the dynamics claim is judged on every category
        dyn.data["pvalues"]["dynamics"]["r-estimator"][c]["active"]["pvalue"] = np.asarray(flat)
    ideal.path, dyn.path = "abl-ideal.h5", "abl-dynamics.h5"
    main = _evaluation({**PAPER_LIKE, "small": bad}, modes=("ideal", "dynamics"))
    rows = {c: (path, flips) for c, path, flips in explained(stage.claims(main), [ideal, dyn])}
    small = next(v for c, v in rows.items() if c.startswith("small displacements"))
    robot = next(v for c, v in rows.items() if c.startswith("with robot dynamics"))
    assert small[0].startswith("abl-ideal.h5: ") and small[1].endswith("posterior kde -> likelihood")
    assert robot[0].startswith("abl-dynamics.h5: ") and robot[1].endswith("estimator ml -> mean")
    alone = {c: p for c, p, _ in explained(stage.claims(main), ideal)}
    assert next(p for c, p in alone.items() if c.startswith("with robot dynamics")) == \
        "not measured by the ladder"
    readme = stage.build(main, ablations=[ideal, dyn]).readme
    assert "`abl-ideal.h5` and `abl-dynamics.h5`" in readme


def test_the_explanation_as_a_result_table_has_the_sections_rows():
    """kbcli bench verdicts --ablations keeps the section as a result table: the same rows."""
    from kbcli.bench.verdicts import EXPLAIN_COLUMNS, explain_table

    bad, good = [1e-7, 1e-3, 1e-6], [1e-9] * 3
    kde = {"posterior": "kde", "estimator": "ml", "model_blur": 0.0}
    rungs = [("paper", kde, bad), ("r-posterior", {**kde, "posterior": "likelihood"}, good)]
    main = _evaluation({**PAPER_LIKE, "small": bad})
    ladder = _ladder(rungs)
    readme = stage.build(main, ablations=ladder).readme
    table = explain_table(stage.claims(main), ladder)
    assert table.columns == EXPLAIN_COLUMNS and table.rows
    for row in table.rows:
        assert f"| {row['claim']} | {row['verdict along the ladder']} | {row['what flips it']} |" \
            in readme
    small = next(r for r in table.rows if r["claim"].startswith("small displacements"))
    assert small["what flips it"].endswith("posterior kde -> likelihood")
    assert table.title.startswith("What explains each difference")


def test_dynamics_claims_on_the_robots_own_model_beside_the_default():
    both = ("ideal", "dynamics")
    main = _evaluation(PAPER_LIKE, modes=both, play=0.99)
    own = _evaluation({c: [0.3, 0.2, 0.9] for c in PAPER_LIKE}, modes=("dynamics",), play=0.6)
    own.inputs["model"] = {"file": "own-model.h5", "sha256": "ab" * 32}
    cl = stage.claims(main, own)
    rows = [c for c in cl if c.source.startswith("Sect. IV-C")]
    assert [c.source for c in rows] == ["Sect. IV-C"] * 2 + ["Sect. IV-C, the robot's own model"] * 2
    assert [c.verdict for c in rows] == ["agrees", "differs", "differs", "agrees"]
    assert all("own-model.h5" in c.measured for c in rows[2:])
    assert "Sect. IV-C, the robot's own model" in stage.build(main, own=own).readme


def test_methods_table_marks_options_that_do_not_apply():
    art = _evaluation(PAPER_LIKE)
    for x, extra in (("paper", {"robust": True, "kde_samples": 10000, "robust_eta": None}),
                     ("kbcli", {"robust": True, "kde_samples": 10000, "robust_eta": None})):
        for by_s in art.attrs["methods"][x]["options"].values():
            for d in by_s.values():
                d["robot"].update(extra)
    text = stage.build(art).readme
    assert "| **robust** | n/a | True |" in text
    assert "| **kde_samples** | 10000 | n/a |" in text
    assert "| **robust_eta** | n/a | None |" in text


def test_methods_table_of_kde_methods_lists_no_likelihood_only_option():
    art = _evaluation(PAPER_LIKE)
    for x in ("paper", "kbcli"):  # both read with the KDE: no method reads the robust options
        art.attrs["methods"][x]["from_model"] = {"redundancy_radius": 0.0, "robust_blurs": [],
                                                 "robust_eta": 1.0}
        for by_s in art.attrs["methods"][x]["options"].values():
            for s, d in by_s.items():
                d["robot"] = AdapterConfig(posterior="kde", estimator="ml", kde_floor=0.0,
                                           strategy=s).to_dict()
    table = "\n".join(stage.tables.methods_table(art))
    for k in ("robust", "robust_blurs", "robust_outliers", "robust_eta", "redundancy_radius",
              "cell_average", "hypotheses", "stop_angle", "max_angle"):
        assert f"| {k} " not in table and f"| {k}," not in table and f"**{k}**" not in table, k
    for k in ("kde_samples", "kde_floor", "kde_draw", "ml_ties", "candidates", "active_keep"):
        assert f"| {k} |" in table, k
    assert "n/a" not in table  # every row applies to both
    # every option of the chosen parts stays recorded in the artifact
    assert "kde_bandwidth" in art.attrs["methods"]["paper"]["options"]["ideal"]["active"]["robot"][
        "posterior"]


@pytest.mark.parametrize("robot,expected", [
    ({"posterior": "kde", "kde_floor": None, "outlier": 0.002}, "eps = 0.002"),  # None: the outlier
    ({"posterior": "kde", "kde_floor": None}, "eps = 0.001"),
    ({"posterior": "kde", "kde_floor": 0.05}, "eps = 0.05"),
    ({"posterior": "kde", "kde_floor": 0.0}, "no floor (Eq. 7 as written)"),
    ({"posterior": "likelihood", "kde_floor": None}, "not a KDE posterior (likelihood)"),
])
def test_the_floor_departure_reads_a_recorded_none_as_the_outlier_rate(robot, expected):
    """A method recorded with kde_floor = None (the paper-v1 reading) names the floor it used;
    the row is there whatever the options (issue 39: every rule listed)."""
    from kbcli.stages.report.departures import _no_kde, by_parts

    assert expected in by_parts("floor", _no_kde)(robot, None)


def test_a_rung_on_the_inputs_says_which_input_flips_a_claim():
    """The small claim differs on the main evaluation; on a rung with 3 px of reach noise it
    agrees, on a rung with another model it still differs: the section names what each rung
    changes (computed from the artifacts), and "What reproduces" names the rung that flips it."""
    from kbcli.stages.report import inputs

    bad, good = [1e-7, 1e-3, 1e-6], [1e-9] * 3
    main = _evaluation({**PAPER_LIKE, "small": bad})
    main.inputs = {"model": {"file": "model.h5", "sha256": "a" * 64}}
    noisy = _evaluation({**PAPER_LIKE, "small": good})
    noisy.inputs, noisy.path = dict(main.inputs), "noise.h5"
    noisy.config["reach_noise"] = {"ideal": 3.0}
    other = _evaluation({**PAPER_LIKE, "small": bad})
    other.inputs, other.path = {"model": {"file": "own.h5", "sha256": "b" * 64}}, "own.h5"
    claims = stage.claims(main)
    rows = inputs.judged(claims, main, [noisy, other], replicates=0)
    small = {r.rung: r for r in rows if r.claim.startswith("small displacements")}
    assert small["noise.h5"].verdict == "agrees" and small["noise.h5"].flips
    assert small["noise.h5"].changes == "reach noise (ideal) 0 px -> 3 px"
    assert small["own.h5"].verdict == "differs" and not small["own.h5"].flips
    assert small["own.h5"].changes.startswith("model model.h5 (sha256 aaaa")
    # only claims that differ on the main evaluation are judged on the rungs
    assert {r.claim for r in rows} == {c.paper for c in claims if c.verdict == "differs"}
    text = stage.build(main, rungs=[noisy, other], replicates=0).readme
    assert "## What the evaluation's inputs change" in text
    reproduces = text.split("## What reproduces")[1].split("\n## ")[0]
    row = next(r for r in reproduces.splitlines() if "small displacements" in r)
    assert "it agrees on an input rung: reach noise (ideal) 0 px -> 3 px: agrees (noise.h5)" in row
    assert "What the evaluation's inputs change" not in stage.build(main, replicates=0).readme


def test_a_rung_flips_a_claim_at_the_papers_sample_size_not_by_its_own_lower_power():
    """A rung run with fewer experiments may agree where its replicates at the paper's 50 runs do
    not: that is the smaller sample's power, not a flip."""
    from kbcli.stages.report.inputs import InputRung
    from kbcli.stages.report.power import Replication

    weak = InputRung("large", "noise.h5", "reach noise (ideal) 0 px -> 3 px", 10, "agrees",
                     Replication(agree=3, replicates=100, runs=50))
    assert not weak.flips
    assert weak.said() == ("reach noise (ideal) 0 px -> 3 px: agrees at 10 runs per cell, 3 of "
                           "100 replicates agree at the paper's 50")
    strong = InputRung("large", "noise.h5", "x", 10, "differs",
                       Replication(agree=80, replicates=100, runs=50))
    assert strong.flips
    assert InputRung("large", "noise.h5", "x", 10, "agrees", None).flips
