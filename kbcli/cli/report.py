"""``kbcli report``: figures and README of an evaluation (paper Figs. 5-7, Sect. IV claims)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, busy, check_io, command, interactive, out
from kbcli.cli.record import show_table
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact
from kbcli.io.atomic import atomic_folder
from kbcli.io.paths import FIGURE_FORMATS, Output
from kbcli.stages import report as stage
from kbcli.stages.report.power import REPLICATES

#: The files a report writes (any format): a new report removes those of an older one it did not
#: write again, and nothing else (the folder is written aside, then moved into place).
OWNED = ("README.md", *(f"{stem}.{fmt}" for stem in ("fig5_posterior", "fig6_entropy",
                                                     "fig7_error_*", "advantage")
                        for fmt in FIGURE_FORMATS))


def _repeated(flag: str, paths: list[Path] | None) -> dict[str, Path]:
    """A repeated option's paths as ``check_io`` inputs: ``--flag``, ``--flag #2``, ..."""
    return {flag if i == 0 else f"{flag} #{i + 1}": p for i, p in enumerate(paths or ())}


def _write_text(path: Path, text: str) -> None:
    Path(path).write_text(text, encoding="utf-8")


@command(name="report")
def report_cmd(
    evaluation: Annotated[Path, typer.Argument(help="Evaluation artifact (.h5) from kbcli evaluate.")],
    output: opts.output_option("Report folder to write (created if needed).") = Path("report"),
    fmt: Annotated[str, typer.Option(
        "--format", help=f"Figure format: {', '.join(FIGURE_FORMATS)}.")] = "png",
    ablations: Annotated[list[Path] | None, typer.Option(
        help="Evaluation of the ablation ladder (kbcli evaluate --config "
             "pipelines/ablations.toml): adds 'What explains each difference', the rung whose "
             "change flips each claim that differs. Repeat it for a ladder run one mode at a "
             "time (make reproduce-ablations MODE=ideal, then MODE=dynamics).")] = None,
    own_model: Annotated[Path | None, typer.Option(
        help="Evaluation of the same protocol with the robot's own learned model (make "
             "reproduce-own-model): the Sect. IV-C claims are judged on it too, beside the "
             "main evaluation's model.")] = None,
    replicates: opts.Replicates = REPLICATES,
) -> None:
    """Write the reproduction report of an evaluation (or of a model-quality sweep).

    Reads EVALUATION (kind 'evaluation', or 'model_quality' from kbcli quality: then
    advantage.png and a README.md that tests the paper's explanation of its robot result). Writes
    into the OUTPUT folder: fig5_posterior.png
    (posterior evolution per method and strategy, px axes), fig6_entropy.png (entropy reduction),
    fig7_error_MODE.png (error against observations per category and method) and README.md (every
    resolved option of every method, the paper's claims judged on the paper's method with ours
    beside it, the large-displacement ablation, tables of observations to each threshold,
    p-values with the smallest attainable one, RMSE and measured playing success); --format pdf or
    svg writes the figures in that format instead; --ablations ABL.h5 adds the section "What
    explains each difference"; --own-model OWN.h5 judges the Sect. IV-C claims on that evaluation
    too. Prints each claim's verdict.
    """
    if fmt not in FIGURE_FORMATS:
        raise ConfigError(f"--format must be one of {', '.join(FIGURE_FORMATS)}, got {fmt!r}")
    inputs = {"EVALUATION": evaluation, **_repeated("--ablations", ablations),
              "--own-model": own_model}
    check_io(inputs, Output(output, "report folder", folder=True))
    from kbcli.viz import report as viz  # (matplotlib: seconds)
    art = read_artifact(evaluation, ("evaluation", "model_quality"))
    if art.kind == "model_quality":
        _quality_report(art, evaluation, output, fmt)
        return
    art = stage.upgrade(art)
    ladders = [read_artifact(p, ("evaluation",)) for p in ablations or ()]
    own = read_artifact(own_model, ("evaluation",)) if own_model else None
    with busy("judging the paper's claims (and replicating those that differ)"):
        rep = stage.build(art, ablations=ladders, own=own, replicates=replicates)
    names = {f.name: str(Path(f.name).with_suffix("." + fmt)) for f in rep.figures}
    check_io(inputs,
             Output(output, "report folder", folder=True, files=("README.md", *names.values())))
    readme = rep.readme
    with atomic_folder(output, owned=OWNED) as tmp, busy("drawing the report's figures"):
        for fig in rep.figures:
            path = tmp / names[fig.name]
            readme = readme.replace(f"]({fig.name})", f"]({names[fig.name]})")
            if fig.name.startswith("fig5"):
                viz.plot_posterior(art, path)
            elif fig.name.startswith("fig6"):
                viz.plot_entropy(art, path)
            else:
                viz.plot_error(art, path, fig.name.removeprefix("fig7_error_").removesuffix(".png"))
        _write_text(tmp / "README.md", readme)
    out.print(f"wrote {output}/: README.md and {len(rep.figures)} figures ({fmt})")
    for c in rep.claims:
        out.print(f"  [{c.verdict}] {c.paper} -- {c.method}: {c.measured}", markup=False,
                  soft_wrap=True)


