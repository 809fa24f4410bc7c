"""``kbcli evaluate`` (the paper's protocol, Sect. IV-B/C) and ``kbcli bench evaluate``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, check_io, command, out
from kbcli.cli.jobs import check_backend, load_checkpoint, note_resumed, run_checkpointed
from kbcli.cli.record import show_table
from kbcli.cli.show import progress, table
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.errors import ConfigError, KbcliError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.checkpoint import Checkpoint, source_digest
from kbcli.io.config import arm_file, load_arm, load_toml
from kbcli.io.paths import Output, checkout_file, default_model_path
from kbcli.io.runner import Job, execute
from kbcli.stages import evaluate as stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.config import MAX_EXPERIMENTS

DEFAULT_CONFIG = Path("pipelines/paper.toml")


def _load_config(config: Path, experiments: int | None, mode: str | None,
                 methods: list[str] | None = None, arm: str | None = None
                 ) -> stage.EvaluateConfig:
    """The [evaluate] table of ``config`` with the command line's overrides (``arm``: every
    mode's)."""
    if config == DEFAULT_CONFIG:
        config = checkout_file(config, "--config")
    doc = load_toml(config)
    if "arm" in doc:  # (adapt reads one; here each mode has its arm)
        raise ConfigError(f"{config}: evaluate does not read a top-level [arm] table: remove it "
                          "(each mode's arm goes in [evaluate.arm]; --arm sets every mode's)")
    cfg = stage.EvaluateConfig.from_dict(dict(load_toml(config, "evaluate")))
    if FAMILIES.get(cfg.family).rotates:
        for cat in cfg.categories:
            for d in cat.displacements:
                if not -180.0 < float(d[0]) <= 180.0:
                    raise ConfigError(f"{config}: categories.{cat.name}: angle {d[0]:g} is outside "
                                      f"(-180, 180] degrees")
    cfg = cfg.with_overrides(experiments=experiments, mode=mode,
                             methods=tuple(methods) if methods else None)
    if arm is not None:
        arm_cfg = load_arm(arm).to_dict()
        cfg = cfg.replace(arm={m: arm_cfg for m in cfg.modes})
    return cfg


def _job(cfg: stage.EvaluateConfig, model_art, experiment: str) -> Job:
    tasks = stage.plan(cfg)
    ctx = stage.context(cfg, model_art, experiment)
    return Job(setup="kbcli.stages.evaluate:setup", run="kbcli.stages.evaluate:run_experiment",
               context=ctx, context_key=stage.context_key(ctx), tasks=tuple(tasks))


def _summary(art, elapsed: float, n_run: int, step_ms: np.ndarray) -> None:
    base = art.attrs["baseline"]
    thr = art.array("thresholds")
    j = int(np.argmin(np.abs(thr - 4.0)))  # the threshold nearest 4 px
    T = art.attrs["max_steps"]
    exp = art.data["experiments"]
    t = table("evaluation summary", ("mode", "method", "category", "strategy",
                                     f"RMSE at t={T} (px)", f"median obs. to < {thr[j]:g} px",
                                     f"p vs {base} (< {thr[j]:g} px)", "playing success after"),
              left=4, title_justify="center")
    from kbcli.stages.report import ordered

    for m in art.attrs["modes"]:
        for x, c, s, cur in ordered(art, "curves", m):
            med = cur["median_samples"][j]
            p = "" if s == base else f"{art.data['pvalues'][m][x][c][s]['pvalue'][j]:.1e}"
            sel = ((exp["mode"] == m) & (exp["method"] == x) & (exp["category"] == c)
                   & (exp["strategy"] == s))
            play = exp["play_adapted"][sel]
            ptxt = "" if np.isnan(play).all() else f"{100 * np.nanmedian(play):.1f} %"
            t.add_row(m, x, c, s, f"{cur['rmse'][-1]:.2f}",
                      f">{T}" if np.isnan(med) else f"{med:g}", p, ptxt)
    out.print(t)
    if n_run:
        med = float(np.median(step_ms)) if len(step_ms) else float("nan")
        out.print(f"ran {n_run} experiments in {elapsed:.1f} s ({n_run / max(elapsed, 1e-9):.2f}/s); "
                  f"median {med:.2f} ms per step")


