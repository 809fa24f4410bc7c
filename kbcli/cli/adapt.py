"""``kbcli adapt``, ``kbcli plot adapt`` and ``kbcli bench adapt``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from kbcli.cli import options as opts
from kbcli.cli.app import (
    bench_app,
    check_io,
    command,
    err,
    figure_output,
    note_arm,
    note_default,
    out,
    plot_app,
)
from kbcli.cli.paper_flags import robot_given, with_paper_flags
from kbcli.cli.record import show_table, timing_note
from kbcli.cli.repair import check_model_out, write_repaired
from kbcli.cli.show import busy, drain, table, ticker, wide
from kbcli.core.adaptation.config import refuse_inactive
from kbcli.core.config import refused_option
from kbcli.core.instrument.transforms import DEFAULT_FAMILY, FAMILIES
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import arm_file, load_arm, load_stage_table, with_file
from kbcli.stages import adapt as stage
from kbcli.stages import repair as repair_stage
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_EXPERIMENTS

#: The posterior snapshots ``adapt`` stores unless told (those past --max-steps are left out).
DEFAULT_SNAPSHOTS = (0, 1, 2, 3, 5, 10, 20, 40)


def _snapshots(text: str | None, table: object, max_steps: int) -> tuple[int, ...]:
    """The steps to snapshot: ``--snapshots`` (a comma list or ``all``), else the config's
    ``[adapt] snapshot_steps`` (the run's recorded key), else :data:`DEFAULT_SNAPSHOTS` up to
    ``max_steps``. A step beyond ``max_steps`` that the user asked for gets a note."""
    if text is None and table is None:
        return tuple(s for s in DEFAULT_SNAPSHOTS if s <= max_steps)
    if text is None:
        if not (isinstance(table, list) and all(isinstance(v, int) and not isinstance(v, bool)
                                                and v >= 0 for v in table)):
            raise ConfigError(f"adapt.snapshot_steps must be a list of steps >= 0, got "
                              f"{table!r:.60}")
        steps, given = tuple(table), "snapshot_steps"
    else:
        steps, given = _parse_snapshots(text, max_steps), "--snapshots"
    _note_beyond(steps, max_steps, given)
    return steps


def _parse_snapshots(text: str, max_steps: int) -> tuple[int, ...]:
    if text.strip().lower() == "all":
        return tuple(range(max_steps + 1))
    steps = opts.comma_list(text, "--snapshots", "step numbers separated by commas")
    if any(s < 0 for s in steps):
        raise ConfigError(f"--snapshots must be steps >= 0, got {text!r}")
    return steps


@command(name="adapt")
@with_paper_flags
def adapt_cmd(
    model: opts.model_option(),
    scene: Annotated[Path, typer.Option("--scene", help="Scene artifact (.h5, kind 'scene'): the "
                                        "displaced keyboard, for the simulated world only.")],
    output: opts.output_option("Run artifact to write (.h5)."),
    config: opts.config_option(
        "TOML file with an [adapt] table (any AdaptConfig option); flags override it.") = None,
    strategy: opts.strategy_option("infogain") = None,
    posterior: opts.posterior_option("likelihood") = None,
    estimator: opts.estimator_option() = None,
    family: opts.family_option("the scene's family") = None,
    mode: opts.mode_option("ideal") = None,
    reach_noise: opts.reach_noise_option("0.0") = None,
    feedback: Annotated[str | None, typer.Option(
        "--feedback", help="Where the robot updates its posterior: landed (where it feels its "
        "finger landed) or aim (where it aimed).", show_default="landed")] = None,
    arm: opts.arm_option("ideal", optional=True) = None,
    model_blur: opts.ModelBlur = None,
    repair: opts.Repair = None,
    model_out: opts.ModelOut = None,
    max_steps: opts.max_steps_option(f"Touches (observations) at most, at most {MAX_ADAPT_STEPS}.",
                                     show_default="40") = None,
    resolution: opts.Resolution = None,
    prior_halfwidth: opts.PriorHalfwidth = None,
    stop: Annotated[bool | None, typer.Option(
        "--stop/--no-stop", help="End at the stopping rules (--stop-mass, --stop-ml). adapt "
        "measures, so by default it takes all --max-steps touches, records the error after each "
        "and says when a rule fired (as evaluate does); serve and run, which drive a robot, stop "
        "at the rules.", show_default="--no-stop")] = None,
    paper_flags: dict | None = None,
    snapshots: Annotated[str | None, typer.Option(
        "--snapshots", help="Steps at which to store the posterior (0 = prior), or 'all' (every "
        "step: kbcli animate then shows each one); in a config, [adapt] snapshot_steps = [...].",
        show_default=",".join(map(str, DEFAULT_SNAPSHOTS)) + " (up to --max-steps)")] = None,
    seed: opts.seed_option("Seed of the robot's and world's draws.") = 0,
) -> None:
    """Recover the scene's displacement by touching and listening.

    Reads MODEL (kind 'model') and SCENE (kind 'scene', whose keyboard must be the model's).
    Writes OUTPUT (kind 'run'): per step the action, where it landed, the sound heard and its class,
    the estimate, its error against the scene's true pose, the posterior entropy and the time
    spent; plus posterior snapshots. Prints the final error and the steps to an error below 1 px.
    With --repair --model-out, also writes the model repaired by the touches (kind 'model').
    """
    check_io({"--model": model, "--scene": scene, "--config": config, "--arm": arm_file(arm)},
             ("--output", output), ("--model-out", model_out))
    flags = {"strategy": strategy, "posterior": posterior, "estimator": estimator,
             "family": family, "mode": mode, "reach_noise": reach_noise, "feedback": feedback,
             "model_blur": model_blur, "repair": repair, "max_steps": max_steps,
             "resolution": resolution, "prior_halfwidth": prior_halfwidth, "stop": stop,
             **(paper_flags or {})}
    model_art = read_artifact(model, "model")
    scene_art = read_artifact(scene, "scene")
    cfg, scene_family, steps = _adapt_config(config, flags, arm, scene_art, model_out, snapshots)
    art, adapter, setup_ms = _adapt(cfg, model_art, scene_art, seed, steps)
    write_artifact(art, output)
    _report_run(art, cfg, output, setup_ms, scene_family)
    if model_out is not None:
        adaptations = [repair_stage.run_adaptation(adapter, art)]
        write_repaired(model_art, adapter.model, adaptations, model_out, "adapt")


def _adapt(cfg: stage.AdaptConfig, model_art, scene_art, seed: int, steps: tuple[int, ...]
           ) -> tuple:
    """The run of the adapt stage behind a progress bar (once its inputs passed their checks):
    its artifact, the adapter (whose model the touches repaired) and the set-up time (ms; None if
    not measured)."""
    stage.check_inputs(model_art, scene_art)
    note_arm(cfg.arm, cfg.mode)
    what = f"adapting ({cfg.robot.strategy.name}, {cfg.robot.posterior.name} posterior), observations"
    timings: dict[str, float] = {}
    keep: dict = {}
    with ticker(cfg.max_steps, what) as tick:
        art = stage.run(cfg, model_art, scene_art, rng=np.random.default_rng(seed), seed=seed,
                        snapshot_steps=steps, on_step=tick, timings=timings, keep=keep)
    return art, keep.get("adapter"), timings.get("setup_ms")


def _note_beyond(steps: tuple[int, ...], max_steps: int, given: str) -> None:
    """A note on the asked-for snapshot steps past ``--max-steps`` (they are not recorded)."""
    if beyond := sorted({s for s in steps if s > max_steps}):
        shown = ", ".join(map(str, beyond[:8])) + (f", ... ({len(beyond)} steps)" if len(beyond) > 8
                                                   else "")
        err.print(f"kbcli: note: {given} {shown} beyond --max-steps {max_steps}: not "
                  "recorded", markup=False)


def _adapt_config(config: Path | None, flags: dict, arm: str | None, scene_art,
                  model_out: Path | None, snapshots: str | None
                  ) -> tuple[stage.AdaptConfig, bool, tuple[int, ...]]:
    """The [adapt] table of ``config`` (if any) with the flags given on top, the arm, and the
    scene's family unless set; whether it was the scene's; and the steps to snapshot
    (:func:`_snapshots`). Refuses a robot option the method does not read
    (:func:`kbcli.core.adaptation.config.refuse_inactive`) and ``--model-out`` without ``--repair``."""
    table = load_stage_table(config, "adapt") if config is not None else {}
    snaps = table.pop("snapshot_steps", None)
    given = {k: v for k, v in flags.items() if v is not None}
    if arm is not None:
        given["arm"] = load_arm(arm)
    scene_family = "family" not in {**table, **given}  # what the scene moved (rigid: an angle)
    if scene_family:
        given["family"] = scene_art.config.get("family", "translation")
    labels = robot_given(flags, table, str(config))
    try:
        cfg = with_file(stage.AdaptConfig, table, given, config)
    except ConfigError as exc:
        raise refused_option(exc, labels, "adapt") from None
    refuse_inactive(cfg.robot, labels, "adapt")
    check_model_out(model_out, cfg.robot.repairs)
    return cfg, scene_family, _snapshots(snapshots, snaps, cfg.max_steps)


def _report_run(art, cfg, output: Path, setup_ms: float | None = None,
                scene_family: bool = False) -> None:
    """One line on the run written (its set-up time apart from the median touch's); notes on a
    family taken from the scene and on a truth outside the prior."""
    if scene_family and cfg.family != DEFAULT_FAMILY:  # (said once the inputs passed every check)
        note_default("family", cfg.family, "the scene's (--family to choose)")
    a = art.attrs
    est = ", ".join(f"{k}={v:.2f}" for k, v in a["estimate"].items())
    truth = ", ".join(f"{k}={v:.2f}" for k, v in a["truth"].items())
    reach = a["steps_to_1px"]
    stop_txt = f"; stopping rule at step {a['stop_step']}" if a["stop_step"] else ""
    angle = (f", angle error {a['final_angle_error_deg']:.2f} deg"
             if FAMILIES.get(cfg.family).rotates or FAMILIES.get(a["world_family"]).rotates
             else "")
    out.print(f"wrote {output}: {cfg.robot.strategy.name}/{cfg.robot.posterior.name}, {a['steps']} steps; estimate "
              f"{est} (truth {truth}); final error {a['final_error_px']:.2f} px{angle}; "
              f"below 1 px {'from step ' + str(reach) if reach else 'never'}{stop_txt}; "
              + (f"set-up {setup_ms:.0f} ms, " if setup_ms is not None else "")
              + f"{a['median_step_ms']:.1f} ms per touch (median)")
    if not a["truth_inside_prior"]:
        err.print("kbcli: note: the scene's displacement lies outside the robot's prior "
                  "(--prior-halfwidth, max_angle, --family): it cannot be recovered exactly", markup=False)


@command(plot_app, name="adapt")
def plot_adapt_cmd(
    run: Annotated[Path, typer.Argument(help="Run artifact (kind 'run') from kbcli adapt.")],
    output: opts.Figure = Path(
        "adapt.png"),
) -> None:
    """Draw the posterior's evolution (the paper's Fig. 5) and the error and entropy curves.

    Reads RUN (kind 'run'); writes the figure (PNG, PDF or SVG by the suffix of -o); prints its path.
    """
    check_io({"RUN": run}, figure_output(output))
    from kbcli.viz.adapt import plot_adapt  # (matplotlib: seconds)
    art = read_artifact(run, "run")
    if len(art.data.get("errors", ())) == 0:
        raise ConfigError(f"{run}: holds no touches (a session that ended before the first one)")
    if "snapshots" not in art.data:
        raise ConfigError(f"{run}: holds no posterior snapshots (rerun kbcli adapt with "
                          f"--snapshots)")
    with busy("drawing"):
        plot_adapt(art, output)
    out.print(f"wrote {output}")


def _kde_speed_table(bench, model_path: Path | None, learned, steps: int, seed: int,
                     con: Console) -> None:
    """Print the KDE step's speed on the learned model (the issue's target: <= 5 ms per step)."""
    if learned is None:
        model_path, _, learned, _ = opts.read_model(None)
    r = bench.kde_speed(learned, steps=steps, seed=seed)
    k, lk = r["kde_ms"], r["likelihood_ms"]
    t = table(f"one adaptation step on {model_path} ({r['grid_cells']:,} grid cells, {steps} "
              "touches, one process)", ("posterior", "median ms/step", "p10", "p90",
                                        "median CPU ms/step", "vs likelihood (CPU)"))
    rows = (("kde (Algorithm 2: binning + FFT, Eq. 8 product)", k, r["kde_cpu_ms"]),
            ("likelihood", lk, r["likelihood_cpu_ms"]))
    for name, ms, cpu in rows:
        t.add_row(name, f"{np.median(ms):.2f}", f"{np.percentile(ms, 10):.2f}",
                  f"{np.percentile(ms, 90):.2f}", f"{np.median(cpu):.2f}",
                  f"{np.median(cpu) / np.median(r['likelihood_cpu_ms']):.1f}x")
    show_table(con, t)
    con.print(timing_note("wall time per step"))
    con.print(f"drawing one class's {10000} samples of p(action | sound) once: median "
              f"{r['sample_ms']:.0f} ms over the {r['classes']} classes heard (not per touch)")


@command(bench_app, name="adapt")
def bench_adapt_cmd(
    experiments: opts.count_option("--experiments", "Runs per strategy and displacement category",
                                   MAX_EXPERIMENTS) = 50,
    section: Annotated[list[str] | None, typer.Option(
        "--section", help="Sections to run (repeat): exact, noise, rigid, kde, learned or "
        "learned-rigid.", show_default="exact, noise, rigid and kde, plus learned with --model")
    ] = None,
    model: opts.model_option("A learned model artifact for the learned section.",
                             optional=True) = None,
    strategy: opts.strategies_option("random, active, infogain") = None,
    category: opts.Categories = None,
    max_steps: opts.count_option("--max-steps", "Touches per run", MAX_ADAPT_STEPS, "-T") = 40,
    seed: opts.seed_option("Seed of displacements and runs.") = 0,
    model_blur: Annotated[float | None, typer.Option(
        "--model-blur", help="learned section: soften the model's map by this many px.",
        show_default="1")] = None,
    layout: opts.layout_option("Keyboard layout of every section: {layouts} (its default "
                               "keyboard).", show_default="the model's keyboard with --model, "
                               "else grid") = None,
    kde_steps: opts.count_option("--kde-steps", "kde section: touches timed for the KDE step's "
                                 "speed (on --model, else the embedded default model)",
                                 opts.MAX_TIMED_STEPS, min=1) = 200,
) -> None:
    """Benchmark the adaptation strategies: sample efficiency and speed, on any layout.

    Reads MODEL if given (its keyboard is the world's). Writes nothing. Prints per section, strategy and category: median
    observations to an error below 4, 2, 1, 0.5 px (in brackets: runs that never got there within
    T), the RMSE at steps 1, 2, 3, 5, 10, 20, 40, the Wilcoxon rank-sum p-value against random at
    each threshold, and the median milliseconds per step (decision plus update). The kde section
    also times one KDE step (Algorithm 2 + the product, samples drawn once per class) against a
    likelihood step on the learned model (--model, default data/default-model.h5), in ms per step.
    """
    from kbcli.bench import adapt as bench

    opts.check_counts(("--experiments", experiments, MAX_EXPERIMENTS),
                      ("--max-steps", max_steps, MAX_ADAPT_STEPS),
                      ("--kde-steps", kde_steps, opts.MAX_TIMED_STEPS))
    learned, model_art, kb, layout = _bench_model(model, layout)
    sections = tuple(section) if section else bench.default_sections(model is not None)
    cfg = bench.BenchConfig(
        experiments=experiments, max_steps=max_steps, seed=seed, sections=sections,
        strategies=tuple(strategy) if strategy else bench.STRATEGY_ORDER,
        categories=tuple(category) if category else tuple(bench.CATEGORIES), model_blur=model_blur,
        layout=layout or "grid")
    con = wide(200)
    if any(bench.SECTIONS.get(s).timed for s in sections):
        _kde_speed_table(bench, model, learned, kde_steps, seed, con)
    cells = bench.plan(cfg, learned, kb)
    drain(bench.run_cells(cells), sum(len(c.truths) for c in cells), "adaptation runs")
    rows = bench.summarize(cells)
    bnd = model_art.attrs.get("boundary_error_px") if model_art is not None else None
    for sec in sections:
        if sec_rows := [r for r in rows if r["section"] == sec]:
            title = bench.section_title(sec, cfg, str(model) if model else None)
            show_table(con, _section_table(bench, cfg, sec, sec_rows, title, bnd))
    note = medians_note(experiments, "observations", "observation", "runs",
                        "rmse in px over all runs; ")
    err.print(note, markup=False)


def medians_note(pairs: int, counted: str, count: str, runs: str, also: str = "") -> str:
    """What the medians of a sample-efficiency table are (``counted``: what is counted, plural;
    ``count``: singular; ``runs``: what a row repeats, plural) and the smallest p-value ``pairs``
    pairs can give."""
    return (f"medians: {counted} until the error first drops below the threshold; (k): {runs} that "
            f"never got there within T; {also}p: Wilcoxon signed-rank test of the {count} counts "
            f"against random on the paired {runs} (same displacement and seed; the smallest p "
            f"{pairs} pairs can give is {2.0 ** (1 - pairs):.0e})")


def _bench_model(model: Path | None, layout: str | None) -> tuple:
    """The learned model of ``--model`` (its fitted model, artifact and keyboard; Nones without
    one) and the layout (the model's; a different ``--layout`` is refused)."""
    if model is None:
        return None, None, None, layout
    _, model_art, learned, kb = opts.read_model(model)
    if layout is not None and layout != kb.layout:
        raise ConfigError(f"--layout {layout} but the model {model} was learned on a "
                          f"{kb.layout} keyboard")
    return learned, model_art, kb, kb.layout


def _section_table(bench, cfg, sec: str, sec_rows: list[dict], title: str, bnd) -> Table:
    """One section's table: per strategy and category the medians to each threshold, the RMSE
    at steps, the p-values, ms per step (and the angle and boundary columns of its section)."""
    part = bench.SECTIONS.get(sec)
    T = sec_rows[0]["T"]
    rmse_steps = [s for s in bench.RMSE_STEPS if s <= T]
    t = table(f"{cfg.layout} layout, {title}: {cfg.experiments} runs per row, T = {T}",
              ("strategy", "category", *(f"<{thr:g}px" for thr in bench.THRESHOLDS),
               *(f"rmse@{s}" for s in rmse_steps), "p vs random, paired (<4/2/1/0.5)", "ms/step",
               *(["final angle rmse"] if part.angle else []),
               *(["final err / boundary err"] if part.learned else [])), left=2)
    for r in sec_rows:
        rm = [f"{r['rmse'][s]:.2f}" for s in rmse_steps]
        row = [r["label"], r["category"], *medians(r), *rm, pvalues(r), f"{r['ms']:.1f}"]
        if part.angle:
            row.append(f"{r['final_angle_rmse']:.2f} deg")
        if part.learned:
            row.append(f"{r['final_rmse']:.2f} / "
                       + (f"{bnd:.2f} px" if isinstance(bnd, (int, float)) else "n/a"))
        t.add_row(*row)
    return t


def medians(r: dict) -> list[str]:
    """A row's median counts to each threshold, with the runs that never got there: ``3 (2)``."""
    def med(m: float, never: int) -> str:
        s = "-" if math.isnan(m) else f"{m:g}"
        return f"{s} ({never})" if never else s

    return [med(m, n) for m, n in zip(r["median"], r["never"], strict=True)]


def pvalues(r: dict) -> str:
    """A row's p-values against random, one per threshold ("" for random itself)."""
    def fmt(p: float) -> str:
        return "1" if p >= 0.9995 else f"{p:.0e}" if p < 1e-3 else f"{p:.3f}"

    return " ".join(fmt(v) for v in r["p"]) if r["p"] is not None else ""
