"""``kbcli quality``: the model-quality sweep (the paper's Sect. IV-C hypothesis)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli import options as opts
from kbcli.cli.app import check_io, command, err, out
from kbcli.cli.jobs import check_backend, load_checkpoint, note_resumed, run_checkpointed
from kbcli.cli.show import progress, table
from kbcli.errors import ConfigError, KbcliError
from kbcli.io import signals
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.checkpoint import Checkpoint, source_digest
from kbcli.io.config import load_config, load_toml
from kbcli.io.paths import Output, checkout_file
from kbcli.io.runner import Job, execute
from kbcli.stages import quality as stage
from kbcli.stages.config import MAX_BUDGET, MAX_EXPERIMENTS
from kbcli.stages.quality.config import MAX_BUDGETS

DEFAULT_CONFIG = Path("pipelines/model-quality.toml")
DEFAULT_KEYBOARD = Path("data/keyboard.h5")


@command(name="quality")
def quality_cmd(
    output: opts.output_option("model_quality artifact to write (.h5)."),
    config: opts.config_option("TOML with a [quality] table.", optional=False) = DEFAULT_CONFIG,
    keyboard: opts.keyboard_option("Keyboard artifact the models are learned on.") = DEFAULT_KEYBOARD,
    experiments: Annotated[int | None, typer.Option(
        "--experiments", help="Repetitions per displacement, model and row, at most "
        f"{MAX_EXPERIMENTS}.", show_default="the config's")] = None,
    budgets: Annotated[str | None, typer.Option(
        "--budgets", help=f"Reach budgets of the models, comma-separated: at most {MAX_BUDGETS} "
        f"budgets, each at most {MAX_BUDGET}.",
        show_default="the config's")] = None,
    jobs: opts.Jobs = 1,
    scheduler: opts.Scheduler = None,
    resume: Annotated[bool, typer.Option(
        "--resume", help="Continue an interrupted sweep from OUTPUT.ckpt/.")] = False,
    models_dir: Annotated[Path | None, typer.Option(
        "--models", help="Also keep every learned model artifact in this folder (created if "
        "missing).")] = None,
) -> None:
    """Test the paper's Sect. IV-C hypothesis: learn models of every budget and exploration, adapt
    with each, and measure how the strategies' advantage depends on the model's quality.

    Reads the TOML config and KEYBOARD. Writes OUTPUT (kind 'model_quality': every run's error per
    touch; per model, category and row the final error, touches to the model's threshold, the
    advantage over the baseline and its Wilcoxon signed-rank p-value; with `ideal = true`, the
    default, also infogain once with the exact model, and its touches to each model's threshold).
    Learned models and finished adaptations are kept in OUTPUT.ckpt/ while it runs (--resume continues from there). Prints a
    progress bar per phase and a table of the advantage per model; `kbcli report OUTPUT` draws it.
    """
    if config == DEFAULT_CONFIG:
        config = checkout_file(config, "--config")
    if keyboard == DEFAULT_KEYBOARD:
        keyboard = checkout_file(keyboard, "--keyboard")
    ckpt_dir = Checkpoint.beside(output)
    cfg = _load_config(config, experiments, budgets)
    names = tuple(f"{n}.h5" for n, _, _ in stage.model_names(cfg))
    check_io({"--config": config, "--keyboard": keyboard}, ("--output", output),
             Output(ckpt_dir, "checkpoint folder", folder=True, removes=True),
             *((Output(models_dir, "--models folder", folder=True, files=names),)
               if models_dir is not None else ()))
    check_backend(jobs, scheduler)
    kb_art = read_artifact(keyboard, "keyboard")
    fp = {**stage.fingerprint(cfg, kb_art), "source_code": source_digest()}
    ckpt = Checkpoint(ckpt_dir, fp, every=20)
    done = load_checkpoint(ckpt, resume, "model")
    started = time.perf_counter()
    models = _learn_models(cfg, kb_art, ckpt, resume, jobs, scheduler)
    learned_s = time.perf_counter() - started
    tasks, results = _adapt_all(cfg, models, kb_art, ckpt, done, jobs, scheduler)
    art = stage.assemble(cfg, models, tasks, results, kb_art)
    write_artifact(art, output)
    if models_dir is not None:
        models_dir.mkdir(exist_ok=True)
        for name, m in models.items():
            write_artifact(m, models_dir / f"{name}.h5")
    ckpt.remove()
    elapsed = time.perf_counter() - started
    out.print(f"wrote {output}: {len(models)} models, {len(tasks)} adaptations "
              f"({learned_s:.0f} s learning, {elapsed - learned_s:.0f} s adapting)")
    _summary(art)


def _load_config(config: Path, experiments: int | None, budgets: str | None) -> stage.QualityConfig:
    """The [quality] table of ``config`` with the command line's overrides."""
    if "arm" in load_toml(config):  # (adapt reads one; here the sweep's arm is quality.arm)
        raise ConfigError(f"{config}: quality does not read a top-level [arm] table: remove it "
                          "(the sweep's arm is the arm key of [quality])")
    cfg = load_config(stage.QualityConfig, config)
    return cfg.with_overrides(experiments=experiments, budgets=None if budgets is None else
                              opts.comma_list(budgets, "--budgets"))


def _learn_models(cfg, kb_art, ckpt: Checkpoint, resume: bool, jobs: int,
                  scheduler: str | None) -> dict:
    """Phase 1: every model of the sweep, kept as artifacts in the checkpoint folder (those
    already there read back with ``resume``). Ctrl-C says how many are kept and exits 130."""
    model_dir = ckpt.folder / "models"
    ltasks = stage.learn_tasks(cfg)
    models = {}
    for t in ltasks:
        f = model_dir / f"{t.name}.h5"
        if resume and f.is_file():
            models[t.name] = read_artifact(f, "model")
    todo = [i for i, t in enumerate(ltasks) if t.name not in models]
    ctx = {"keyboard": kb_art, "quality": cfg.to_dict()}
    job = Job(setup="kbcli.stages.quality:learn_setup", run="kbcli.stages.quality:learn_one",
              context=ctx, context_key=f"learn-{kb_art.sha256}", tasks=tuple(ltasks))
    try:
        for i, res in progress(execute(job, todo, jobs=jobs, scheduler=scheduler), len(todo),
                               "learning models"):
            art = res["artifact"]
            _keep_model(ckpt, model_dir, ltasks[i].name, art, models, len(ltasks))
    except KeyboardInterrupt as exc:
        msg = (f"{len(models)} of {len(ltasks)} models kept in {model_dir}: rerun with --resume "
               "to continue") if models else f"none of {len(ltasks)} models had finished; " \
            "nothing was kept"
        err.print(f"kbcli: {signals.what(exc)}; {msg}", markup=False)
        raise typer.Exit(signals.exit_code(exc)) from None
    return models


def _keep_model(ckpt: Checkpoint, model_dir: Path, name: str, art, models: dict,
                total: int) -> None:
    """Write one learned model into the checkpoint. A failed write (a full disk) leaves no
    checkpoint when none was kept yet, else says how many are kept and how to resume."""
    fresh = not ckpt.exists()
    try:
        ckpt.start()  # (only now: a run that fails before its first model leaves nothing)
        model_dir.mkdir(exist_ok=True)
        write_artifact(art, model_dir / f"{name}.h5")
    except (KbcliError, OSError) as exc:
        if fresh and not models:
            ckpt.remove()
            raise
        raise KbcliError(f"{exc}; {len(models)} of {total} models kept in {model_dir}: rerun "
                         "with --resume to continue") from None
    models[name] = art


def _adapt_all(cfg, models: dict, kb_art, ckpt: Checkpoint, done: dict, jobs: int,
               scheduler: str | None) -> tuple[list, dict]:
    """Phase 2: every adaptation with every model (those in the checkpoint kept); the tasks and
    the results by task row."""
    tasks = stage.plan(cfg)
    ctx = {"models": models, "quality": cfg.to_dict(), "keyboard": kb_art}
    key = "adapt-" + "-".join(str(models[n].sha256)[:12] for n, _, _ in stage.model_names(cfg))
    job = Job(setup="kbcli.stages.quality:adapt_setup", run="kbcli.stages.quality:adapt_one",
              context=ctx, context_key=key, tasks=tuple(tasks))
    todo = [t.row for t in tasks if t.row not in done]
    note_resumed(done, len(tasks), "adaptations")
    fresh = run_checkpointed(execute(job, todo, jobs=jobs, scheduler=scheduler), len(todo), ckpt,
                             kept=len(done), total=len(tasks), what="adaptations")
    return tasks, {**done, **fresh}


def _summary(art) -> None:
    a = art.attrs
    rows = stage.compared_rows(a)
    t = table(f"advantage over {a['baseline']} (touches saved to tau, all categories; p)",
              ("model", "accuracy", "boundary err", *rows))
    for m, mi in a["models"].items():
        cells = []
        for r in rows:
            s = a["summary"][m]["all"][r]
            cells.append(f"{s['advantage']:+g} ({s['pvalue']:.0e})")
        t.add_row(m, f"{100 * mi['accuracy']:.1f} %", f"{mi['boundary_error']:.2f} px", *cells)
    out.print(t)
    for r in rows:
        out.print(f"{r}: the paper's explanation {stage.verdict(stage.hypothesis(art, r))}",
                  soft_wrap=True)
