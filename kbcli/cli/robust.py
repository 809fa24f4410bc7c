"""``kbcli bench robust``: the robust posterior against the plain one on a model."""

from __future__ import annotations

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, command
from kbcli.cli.record import show_table
from kbcli.cli.show import table, ticker, wide
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_EXPERIMENTS


@command(bench_app, name="robust")
def bench_robust_cmd(
    model: opts.model_option("Model artifact (.h5, kind 'model').", optional=True,
                             show_default="the embedded default model") = None,
    experiments: opts.count_option("--experiments", "Runs per category, strategy and posterior",
                                   MAX_EXPERIMENTS) = 30,
    max_steps: opts.count_option("--max-steps", "Touches per run", MAX_ADAPT_STEPS, "-T") = 30,
    strategy: opts.strategies_option("random, active, infogain") = None,
    seed: opts.seed_option("Seed of displacements and runs.") = 0,
) -> None:
    """The robust posterior against the plain one on a model: touches to 1 px, final error, time.

    Reads MODEL (default: the embedded default model). Writes nothing. Prints, for the ideal arm in
    ideal mode and the realistic arm in dynamics mode, per strategy, posterior and category: the
    median touches to an error below 1 px, the median and 90th percentile of the final error, and
    the median wall-clock time of one step and the run's CPU time per touch (setup and reaching
    included); then the CPU time of one translation step of the posterior alone.
    """
    from kbcli.bench import robust as bench

    opts.check_counts(("--experiments", experiments, MAX_EXPERIMENTS),
                      ("--max-steps", max_steps, MAX_ADAPT_STEPS))
    model, _, m, kb = opts.read_model(model)
    strategies = tuple(strategy) if strategy else bench.STRATEGIES
    total = len(bench.SETTINGS) * 3 * len(strategies) * len(bench.POSTERIORS) * experiments
    with ticker(total, "adaptations") as tick:
        rows = bench.run(m, kb, experiments=experiments, max_steps=max_steps, seed=seed,
                         strategies=strategies, progress=tick)
    t = table(f"robust vs plain posterior, {model}: {experiments} runs per row, T = {max_steps}",
              ("mode / arm", "strategy", "posterior", "category", "touches to <1 px",
               "final median", "final p90", "median step ms (wall)",
               "run CPU ms / touch (setup, reaching included)"), left=4)
    for r in rows:
        t.add_row(f"{r.mode} / {r.arm}", r.strategy, r.posterior, r.category,
                  f"{r.touches_1px:g}" if r.touches_1px <= max_steps else f">{max_steps}",
                  f"{r.final_median:.2f}", f"{r.final_p90:.2f}", f"{r.ms_wall:.1f}",
                  f"{r.ms_cpu:.1f}")
    con = wide(160)
    show_table(con, t)
    st = bench.step_time(m, kb, seed=seed)
    con.print("translation step of the posterior alone (update + estimate, CPU ms, median / 90th "
              "percentile of 300 touches; one core with OMP_NUM_THREADS=1): "
              + "; ".join(f"{p} {a:.2f} / {b:.2f}" for p, (a, b) in st.items()) + " (target: robust "
              "<= 5 ms)")