@command(name="evaluate")
def evaluate_cmd(
    output: opts.output_option("Evaluation artifact to write (.h5)."),
    model: opts.model_option("Model artifact (.h5, kind 'model') to adapt with.", optional=True,
                             show_default="the embedded default model, data/default-model.h5"
                             ) = None,
    config: opts.config_option("TOML with an [evaluate] table.", optional=False) = DEFAULT_CONFIG,
    method: Annotated[list[str] | None, typer.Option(
        "--method", help="Only this method of the config (repeat for several).",
        show_default="all")] = None,
    experiments: Annotated[int | None, typer.Option(
        "--experiments", help="Repetitions per parametrization, strategy and mode, at most "
        f"{MAX_EXPERIMENTS}.", show_default="the config's")] = None,
    mode: opts.mode_option("the config's modes", help="Only this mode") = None,
    arm: opts.arm_option("the config's [evaluate.arm] per mode", optional=True) = None,
    jobs: opts.Jobs = 1,
    scheduler: opts.Scheduler = None,
    resume: Annotated[bool, typer.Option(
        "--resume", help="Continue an interrupted run from its checkpoint OUTPUT.ckpt.")] = False,
    checkpoint_every: Annotated[int, typer.Option(
        "--checkpoint-every", help="Save finished experiments to OUTPUT.ckpt after this many (more "
        "than the experiments: only at the end).")] = 10,
) -> None:
    """Run the paper's evaluation protocol: every displacement x method x strategy x mode, N times.

    Reads the TOML config (its [evaluate.methods.NAME] tables name the methods: 'paper', the
    paper's KDE posterior, maximum-likelihood estimate, random and active; 'kbcli', ours) and the
    model artifact. Writes OUTPUT (kind 'evaluation': errors and entropy per step, RMSE curves,
    observations to thresholds, tie-corrected Mann-Whitney p-values, measured playing success, the
    experiment table, example posteriors, every resolved option of every method). While running,
    finished experiments are kept in OUTPUT.ckpt/ (removed once OUTPUT is written); --resume
    continues from there. Prints a progress bar, then a table of final RMSE, median observations,
    p-values and playing success, and the speed.
    """
    model = default_model_path() if model is None else model
    if config == DEFAULT_CONFIG:
        config = checkout_file(config, "--config")
    check_io({"--model": model, "--config": config, "--arm": arm_file(arm)}, ("--output", output),
             Output(Checkpoint.beside(output), "checkpoint folder", folder=True, removes=True))
    cfg = _load_config(config, experiments, mode, method, arm)
    check_backend(jobs, scheduler, " (the cluster sets the workers)")
    if checkpoint_every < 1:
        raise ConfigError(f"--checkpoint-every must be >= 1, got {checkpoint_every}")
    model_art = read_artifact(model, "model")
    keyboard = keyboard_stage.load(model_art)
    job = _job(cfg, model_art, stage.EXPERIMENT)
    tasks = list(job.tasks)
    fingerprint = {**stage.fingerprint(cfg, model_art, stage.EXPERIMENT),
                   "source_code": source_digest()}
    ckpt = Checkpoint(Checkpoint.beside(output), fingerprint, every=checkpoint_every)
    done = load_checkpoint(ckpt, resume, "experiment")
    note_resumed(done, len(tasks), "experiments")
    fresh, elapsed = _run(job, done, ckpt, jobs, scheduler)
    art = stage.assemble(cfg, tasks, {**done, **fresh}, model_art, keyboard)
    _write(art, output, ckpt, len(tasks))
    out.print(f"wrote {output}: {len(tasks)} experiments ({', '.join(cfg.modes)}; methods "
              + ", ".join(f"{m.name} ({', '.join(m.strategies)})" for m in cfg.methods) + ")")
    _summary(art, elapsed, len(fresh), stage.timing(fresh))


def _run(job: Job, done: dict, ckpt: Checkpoint, jobs: int, scheduler: str | None
         ) -> tuple[dict, float]:
    """Run the experiments not ``done`` into the checkpoint: their results, and the seconds."""
    todo = [t.row for t in job.tasks if t.row not in done]
    started = time.perf_counter()
    fresh = run_checkpointed(execute(job, todo, jobs=jobs, scheduler=scheduler), len(todo), ckpt,
                             kept=len(done), total=len(job.tasks), what="experiments")
    return fresh, time.perf_counter() - started


