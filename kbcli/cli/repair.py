"""The repaired model of ``kbcli adapt/run --repair --model-out``: writing it, saying what it absorbed."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, check_io, command, figure_output, out
from kbcli.cli.record import show_table
from kbcli.cli.show import busy, table, ticker, wide
from kbcli.errors import ConfigError
from kbcli.io.artifact import write_artifact
from kbcli.stages import repair as repair_stage
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_EXPERIMENTS


def check_model_out(model_out: Path | None, repair: bool) -> None:
    """``--model-out`` needs the repaired belief."""
    if model_out is not None and not repair:
        raise ConfigError("--model-out writes the model repaired by the adaptation: add --repair "
                          "(or repair = true in the [adapt] table)")


def write_repaired(model_art, model, adaptations, model_out: Path, source: str) -> None:
    """Refit, calibrate and score the repaired model, write it to ``model_out``, say what it
    absorbed and how its boundary error moved (against the simulator's keyboard)."""
    with busy("refitting the repaired model (5-fold cross-validation)"):
        art, s = repair_stage.repaired_model(model_art, model, adaptations, source=source)
    write_artifact(art, model_out)
    before = s["parent_boundary_error_px"]
    moved = (f"boundary error {before:.2f} -> {s['boundary_error_px']:.2f} px"
             if before is not None else f"boundary error {s['boundary_error_px']:.2f} px")
    skipped = (f"; {s['skipped']} adaptation(s) not absorbed (90 % credible radius above "
               f"{repair_stage.ABSORB_RADIUS:g} px)" if s["skipped"] else "")
    out.print(f"wrote {model_out}: generation {s['generation']}, {s['absorbed']} touches absorbed, "
              f"accuracy {100 * s['accuracy']:.2f} %, {moved}{skipped}")


@command(bench_app, name="repair")
def bench_repair_cmd(
    moves: Annotated[int, typer.Option("--moves", help=opts.at_most(
        "Displacements per weak model (5-30 px)", MAX_EXPERIMENTS))] = 8,
    touches: Annotated[int, typer.Option("--touches", "-T", help=opts.at_most(
        "Infogain touches per adaptation", MAX_ADAPT_STEPS))] = 30,
    seeds: Annotated[int, typer.Option("--seeds", help="Weak models per arm (learn seeds 1..N), "
                                       "at most 10.")] = 3,
    episodes: Annotated[int, typer.Option("--episodes", help="Moves in a row of the lifelong "
                                          "section, at most 20 (0: skip it).")] = 5,
    lifelong_models: Annotated[int | None, typer.Option(
        "--lifelong-models", help="Weak models the lifelong section carries over the moves: the "
        "first N, ideal arm first. The first is shown move by move and drawn; each gets a line "
        "of the summary.", show_default="every one")] = None,
    plot: Annotated[Path, typer.Option("--plot", help="Figure of the lifelong section (PNG, PDF "
                                       "or SVG by the suffix).")] = Path("repair-lifelong.png"),
    replicates: Annotated[int, typer.Option("--replicates", help="Adaptations of each move, "
                                            "seeds --seed, --seed + 1, ...: one seed's median "
                                            "swings by about 0.2 px. At most 10.")] = 3,
    seed: opts.seed_option("Seed of the adaptations.") = 0,
) -> None:
    """Adaptation that repairs the model, side by side with plain infogain and the exact model.

    Learns the weak models in memory (kbcli learn --strategy random --budget 250
    --seed 1..N, ideal arm and --mode dynamics --arm realistic), adapts each to --moves
    displacements (each --replicates times) with --touches infogain touches: plain (the robust posterior), repair (the
    repaired belief) and exact (the keyboard's own map), paired. Prints the median final error,
    the share under 1 px, the touches to stay under 1 px, the runs made worse than plain by more
    than 0.5 px, the coverage of the 90 % credible discs and the time per touch; per model, the
    median final error and the samples floor (the shift the model's own training samples pin
    when the whole moved keyboard is known), and the final offset's systematic part (the model's
    mean offset over its runs) and spread; then the lifelong section: each weak model (or the
    first --lifelong-models) carried over --episodes moves, the first shown move by move and
    drawn, and a line per model of what the lifelong targets read.
    """
    from kbcli.bench import repair as bench

    opts.check_counts(("--moves", moves, MAX_EXPERIMENTS), ("--touches", touches, MAX_ADAPT_STEPS),
                      ("--seeds", seeds, 10), ("--episodes", episodes or None, 20),
                      ("--replicates", replicates, 10),
                      ("--lifelong-models", lifelong_models, 2 * seeds))
    check_io({}, figure_output(plot))
    with busy("learning the weak models"):
        models = bench.weak_models(seeds=tuple(range(1, seeds + 1)))
    with ticker(len(models) * len(bench.METHODS) * moves * replicates, "adaptations") as tick:
        runs = bench.side_by_side(models, n_moves=moves, touches=touches, seed=seed,
                                  replicates=replicates, progress=tick)
    con = wide(160)
    with busy("registering each model's samples to the moved keyboard"):
        floors = bench.sample_floors(models)
    _side_table(con, bench.summarize(runs, touches), models, f"{moves} moves x {replicates} "
                f"adaptation seed{'s' if replicates > 1 else ''}", touches, floors)
    if episodes:
        _lifelong_section(con, models[:lifelong_models] if lifelong_models else models,
                          episodes, touches, seed, plot)


def _lifelong_section(con, carried: list, episodes: int, touches: int, seed: int,
                      plot: Path) -> None:
    """Carry each of ``carried`` over the moves; tabulate the first move by move and draw it, and
    every one in a line of the summary."""
    from kbcli.bench import repair as bench

    with ticker(episodes * len(carried), "lifelong moves") as tick:
        sections = [bench.lifelong(wm, episodes=episodes, touches=touches, seed=seed,
                                   progress=tick) for wm in carried]
    start, eps = sections[0]
    _lifelong_table(con, carried[0], start, eps, touches)
    _lifelong_models_table(con, carried, sections, touches)
    from kbcli.viz.repair import plot_lifelong  # (matplotlib: seconds)
    with busy("drawing"):
        plot_lifelong(start, eps, plot, touches=touches,
                      title=f"lifelong: {carried[0].name} model carried over {episodes} moves")
    con.print(f"wrote {plot}")


def _side_table(con, rows: list[dict], models, runs: str, touches: int,
                floors: dict[str, float]) -> None:
    t = table(f"repair vs plain infogain vs exact model: {len(models)} weak models (random, 250 "
              f"reaches) x {runs} (moves of 5-30 px), {touches} touches",
              ("method", "runs", "median final px", "under 1 px", "touches to stay < 1 px",
               "never", "worse than plain by > 0.5 px", "90 % disc covers truth",
               "ms / touch (median)", "x plain"))
    for r in rows:
        t.add_row(r["method"], str(r["runs"]), f"{r['median_final_px']:.2f}",
                  f"{100 * r['under_1px']:.0f} %", f"{r['median_touches_stay_1px']:g}",
                  str(r["never_stay_1px"]), str(r["worse_than_plain"]),
                  f"{100 * r['coverage_90']:.0f} %", f"{r['median_ms']:.1f}",
                  f"{r['ms_ratio']:.2f}")
    show_table(con, t)
    names = [m.name for m in models]
    pm = table("median final error per model, px", ("method", *names))
    for r in rows:
        pm.add_row(r["method"], *(f"{r['per_model'][n]:.2f}" for n in names))
    pm.add_row("samples floor", *(f"{floors[n]:.2f}" for n in names))
    show_table(con, pm)
    con.print("samples floor: the shift the model's own training samples pin with the whole "
              "moved keyboard known (kbcli.bench.repair_floor)")
    so = table("final offset per model, px: systematic part / spread", ("method", *names,
               "systematic share of squared error"))
    for r in rows:
        so.add_row(r["method"], *(f"{r['per_model_offset'][n][0]:.2f} / "
                                  f"{r['per_model_offset'][n][1]:.2f}" for n in names),
                   f"{100 * r['systematic_share']:.0f} %")
    show_table(con, so)
    con.print("systematic part: the length of the model's mean final offset (estimate - truth) "
              "over its runs, which more moves or seeds do not average away; spread: the rms "
              "distance of its runs' offsets from that mean")


def _lifelong_table(con, wm, start: float, eps: list, touches: int) -> None:
    t = table(f"lifelong: the {wm.name} model (boundary error {start:.2f} px as learned) "
              f"carried over {len(eps)} moves, {touches} touches each",
              ("move", "dx", "dy", "repair: touches to stay < 1 px", "repair final px",
               "repair, model as learned: touches", "final px",
               "plain: touches to stay < 1 px", "plain final px", "touches absorbed",
               "carried model's boundary error px"), left=0)
    for e in eps:
        t.add_row(str(e.episode), f"{e.truth[0]:+.1f}", f"{e.truth[1]:+.1f}",
                  _stay(e.repair_stay, touches), f"{e.repair_final:.2f}",
                  _stay(e.learned_stay, touches), f"{e.learned_final:.2f}",
                  _stay(e.plain_stay, touches), f"{e.plain_final:.2f}", str(e.absorbed),
                  f"{e.boundary_error:.2f}")
    show_table(con, t)


def _lifelong_models_table(con, models, sections: list, touches: int) -> None:
    from kbcli.bench.repair import lifelong_summary

    n = len(sections[0][1])
    sums = [lifelong_summary(start, eps) for start, eps in sections]
    t = table(f"lifelong, every carried model: {n} moves, {touches} touches each",
              ("model", "boundary error px: as learned, then after each move",
               "moves after which it fell", "repair: touches to stay < 1 px, first move",
               "last move", "later moves ending closer / further than with the model as learned"),
              left=0)
    for wm, s in zip(models, sums, strict=True):
        t.add_row(wm.name, "  ".join(f"{e:.2f}" for e in s["errors"]), f"{s['falls']} of {n}",
                  _stay(s["first_stay"], touches), _stay(s["last_stay"], touches),
                  f"{s['carried_closer']} / {s['carried_further']} of {s['later']}")
    show_table(con, t)
    every = sum(s["falls_every"] for s in sums)
    fewer = sum(s["last_stay"] < s["first_stay"] for s in sums)
    closer = sum(s["carried_closer"] for s in sums)
    further = sum(s["carried_further"] for s in sums)
    con.print(f"the carried model's boundary error fell after every move on {every} of "
              f"{len(sums)} models; the last move needed fewer touches to stay under 1 px than "
              f"the first on {fewer} of {len(sums)}; on the later moves, repair with the carried "
              f"model ended closer to the truth than with the model as learned {closer} times "
              f"and further {further} times, of {sum(s['later'] for s in sums)}")


def _stay(v: int, touches: int) -> str:
    return f">{touches}" if v > touches else str(v)