def _quality_report(art, source: Path, output: Path, fmt: str) -> None:
    """The report of a model-quality sweep: the advantage figure and README.md."""
    from kbcli.stages import quality
    from kbcli.viz.quality import plot_advantage

    fig = f"advantage.{fmt}"
    check_io({"EVALUATION": source},
             Output(output, "report folder", folder=True, files=("README.md", fig)))
    with atomic_folder(output, owned=OWNED) as tmp, busy("drawing the report's figure"):
        plot_advantage(art, tmp / fig)
        _write_text(tmp / "README.md",
                    quality.report(art).replace("](advantage.png)", f"]({fig})"))
    out.print(f"wrote {output}/: README.md and {fig}")
    for r in art.attrs["rows"]:
        if r != art.attrs["baseline"]:
            out.print(f"  {r}: the paper's explanation "
                      f"{quality.verdict(quality.hypothesis(art, r))}", soft_wrap=True)


@command(bench_app, name="verdicts")
def bench_verdicts_cmd(
    evaluation: Annotated[Path, typer.Argument(
        help="Evaluation artifact (.h5) from kbcli evaluate, or a model-quality sweep from kbcli "
             "quality.")],
    timings: Annotated[Path | None, typer.Option(
        help="Stage timings to show beside the verdicts, as benchmarks/reproduce.sh writes them "
             "(OUT/timings.txt: one 'stage  wall s' line per stage).")] = None,
    own_model: Annotated[Path | None, typer.Option(
        help="Evaluation with the robot's own learned model: its Sect. IV-C claims too, as "
             "kbcli report --own-model judges them.")] = None,
    ablations: Annotated[list[Path] | None, typer.Option(
        help="The ablation ladder's evaluation (make reproduce-ablations): what explains each "
             "claim that differs, as kbcli report --ablations writes it (repeat it for a ladder "
             "run one mode at a time).")] = None,
    replicates: opts.Replicates = REPLICATES,
) -> None:
    """Print the verdicts of an evaluation or a model-quality sweep as tables, with stage timings.

    Reads EVALUATION (kind 'evaluation': the paper's claims judged as kbcli report judges them,
    with the smallest p-value each one measured; kind 'model_quality': the paper's explanation
    tested and every model's advantage); with --ablations, what explains each claim that differs;
    with --timings, the wall time of each stage. Writes
    nothing (kbcli bench --json FILE verdicts ... keeps the tables: the documentation's results
    pages are generated from benchmarks/results/reproduce.json and model-quality.json).
    """
    from kbcli.bench import verdicts as bench

    inputs = {"EVALUATION": evaluation, "--timings": timings, "--own-model": own_model,
              **_repeated("--ablations", ablations)}
    check_io(inputs)
    art = read_artifact(evaluation, ("evaluation", "model_quality"))
    if art.kind == "model_quality":
        for flag, given in (("--own-model", own_model), ("--ablations", ablations)):
            if given:
                raise ConfigError(f"{flag} reads an evaluation's claims; EVALUATION is a "
                                  "model-quality sweep")
        tables = [bench.sweep_table(art), bench.hypothesis_table(art), bench.models_table(art),
                  bench.plateau_table(art)]
    else:
        own = read_artifact(own_model, ("evaluation",)) if own_model else None
        ladders = [read_artifact(p, ("evaluation",)) for p in ablations or ()]
        with busy("judging the paper's claims (and replicating those that differ)"):
            tables = bench.evaluation_tables(art, own, ladders, replicates=replicates)
    if timings is not None:
        tables += [t for t in bench.timings_table(timings.read_text(encoding="utf-8")) if t.rows]
    con = out if interactive() else Console(width=max(out.width, 160), highlight=False)
    for t in tables:
        _show(con, t)


def _show(con: Console, t) -> None:
    """One result table (:class:`kbcli.bench.verdicts.ResultTable`) printed, and kept for --json."""
    table = Table(title=t.title, title_justify="left")
    for c in t.columns:
        table.add_column(c, overflow="fold")
    for r in t.rows:
        table.add_row(*(r.get(c, "") for c in t.columns))
    show_table(con, table)