def _write(art, output: Path, ckpt: Checkpoint, n: int) -> None:
    """Write the evaluation of ``n`` experiments, then remove their checkpoint; a failed write (a
    full disk) keeps the checkpoint and says how to write it."""
    try:
        write_artifact(art, output)
    except KbcliError as exc:
        hint = (f"; all {n} experiments are kept in {ckpt.folder}: rerun with --resume "
                "to write it" if ckpt.exists() else "")
        raise KbcliError(f"{exc}{hint}") from None
    ckpt.remove()


@command(bench_app, name="evaluate")
def bench_evaluate_cmd(
    config: opts.config_option("TOML with an [evaluate] table.", optional=False) = DEFAULT_CONFIG,
    model: opts.model_option("Model artifact (.h5, kind 'model').", optional=True,
                             show_default="the exact model of the config's keyboard") = None,
    experiments: opts.count_option("--experiments", "Repetitions per parametrization and strategy",
                                   MAX_EXPERIMENTS) = 2,
    mode: opts.mode_option() = "ideal",
    workers: Annotated[int, typer.Option("--workers", help="Workers of the parallel backends; at "
                                         "most the number of cores this process may use (more "
                                         "is capped, with a note).")] = 2,
) -> None:
    """Benchmark the execution backends on a slice of the protocol.

    Reads the config (and the model, if given; otherwise the exact model of the default 4 x 8
    keyboard). Writes nothing. Prints experiments per second serially, with WORKERS local processes
    and through a WORKERS-worker Dask LocalCluster on loopback (start-up included), and whether
    every backend gave bit-identical results.
    """
    cfg = _load_config(config, experiments, mode)
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    workers = opts.cap_workers(workers, "--workers")
    if model is not None:
        model_art = read_artifact(model, "model")
    else:
        from kbcli.core.instrument.keyboard import KeyboardConfig
        from kbcli.stages.models import exact_artifact

        model_art = exact_artifact(keyboard_stage.run(KeyboardConfig()))
    job = _job(cfg, model_art, stage.EXPERIMENT)
    n = len(job.tasks)
    rows = _time_backends(job, workers)
    ref = rows[0][-1]

    def same(res: dict) -> bool:
        return all(np.array_equal(res[i][k], ref[i][k], equal_nan=True)
                   for i in ref for k in stage.STEP_KEYS)

    t = table(f"kbcli evaluate backends: {n} experiments ({mode}, {cfg.max_steps} steps, "
              f"{model_art.config.get('strategy')} model)", ("backend", "wall s", "start-up s",
                                                            "exp/s", "exp/s after start-up",
                                                            "same as serial"),
              title_justify="center")
    for label, secs, startup, steady, res in rows:
        t.add_row(label, f"{secs:.1f}", f"{startup:.1f}", f"{n / secs:.2f}", f"{steady:.2f}",
                      "yes" if same(res) else "NO")
    show_table(out, t)
    out.print("start-up: until the first result (process spawn, imports, model raster; for Dask "
              "also starting the LocalCluster on loopback)")
    if not all(same(r[-1]) for r in rows):
        raise KbcliError("the backends gave different results")


def _time_backends(job: Job, workers: int) -> list[tuple[str, float, float, float, dict]]:
    """Run ``job``'s experiments serially, on ``workers`` local processes and on a Dask
    LocalCluster of ``workers`` on loopback: per backend its label, wall seconds, seconds to the
    first result (start-up), experiments per second after it, and the results by index."""
    n = len(job.tasks)
    rows: list[tuple[str, float, float, float, dict]] = []

    def timed(label: str, extra_startup: float = 0.0, **kw) -> None:
        t0 = time.perf_counter()
        res: dict = {}
        first = last = t0
        for i, r in progress(execute(job, range(n), **kw), n, label):
            last = time.perf_counter()
            if not res:
                first = last
            res[i] = r
        steady = (n - 1) / (last - first) if n > 1 and last > first else float("nan")
        rows.append((label, last - t0 + extra_startup, first - t0 + extra_startup, steady, res))

    timed("serial", jobs=1)
    timed(f"loky, {workers} processes", jobs=workers)
    from dask.distributed import LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        timed(f"dask, {workers} workers", time.perf_counter() - t0,
              scheduler=cluster.scheduler_address)
    return rows
