"""``kbcli report``: figures and README of an evaluation (paper Figs. 5-7, Sect. IV claims)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli.app import command, out
from kbcli.errors import KbcliError
from kbcli.io.artifact import read_artifact
from kbcli.io.atomic import atomic_path
from kbcli.stages import report as stage


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


@command(name="report")
def report_cmd(
    evaluation: Annotated[Path, typer.Argument(help="Evaluation artifact (.h5) from kbcli evaluate.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Report folder to write (created if needed).")] = Path("report"),
) -> None:
    """Write the reproduction report of an evaluation.

    Reads EVALUATION (kind 'evaluation', or 'model_quality' from kbcli quality: then
    advantage.png and a README.md that tests the paper's explanation of its robot result). Writes
    into the OUTPUT folder: fig5_posterior.png
    (posterior evolution per method and strategy, px axes), fig6_entropy.png (entropy reduction),
    fig7_error_MODE.png (error against observations per category and method) and README.md (every
    resolved option of every method, the paper's claims judged on the paper's method with ours
    beside it, the large-displacement ablation, tables of observations to each threshold,
    p-values with the smallest attainable one, RMSE and measured playing success). Prints each
    claim's verdict.
    """
    from kbcli.viz import report as viz

    art = read_artifact(evaluation, ("evaluation", "model_quality"))
    if art.kind == "evaluation":
        art = stage.upgrade(art)
    parent = output.parent if str(output.parent) else Path(".")
    if output.exists() and not output.is_dir():
        raise KbcliError(f"{output}: exists and is not a folder")
    if not parent.is_dir():
        raise KbcliError(f"{output}: parent folder {parent} does not exist")
    if art.kind == "model_quality":
        _quality_report(art, output)
        return
    rep = stage.build(art)
    output.mkdir(exist_ok=True)
    for fig in rep.figures:
        path = output / fig.name
        if fig.name.startswith("fig5"):
            viz.plot_posterior(art, path)
        elif fig.name.startswith("fig6"):
            viz.plot_entropy(art, path)
        else:
            viz.plot_error(art, path, fig.name.removeprefix("fig7_error_").removesuffix(".png"))
    _write_text(output / "README.md", rep.readme)
    out.print(f"wrote {output}/: README.md and {len(rep.figures)} figures")
    for c in rep.claims:
        out.print(f"  [{c.verdict}] {c.paper} -- {c.method}: {c.measured}", markup=False,
                  soft_wrap=True)


def _quality_report(art, output: Path) -> None:
    """The report of a model-quality sweep: advantage.png and README.md."""
    from kbcli.stages import quality
    from kbcli.viz.quality import plot_advantage

    output.mkdir(exist_ok=True)
    plot_advantage(art, output / "advantage.png")
    _write_text(output / "README.md", quality.report(art))
    out.print(f"wrote {output}/: README.md and advantage.png")
    for r in art.attrs["rows"]:
        if r != art.attrs["baseline"]:
            out.print(f"  {r}: the paper's explanation "
                      f"{quality.verdict(quality.hypothesis(art, r))}", soft_wrap=True)
