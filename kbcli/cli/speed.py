"""``kbcli bench speed``: the adaptation's time per touch against its targets."""

from __future__ import annotations

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, command
from kbcli.cli.record import show_table, timing_note
from kbcli.cli.show import busy, table, wide
from kbcli.stages.config import MAX_ADAPT_STEPS

#: Repeats of each measure at most.
MAX_REPEATS = 1000


def _touch_rows(adapter_config) -> list:
    """(config, row name) of the per-touch table: the paper's method as the paper writes it, its
    faster named variant, kbcli's default."""
    from kbcli.bench import speed as bench
    return [(bench.paper_config(), "paper-active + kde (the paper method, as written)"),
            (bench.paper_config(simulate_draw="shared"), "paper-active + kde, simulate_draw = "
             "shared (simulations reuse a draw per sound)"),
            (adapter_config(), "infogain + likelihood (kbcli's default)")]


@command(bench_app, name="speed")
def bench_speed_cmd(
    model: opts.model_option("Model artifact.", optional=True,
                             show_default="the embedded default model") = None,
    repeats: opts.count_option("--repeats", "Adaptations per row (each its own seed); the table "
                               "gives medians", MAX_REPEATS) = 5,
    touches: opts.count_option("--touches", "Touches per adaptation", MAX_ADAPT_STEPS, "-T") = 20,
    seed: opts.seed_option("Seed of the adaptations.") = 0,
) -> None:
    """Time the adaptation per touch: the paper's method and kbcli's, and kbcli adapt's posteriors.

    Reads MODEL (default: the embedded default model). Writes nothing. Prints two tables, medians
    over the repeats, on one thread: the robot's time per touch (decide, update, estimate; set-up
    excluded) of the paper's active strategy with the KDE posterior (the paper method's options,
    as the paper writes them, and with simulate_draw = shared: the simulated touches reuse one set
    of samples per sound), of infogain with the likelihood posterior (kbcli's default), and
    which paper-active row meets the 20 ms target; and the adapt stage as
    kbcli adapt runs it with each posterior (infogain, defaults): set-up, median touch, and the
    whole run over its touches (set-up included), with the ratio kde / likelihood.
    """
    from kbcli.bench import speed as bench
    from kbcli.core.adaptation.config import AdapterConfig

    opts.check_counts(("--repeats", repeats, MAX_REPEATS), ("--touches", touches, MAX_ADAPT_STEPS))
    path, art, learned, kb = opts.read_model(model)
    con = wide(160)
    with busy("timing per touch"):
        rows = [bench.touch_times(learned, kb, cfg, name, runs=repeats, touches=touches,
                                  seed=seed) for cfg, name in _touch_rows(AdapterConfig)]
    t = table(f"time per touch on {path}: {repeats} adaptations x {touches} touches per row, "
              "set-up excluded, one thread", ("strategy + posterior", "median CPU ms / touch",
                                              "p90 CPU ms", "median wall ms",
                                              f"<= {bench.TARGET_MS:g} ms (issue 26)"))
    for r in rows:
        meets = ("yes" if r.cpu_ms <= bench.TARGET_MS else "no") \
            if r.name.startswith("paper-active") else ""
        t.add_row(r.name, f"{r.cpu_ms:.1f}", f"{r.cpu_p90:.1f}", f"{r.wall_ms:.1f}", meets)
    show_table(con, t)
    with busy("timing kbcli adapt"):
        arows = [bench.adapt_times(art, kb, p, runs=repeats, touches=touches, seed=seed)
                 for p in ("likelihood", "kde")]
    t = table(f"kbcli adapt --posterior P on {path} (infogain, defaults): {repeats} runs of "
              f"{touches} touches per row, one thread",
              ("posterior", "set-up ms", "median touch ms", "ms / touch, set-up included",
               "CPU ms / touch, set-up included", "vs likelihood"))
    base = arows[0].per_touch_ms
    for r in arows:
        t.add_row(r.posterior, f"{r.setup_ms:.0f}", f"{r.touch_ms:.1f}", f"{r.per_touch_ms:.1f}",
                  f"{r.per_touch_cpu_ms:.1f}", f"{r.per_touch_ms / base:.2f}x")
    show_table(con, t)
    con.print(f"{timing_note()}. Targets (issue 26): paper-active + kde <= {bench.TARGET_MS:g} "
              f"CPU ms per touch (met by: {_met(rows, bench.TARGET_MS)}); kde within 3x of "
              "likelihood, set-up included")


def _met(rows, target: float) -> str:
    """The paper-active rows at or below ``target`` CPU ms per touch, for the closing line."""
    met = [r.name for r in rows if r.name.startswith("paper-active") and r.cpu_ms <= target]
    return "; ".join(met) if met else "none"
