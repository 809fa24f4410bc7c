"""``kbcli learn``, ``kbcli plot model`` and ``kbcli bench learn``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, check_io, command, err, figure_output, note_arm, out, plot_app
from kbcli.cli.record import show_table
from kbcli.cli.show import busy, drain, phases, progress, table, wide
from kbcli.core.config import refused_option
from kbcli.core.model.explore.base import Covering
from kbcli.errors import ConfigError, KbcliError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import arm_file, load_arm
from kbcli.io.schema import MIN_SOUNDS
from kbcli.sim import SimConfig
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as stage
from kbcli.stages.config import MAX_BUDGET, MAX_EXPERIMENTS


@command(name="learn")
def learn_cmd(
    keyboard: opts.keyboard_option(),
    output: opts.output_option("Model artifact to write (.h5)."),
    mode: opts.mode_option(note="ideal: the finger lands on the target; dynamics: the pymunk "
                           "arm") = "ideal",
    strategy: Annotated[str, typer.Option(
        "--strategy", help=f"Exploration: {opts.one_of('exploration', 'exact')} (exact: the "
        "keyboard's own geometry, no learning).")] = "active",
    budget: Annotated[int, typer.Option(
        "--budget", help=f"Reaches to explore with, at most {MAX_BUDGET}; a run that hears fewer than "
        "two distinct sounds is refused (nothing written).")] = 800,
    seed: opts.seed_option("Seed of the exploration and arm noise.") = 0,
    reach_noise: opts.ReachNoise = 0.0,
    arm: opts.arm_option() = "ideal",
    batch: Annotated[int, typer.Option("--batch", help=f"Reaches per refit, at most {MAX_BUDGET}.")] = 10,
    explore_radius: Annotated[float | None, typer.Option(
        "--explore-radius", help="active, balanced: first cover the working area to this radius, "
        "px (at least 1.9 px on the default pad: a cover of 1,000,000 points).",
        show_default=str(Covering.model_fields["explore_radius"].default))] = None,
    curve_every: Annotated[int, typer.Option(
        "--curve-every", help=f"Reaches between learning-curve points, at most {MAX_BUDGET}.")] = 50,
    model_class: opts.model_class_option(
        "Model class: auto or one of {classes}. auto: explore with forest, keep the class with the "
        "best cross-validated score on the samples (on stderr); lines: straight key edges; svc, "
        "forest, knn: scikit-learn SVMs, random forest, nearest samples (any key shape); "
        "forest-xy: a forest splitting on x and y only (horizontal and vertical key edges).")
        = "auto",
    model_option: opts.ModelOption = None,
) -> None:
    """Learn the instrument model by exploring the pad with the simulated arm.

    Reads KEYBOARD (kind 'keyboard'; its whole working area must be within the arm's reach).
    Writes OUTPUT (kind 'model': the samples, the fitted model, the learning curve and the
    model's predicted key map). Prints the model's accuracy and boundary error against the
    simulator's ground truth.
    """
    sim = SimConfig(mode=mode, reach_noise=reach_noise, arm=load_arm(arm))
    own = {} if explore_radius is None else {"explore_radius": explore_radius}
    mine = opts.key_values(model_option, "--model-option")
    try:
        cfg = stage.LearnConfig(strategy=strategy, budget=budget, batch=batch, curve_every=curve_every,
                                sim=sim, model_class={"name": model_class, **mine}, **own)
    except ConfigError as exc:
        raise refused_option(exc, {"explore_radius": "--explore-radius"}, "learn",
                             f"strategy {strategy}") from None
    check_io({"--keyboard": keyboard, "--arm": arm_file(arm)}, ("--output", output))
    kb_art = read_artifact(keyboard, "keyboard")
    if not cfg.exact:  # (the exact model reaches for nothing)
        note_arm(sim.arm, sim.mode)
    if cfg.exact:
        art = stage.run(cfg, kb_art, rng=np.random.default_rng(seed), seed=seed)
        write_artifact(art, output)
        out.print(f"wrote {output}: exact model (the keyboard's own geometry, "
                  f"{stage.check_keyboard(kb_art).n_keys} keys)")
        return
    art = _explore(cfg, kb_art, seed, f"{strategy} exploration ({mode}, {model_class}), reaches")
    write_artifact(art, output)
    _note_selection(art.attrs)
    _report_learned(art.attrs, output, strategy, mode)


def _explore(cfg: stage.LearnConfig, kb_art, seed: int, what: str):
    """The model learned by exploring behind a progress bar of the reaches, then a spinner of
    its finishing phases; refused (nothing written) when it heard too few sounds."""
    learning = stage.learn(cfg, kb_art, rng=np.random.default_rng(seed), seed=seed)
    done = [0]

    def reaches(n: int) -> int:  # each item is a batch; the bar counts reaches
        step, done[0] = n - done[0], n
        return step

    drain(learning, cfg.budget, what, advance=reaches)
    with phases("finishing the model") as phase:  # (model selection and calibration take a while)
        art = learning.artifact(on_phase=phase)
    a = art.attrs
    sounds = a["n_classes"] - 1
    if sounds < MIN_SOUNDS:
        raise KbcliError(
            f"learned only {sounds} sound class(es) besides silence in {a['n_reaches']} reaches, "
            f"fewer than the {MIN_SOUNDS} a model needs to find a moved keyboard; nothing written: "
            f"raise --budget")
    return art


def _report_learned(a: dict, output: Path, strategy: str, mode: str) -> None:
    """The learned model in one line: sounds, accuracy, boundary error, when it reached 99 %;
    below 99 %, a note on what that means for playing."""
    to99 = a["reaches_to_99"]
    out.print(
        f"wrote {output}: {a['layout']} layout, {a['model_class']} model, {strategy} exploration, "
        f"{mode} mode, {a['n_reaches']} reaches: "
        f"{a['n_classes'] - 1} sounds + silence, accuracy {100 * a['accuracy']:.2f} %, "
        f"boundary error {a['boundary_error_px']:.2f} px, "
        + (f"99 % accuracy after {to99} reaches" if to99 is not None
           else "99 % accuracy not reached")
    )
    if to99 is None:
        err.print("kbcli: note: below 99 % accuracy the robot misses some notes even where the "
                  "keyboard is (kbcli run says how many): more reaches (--budget) learn it "
                  "better", markup=False)


def _note_selection(attrs: dict) -> None:
    """Under ``--model-class auto``: the class chosen and every candidate's score, on stderr."""
    if "model_selection" in attrs:
        from kbcli.core.model.select import Selection

        err.print(Selection(**attrs["model_selection"]).summary())


@command(plot_app, name="model")
def plot_model_cmd(
    artifact: Annotated[Path, typer.Argument(help="Model artifact (.h5).")],
    output: opts.Figure = Path("model.png"),
) -> None:
    """Draw a model: the learned map (predicted key, uncertainty, reaches) beside the true layout,
    and the learning curve. Reads ARTIFACT (kind 'model'); writes the figure (PNG, PDF or SVG by the suffix of -o)."""
    from kbcli.stages.models import load_model
    check_io({"ARTIFACT": artifact}, figure_output(output))
    from kbcli.viz.model import plot_model  # (matplotlib: seconds)
    art = read_artifact(artifact, "model")
    with busy("drawing"):
        plot_model(art, load_model(art), keyboard_stage.load(art), output)
    out.print(f"wrote {output}")


#: Budgets one benchmark's --budgets may list.
MAX_BUDGETS = 64


def _budgets(text: str) -> tuple[int, ...]:
    vals = opts.comma_list(text, "--budgets")
    if not vals or any(v < 1 or v > MAX_BUDGET for v in vals):
        raise ConfigError(f"--budgets must be whole numbers in [1, {MAX_BUDGET}], got {text!r}")
    if len(vals) > MAX_BUDGETS:
        raise ConfigError(f"--budgets: at most {MAX_BUDGETS} budgets, got {len(vals)}")
    return vals


@command(bench_app, name="learn")
def bench_learn_cmd(
    seeds: opts.count_option("--seeds", "Runs per row", opts.MAX_SEEDS) = 5,
    budgets: Annotated[str | None, typer.Option(
        "--budgets", help="Budgets (reaches) at which to report the accuracy, comma-separated, "
        f"each at most {MAX_BUDGET}.", show_default="200,400,800,1600; with --peer 150,300,800")] = None,
    strategy: opts.strategies_option("active, random", kind="exploration") = None,
    layout: opts.layout_option("Layouts to learn, each its default keyboard (repeat): {layouts}.",
                               many=True, show_default="grid; with --peer all five") = None,
    model_class: opts.model_class_option("Model classes to fit (repeat): {classes}.", many=True,
                                         show_default="lines") = None,
    keyboard: opts.keyboard_option("A keyboard artifact to learn instead of the layouts' "
                                   "defaults.", optional=True) = None,
    mode: opts.mode_option(help="Reaching") = "ideal",
    reach_noise: opts.ReachNoise = 0.0,
    seed: opts.seed_option("Seed of the runs.") = 0,
    boundary_budget: opts.count_option("--boundary-budget", "Reaches at which the boundary error "
                                       "and the learn wall time are measured", MAX_BUDGET) = 800,
    eval_step: Annotated[float, typer.Option(
        "--eval-step", help="Grid (px) on which the accuracy is measured.")] = 1.0,
    cache: Annotated[Path | None, typer.Option(
        "--cache", help="Folder keeping each run's result: a run already there (same settings) is "
        "read back, not run again.")] = None,
    peer: Annotated[bool, typer.Option(
        "--peer", help="Instead: kbcli's default learner (auto, active) beside scikit-activeml's "
        "uncertainty sampling around scikit-learn classifiers, same simulator, seeds and scorer, "
        "with a verdict per layout and budget; on grid, hex, piano, pads and polygons unless "
        "--layout is given.")] = False,
    jobs: opts.Jobs = 1,
) -> None:
    """Benchmark learning the model: sample efficiency and speed per layout, class and strategy.

    Reads nothing (or --keyboard); writes nothing. Prints, per row over SEEDS runs: the median
    accuracy (on a grid of --eval-step px over the working area) at each budget, the median reaches
    until 97 % and 99 % accuracy, the median boundary error (px) at the boundary budget and the
    median time of one fit at the largest budget; active / random reaches to 97 %; then the wall
    time of one `kbcli learn` stage run at the boundary budget and the dynamics simulator's
    reaches per second. --jobs: with --peer, learning runs at once (the same numbers).
    """
    from kbcli.bench import learn as bench

    opts.check_counts(("--seeds", seeds, opts.MAX_SEEDS),
                      ("--boundary-budget", boundary_budget, MAX_BUDGET))
    if _bench_peer(peer, seeds, budgets, layout, seed, eval_step, jobs):
        return
    kb = None
    if keyboard is not None:
        kb = keyboard_stage.load(read_artifact(keyboard, "keyboard"))
        layout = [kb.layout]
    cfg = bench.BenchConfig(seeds=seeds, budgets=_budgets(budgets or "200,400,800,1600"), mode=mode,
                            reach_noise=reach_noise, seed=seed, boundary_budget=boundary_budget,
                            strategies=tuple(strategy) if strategy else bench.STRATEGY_ORDER,
                            layouts=tuple(layout) if layout else ("grid",),
                            model_classes=tuple(model_class) if model_class else ("lines",),
                            eval_step=eval_step)
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    _learning_tables(bench, cfg, kb, cache)


def _learning_tables(bench, cfg, kb, cache: Path | None) -> None:
    """Run the learning benchmark and print its table, the reaches to 97 % per strategy, the wall
    time of one learn stage and the dynamics simulator's rate."""
    results = list(progress(bench.runs(cfg, kb, cache), cfg.n_runs, "learning runs"))
    rows = bench.summarize(cfg, results)
    con = wide(200)
    head, body = bench.table(cfg, rows)
    t = table(f"learning the model: {cfg.seeds} seeds per row, {cfg.mode} mode"
              + (f", {cfg.reach_noise:g} px reach noise" if cfg.reach_noise else "")
              + f"; median accuracy (%) on a {cfg.eval_step:g} px grid", head, left=3)
    for row in body:
        t.add_row(*row)
    show_table(con, t)
    con.print(f"reaches to 97 % / 99 %: median over runs of the first curve point (every "
              f"{cfg.resolution} reaches) at or above it; runs that never get there count as more "
              "than the largest budget.")
    for line in bench.ratio_lines(cfg, rows):
        con.print(line)
    wall = bench.learn_wall_time(cfg, kb)
    con.print(f"kbcli learn ({cfg.layouts[0]}, {cfg.model_classes[0]}, active, {cfg.mode}, budget "
              f"{cfg.boundary_budget}, one core): {wall:.1f} s")
    rate = bench.dynamics_rate()
    con.print(f"dynamics simulator: {rate:.0f} reaches/s (1000 reaches, one core)")


def _bench_peer(peer: bool, seeds: int, budgets: str | None, layout: list[str] | None, seed: int,
                eval_step: float, jobs: int = 1) -> bool:
    """``kbcli bench learn --peer``: run and print the tables (``kbcli bench --json FILE learn
    --peer`` also writes them); False (nothing done) without ``--peer``."""
    if not peer:
        if jobs > 1:
            raise ConfigError("--jobs applies to --peer runs only")
        return False
    budgets = budgets or "150,300,800"
    from kbcli.bench import peer as bench

    fields = {"seeds": seeds, "budgets": _budgets(budgets), "seed": seed, "eval_step": eval_step}
    if layout:
        fields["layouts"] = tuple(layout)
    cfg = bench.PeerConfig(**fields)
    n = len(cfg.layouts) * cfg.seeds * (1 + len(cfg.peers))
    results = list(progress(bench.runs(cfg, jobs), n, "learning runs (kbcli and peers)"))
    tables = bench.tables(cfg, bench.summarize(cfg, results))
    con = wide(200)
    for tb in tables:
        t = table(tb["title"], tb["columns"], [c for c in tb["columns"] if c != "budget"
                                               and "%" not in c and "px" not in c])
        for r in tb["rows"]:
            t.add_row(*(str(r[c]) for c in tb["columns"]))
        show_table(con, t)
    return True


@command(bench_app, name="layouts")
def bench_layouts_cmd(
    config: opts.config_option("TOML file with a [layouts] table (pipelines/layouts.toml).",
                               optional=False) = Path("pipelines/layouts.toml"),
    output: opts.output_option("Folder to write keyboards/, models/, cache/ and report/ in.") = Path(
        "out/layouts"),
    seeds: Annotated[int | None, typer.Option(
        "--seeds", min=1, help=f"Learning runs per layout, class and strategy, at most "
        f"{opts.MAX_SEEDS}.", show_default="the config's")] = None,
    experiments: Annotated[int | None, typer.Option(
        "--experiments", min=2, help="Adaptation runs per strategy and category, translation, at "
        f"most {MAX_EXPERIMENTS}.", show_default="the config's")] = None,
    layout: opts.layout_option("Only these layouts (repeat): {layouts}.", many=True,
                               show_default="the config's") = None,
) -> None:
    """Learning and adaptation on every layout: tables and one figure per layout.

    Reads CONFIG (and its keyboards' TOML files). Writes OUTPUT/keyboards/<layout>.h5,
    OUTPUT/models/<layout>.h5 (the adaptation model), OUTPUT/cache/ (every learning run: a run
    interrupted continues where it stopped) and OUTPUT/report/: README.md (the learning and
    adaptation tables, each target beside the measured figure, the settings),
    <layout>.png and results.json. Long: hours at the default settings (make reproduce-layouts).
    """
    from kbcli.bench.layouts import LayoutsConfig, Pipeline, targets

    opts.check_counts(("--seeds", seeds, opts.MAX_SEEDS),
                      ("--experiments", experiments, MAX_EXPERIMENTS))
    cfg = LayoutsConfig.from_toml(config)
    over = {k: v for k, v in (("seeds", seeds), ("experiments", experiments),
                              ("layouts", tuple(layout) if layout else None)) if v is not None}
    if over:
        cfg = cfg.replace(**over)
    if output.exists() and not output.is_dir():
        raise ConfigError(f"{output}: exists and is not a folder")
    output.mkdir(parents=True, exist_ok=True)
    pipe = Pipeline(cfg, output)
    pipe.keyboards()
    drain(pipe.learn(), pipe.n_learn_runs, "learning runs")
    drain(pipe.models(), len(cfg.layouts), "adaptation models")
    total = pipe.plan_adapt()
    drain(pipe.adapt(), total, "adaptation runs")
    folder = pipe.report()
    met = [t["met"] for res in pipe.results.values() for t in targets(cfg, res)]
    out.print(f"wrote {folder}/README.md, {len(cfg.layouts)} figures and results.json: "
              f"{sum(met)} of {len(met)} targets met")


@command(bench_app, name="arm")
def bench_arm_cmd(
    reaches: Annotated[int, typer.Option("--reaches", help=opts.at_most(
        "Reaches per preset and mode", opts.MAX_REACHES))] = 500,
    seed: opts.seed_option("Seed of the targets and the noise.") = 0,
) -> None:
    """How each arm preset errs: landing error and felt-minus-true error.

    Reads nothing; writes nothing. For each preset (ideal, servo, realistic) and mode, reaches
    REACHES targets uniform over the default keyboard's working area in turn and prints the median
    and 95th percentile of |landed - target| (tracking), |felt - landed| (proprioception) and
    |contact - landed| (the finger's contact disc), and the simulated reaches per second.
    """
    from kbcli.bench import arm as bench

    opts.check_counts(("--reaches", reaches, opts.MAX_REACHES))
    rows = bench.run(reaches=reaches, seed=seed)
    t = table(f"arm presets: {reaches} reaches each over the default working area, px (median / "
              "95th percentile)", ("preset", "mode", "|landed - target|", "|felt - landed|",
                                   "|contact - landed|", "reaches/s"), left=2)
    for r in rows:
        t.add_row(r.preset, r.mode, *(f"{m:.2f} / {p:.2f}" for m, p in (r.landing, r.felt, r.contact)),
                  f"{r.reaches_per_s:,.0f}")
    show_table(wide(140), t)


@command(bench_app, name="reliability")
def bench_reliability_cmd(
    budgets: Annotated[str, typer.Option(
        "--budgets", help=f"Reach budgets, comma-separated, each at most {MAX_BUDGET}.")] = \
        "150,300,800,1600",
    mode: opts.mode_option(help="Reaching") = "ideal",
    arm: opts.arm_option(files=False) = "ideal",
    seed: opts.seed_option("First seed of the learning runs.") = 0,
    seeds: Annotated[int, typer.Option(
        "--seeds", help=opts.at_most("Learning runs per cell (seeds SEED, SEED+1, ...): the "
                                     "table prints medians", opts.MAX_SEEDS))] = 3,
) -> None:
    """How well calibrated learned models are, and how well they know it.

    Reads nothing; writes nothing. For active and random exploration at each budget, learns
    SEEDS models of the default keyboard (calibration included) and prints, against the simulator
    on a 2 px grid, the median over seeds of: the expected calibration error of p(sound | felt
    action) (with its smallest and largest), the accuracy and the boundary error; beside the
    model's own cross-validated estimates of each, and the calibration the first seed chose.
    """
    from kbcli.bench import reliability as bench

    opts.check_counts(("--seeds", seeds, opts.MAX_SEEDS))
    rows = bench.summarise(bench.run(budgets=_budgets(budgets), mode=mode, arm=arm, seed=seed,
                                     seeds=seeds))
    last = seed + seeds - 1
    seed_text = f"seed {seed}" if seeds == 1 else f"medians over seeds {seed}-{last}"
    chosen = f"chosen calibration (seed {seed})"
    t = table(f"calibration and self-assessment of learned models ({mode} mode, arm {arm}, "
              f"{seed_text}): measured / the model's own estimate",
              ("exploration", "reaches", "calibration error", "(min-max)", "mislabel rate",
               "boundary error (px)", chosen, "learn s"), left=("exploration", chosen))
    for r in rows:
        cal = ", ".join(f"{k} {v:g}" for k, v in sorted(r.calibration.items()))
        t.add_row(r.exploration, str(r.budget), f"{r.ece:.3f} / {r.est_ece:.3f}",
                  f"{r.ece_min:.3f}-{r.ece_max:.3f}",
                  f"{100 * r.mislabel:.1f} % / {100 * r.est_mislabel:.1f} %",
                  f"{r.boundary_error:.2f} / {r.est_boundary_error:.2f}", cal, f"{r.seconds:.0f}")
    con = wide(180)
    show_table(con, t)
    worst = max(r.ece for r in rows)
    con.print(f"largest median calibration error: {worst:.3f} (target <= 0.03)")
