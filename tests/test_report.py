"""The report: claims judged against known p-values, README tables, figures, bad input (issue 6)."""

from __future__ import annotations

import numpy as np
import pytest
from test_evaluate import FAKE, small_config

from kbcli.cli import app
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import evaluate as evaluate_stage
from kbcli.stages import report as stage
from kbcli.stages.artifact import Artifact
from kbcli.stages.models import exact_artifact


def _evaluation(pvalues: dict, stats_sign: float = -1.0, reached: float = 1.0,
                play: float = 1.0, modes=("ideal",)) -> Artifact:
    """A hand-made evaluation artifact: thresholds 10, 8, 4 px; p-values per category given."""
    thr = np.array([10.0, 8.0, 4.0])
    cats = ["small", "medium", "large"]
    strategies = ["random", "active"]
    T = 5
    curve = {"rmse": np.linspace(10, 1, T), "q25": np.ones(T), "q75": np.ones(T) * 3,
             "median_samples": np.array([1.0, 2.0, 3.0]), "reached": np.full(3, reached)}
    n = len(modes) * len(cats) * 2
    exp = {
        "mode": np.repeat(np.array(modes), len(cats) * 2),
        "category": np.tile(np.repeat(np.array(cats), 2), len(modes)),
        "strategy": np.tile(np.array(strategies), len(modes) * len(cats)),
        "play_adapted": np.full(n, play), "play_unadapted": np.full(n, 0.5),
        "params": np.zeros((n, 2)),
    }
    data = {
        "thresholds": thr,
        "experiments": exp,
        "curves": {m: {c: {s: dict(curve) for s in strategies} for c in cats} for m in modes},
        "pvalues": {m: {c: {"active": {"pvalue": np.asarray(pvalues[c], float),
                                       "statistic": np.full(3, stats_sign)}} for c in cats}
                    for m in modes},
        "entropy": {m: {s: {"mean": np.arange(T, 0, -1.0), "q25": np.zeros(T), "q75": np.ones(T)}
                        for s in strategies} for m in modes},
        "examples": {m: {} for m in modes},
    }
    cfg = {"experiments": 1, "example": "small", "family": "translation",
           "categories": {c: {"limit": lim, "displacements": [[1.0, 1.0]]}
                          for c, lim in zip(cats, (10.0, 20.0, 40.0), strict=True)}}
    attrs = {"modes": list(modes), "categories": cats, "strategies": strategies,
             "baseline": "random", "max_steps": T, "model_strategy": "exact"}
    return Artifact(kind="evaluation", config=cfg, seed=1, data=data, attrs=attrs)


PAPER_LIKE = {"small": [1e-7, 1e-6, 1e-6], "medium": [0.5, 1e-4, 1e-4], "large": [0.3, 0.2, 0.9]}


def _key(claim) -> str:
    if claim.source.startswith("Sect. IV-B"):
        return claim.paper.split(" ")[0]  # small, medium, large
    return "restores" if "restores" in claim.paper else "dynamics_ns"


def _verdicts(art):
    return {_key(c): c.verdict for c in stage.claims(art)}


def test_claims_agree_with_paper_like_numbers():
    v = _verdicts(_evaluation(PAPER_LIKE))
    # medium: p at 10 px is 0.5 but the claim is only "up to 8 px"
    assert v == {"small": "agrees", "medium": "agrees", "large": "agrees",
                 "restores": "not measured", "dynamics_ns": "not measured"}


def test_claims_differ_when_measurements_do():
    v = _verdicts(_evaluation({"small": [1e-7, 1e-3, 1e-6], "medium": PAPER_LIKE["medium"],
                               "large": [1e-4, 0.2, 0.9]}))
    assert v["small"] == "differs" and v["large"] == "differs" and v["medium"] == "agrees"
    # significant but in the baseline's favour is not the paper's claim
    assert _verdicts(_evaluation(PAPER_LIKE, stats_sign=1.0))["small"] == "differs"


def test_uninformative_thresholds_are_not_counted():
    art = _evaluation(PAPER_LIKE, reached=0.2)
    cl = {_key(c): c for c in stage.claims(art)}
    assert cl["small"].verdict == "not measured" and "uninformative" in cl["small"].measured


def test_dynamics_claim():
    both = ("ideal", "dynamics")
    v = _verdicts(_evaluation(PAPER_LIKE, modes=both, play=0.99))
    assert v["restores"] == "agrees"
    assert v["dynamics_ns"] == "differs"  # PAPER_LIKE is significant in small and medium
    assert _verdicts(_evaluation(PAPER_LIKE, modes=both, play=0.6))["restores"] == "differs"
    calm = {c: [0.3, 0.2, 0.9] for c in PAPER_LIKE}
    assert _verdicts(_evaluation(calm, modes=both))["dynamics_ns"] == "agrees"


def test_readme_has_every_table_and_claim():
    rep = stage.build(_evaluation(PAPER_LIKE, modes=("ideal", "dynamics")))
    text = rep.readme
    for heading in ("The paper's claims", "Observations to reach each error threshold (ideal mode)",
                    "Wilcoxon rank-sum p-values against random (dynamics mode)",
                    "RMSE (px) after t observations", "Playing success"):
        assert heading in text
    assert "p < 1e-05 at 10 px (p=1.0e-07)" in text
    assert text.count("| Sect. IV-") == 5
    assert [f.name for f in rep.figures] == ["fig6_entropy.png", "fig7_error_ideal.png",
                                             "fig7_error_dynamics.png"]  # no snapshots: no Fig. 5


def test_report_cli_from_an_evaluation(runner, tmp_path, monkeypatch):
    from kbcli.core.keyboard import KeyboardConfig
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
    assert "[agrees]" in r.output or "[differs]" in r.output or "[not measured]" in r.output


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
