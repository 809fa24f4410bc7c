"""``kbcli detect`` (failure detection over a play history, Sect. III-C) and ``kbcli bench detect``."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, check_io, command, err, out
from kbcli.cli.record import show_table
from kbcli.cli.show import progress, table
from kbcli.core.config import refused_option
from kbcli.core.detection.detectors import MAX_N_LT, MAX_N_ST, DetectorConfig
from kbcli.core.detection.detectors.bocpd import BocpdOptions
from kbcli.core.detection.detectors.cusum import CusumOptions
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import detect as stage

#: The detector's defaults: its config's, the one source of them.
DEFAULT = DetectorConfig()


@command(name="detect")
def detect_cmd(
    history: Annotated[Path, typer.Argument(help="History artifact (kbcli play).")],
    output: opts.output_option("Detection artifact to write (.h5)."),
    detector: opts.detector_option() = DEFAULT.detector.name,
    n_lt: Annotated[int, typer.Option(
        "--n-lt", help=f"Long-term window N_LT (Eq. 4), at most {MAX_N_LT}.")] = DEFAULT.n_lt,
    n_st: Annotated[int, typer.Option(
        "--n-st", help=f"Short-term window N_ST (Eq. 5), < N_LT and at most {MAX_N_ST}.")] = DEFAULT.n_st,
    threshold: Annotated[float, typer.Option(
        "--threshold", help="Fire when the score (binomial: upper tail of Eq. 6) falls below it; in (0, 1).")] = DEFAULT.threshold,
    shift: Annotated[float | None, typer.Option(
        "--shift", help="cusum: failure-rate increase it is tuned to (p1 = p0 + shift).",
        show_default=str(CusumOptions.model_fields["shift"].default))] = None,
    hazard: Annotated[float | None, typer.Option(
        "--hazard", help="bocpd: prior change probability per step.",
        show_default=str(BocpdOptions.model_fields["hazard"].default))] = None,
) -> None:
    """Run a failure detector online over a play history, one result at a time.

    Reads HISTORY (kind 'history'); writes OUTPUT (kind 'detection': the score per step and the
    firing steps); prints the first firing and, if the history has a perturbation, the delay after
    it (post-move actions seen when it fired) and the false alarms before it.
    """
    check_io({"HISTORY": history}, ("--output", output))
    own = {k: v for k, v in {"shift": shift, "hazard": hazard}.items() if v is not None}
    try:
        cfg = DetectorConfig(detector=detector, n_lt=n_lt, n_st=n_st, threshold=threshold, **own)
    except ConfigError as exc:
        raise refused_option(exc, {k: f"--{k}" for k in own}, "detect", f"detector {detector}") \
            from None
    hist = read_artifact(history, "history")
    art = stage.run(cfg, hist)
    write_artifact(art, output)
    a = art.attrs
    if a["first_firing"] is None:
        msg = f"{detector} never fired in {a['steps']} steps"
    else:
        msg = f"{detector} fired {a['n_firings']} time(s), first at step {a['first_firing']}"
    if a["perturb_at"] is not None:
        if a["detected_at"] is None:
            msg += f"; the move at step {a['perturb_at']} was not detected"
        else:
            msg += (f"; the move at step {a['perturb_at']} was detected at step "
                    f"{a['detected_at']} (delay {a['delay']} actions, {a['false_alarms']} false "
                    "alarm(s) before)")
    out.print(f"wrote {output}: {msg}")


def _fmt(v: float, horizon: int) -> str:
    return f">{horizon}" if math.isinf(v) else f"{v:g}"


@command(bench_app, name="detect")
def bench_detect_cmd(
    p_pre: Annotated[float | None, typer.Option(
        "--p-pre", help="Failure rate before the change (a probability per played note).",
        show_default="the --model's on its reference pose, else 0.01")] = None,
    p_post: Annotated[str | None, typer.Option(
        "--p-post", help="Comma-separated post-change failure rates instead of the displacement "
        "categories (e.g. 0.05,0.2).")] = None,
    model: opts.model_option("Model artifact whose melody player sets the failure rates.",
                             optional=True,
                             show_default="the exact model of the default keyboard") = None,
    streams: opts.count_option("--streams", "Evaluation streams per category",
                               opts.MAX_STREAMS) = 400,
    tune_actions: opts.count_option("--tune-actions", "Change-free actions used to tune every "
                                    "detector", opts.MAX_TUNE_ACTIONS) = 1_000_000,
    horizon: opts.count_option("--horizon", "Post-change actions after which a change counts as "
                               "missed", opts.MAX_HORIZON) = 1000,
    fa_target: Annotated[float, typer.Option(
        "--fa-target", help="False alarms allowed per 10,000 actions when tuning.")] = 1.0,
    n_lt: opts.count_option("--n-lt", "Long-term window of our detectors",
                            MAX_N_LT) = DEFAULT.n_lt,
    n_st: opts.count_option("--n-st", "Short-term window of our detectors",
                            MAX_N_ST) = DEFAULT.n_st,
    detectors: Annotated[str, typer.Option(
        "--detectors", help="Comma-separated subset of binomial,cusum,bocpd,fhddm,ddm,adwin.")] =
        "binomial,cusum,bocpd,fhddm,ddm,adwin",
    seed: opts.seed_option("Seed of the simulation.") = 0,
) -> None:
    """Benchmark the failure detectors against river's FHDDM, DDM and ADWIN on simulated histories.

    Reads an optional MODEL; writes nothing; prints, per displacement category, each detector's
    tuned setting, false alarms per 10,000 pre-change actions, median and 90th-percentile detection
    delay (actions after the change) and missed detections, every detector tuned to at most
    --fa-target false alarms per 10,000 actions on separate streams.
    """
    from kbcli.bench import detect as bench

    opts.check_counts(("--streams", streams, opts.MAX_STREAMS),
                      ("--tune-actions", tune_actions, opts.MAX_TUNE_ACTIONS),
                      ("--horizon", horizon, opts.MAX_HORIZON), ("--n-lt", n_lt, MAX_N_LT),
                      ("--n-st", n_st, MAX_N_ST))
    rng = np.random.default_rng(seed)
    m, kb, p_pre, note = _model_rate(model, p_pre, rng)
    posts = None if p_post is None else opts.comma_list(
        p_post, "--p-post", "comma-separated numbers", float)
    cfg = bench.BenchConfig(
        p_pre=p_pre, p_post=posts, streams=streams, tune_actions=tune_actions, horizon=horizon,
        fa_target=fa_target, n_lt=n_lt, n_st=n_st,
        detectors=tuple(d.strip() for d in detectors.split(",") if d.strip()))
    if any(d in bench.RIVER for d in cfg.detectors):
        bench._river()  # fail early with a clear message if river is missing
    if note:
        err.print(note)
    total = len(cfg.detectors) * (1 + len(posts if posts is not None else cfg.categories))
    t0 = time.perf_counter()
    res = None
    for _, partial in progress(bench.run(cfg, rng=rng, model=m, keyboard=kb), total, "benchmark"):
        res = partial
    elapsed = time.perf_counter() - t0
    _show_results(bench, res, cfg)
    out.print(f"benchmark took {elapsed:.0f} s")


def _show_results(bench, res, cfg) -> None:
    """The benchmark's settings, a table per group and how our detectors compare with river's."""
    wide = Console(width=max(out.width, 110), highlight=False)  # the table needs ~100 columns
    wide.print(f"detection delay = actions after the change until the alarm; p_pre={cfg.p_pre:g}; "
              f"{cfg.streams} streams per category, change at a step in "
              f"[{cfg.change_min}, {cfg.change_max}]; every detector tuned on "
              f"{cfg.tune_actions:,} change-free actions to <= {cfg.fa_target:g} false alarm per "
              f"10,000 (FA tune); FA eval: false alarms per 10,000 pre-change actions of the "
              f"evaluation streams; misses (no alarm within {cfg.horizon}) count as infinite delays")
    for group, g in res.groups.items():
        show_table(wide, _group_table(res, group, g, cfg.horizon))
    for group in res.groups:
        if (line := _verdict(bench, res, group, cfg)) is not None:
            wide.print(line)


def _model_rate(model: Path | None, p_pre: float | None, rng) -> tuple:
    """The model and keyboard of ``--model`` (Nones without one), the pre-change failure rate
    (``--p-pre``, else the model's on its reference pose, else 0.01) and a note on where it came
    from ("" when given)."""
    if model is None:
        return None, None, 0.01 if p_pre is None else p_pre, ""
    from kbcli.core.instrument.melody import DEFAULT_MELODY, parse_melody
    from kbcli.core.playing.play import expected_failure_rate

    _, _, m, kb = opts.read_model(model)
    if p_pre is not None:
        return m, kb, p_pre, ""
    measured = float(expected_failure_rate(
        m, kb, parse_melody(DEFAULT_MELODY, kb), "translation", None, rng=rng,
        n_samples=4000)[0])
    note = (f"p_pre {measured:.4f}: the model's failure rate on the reference pose"
            if measured > 0 else "the model never fails on its reference pose: p_pre 0.01")
    return m, kb, measured if measured > 0 else 0.01, note


def _group_table(res, group: str, g: dict, horizon: int) -> Table:
    """One group's table: each detector's setting, false alarms, delays and misses."""
    t = table(f"{group}: post-change failure rate median {g['median_p_post']:.2f} (10-90%: "
              f"{g['p10']:.2f}-{g['p90']:.2f})", ("detector", "setting", "FA tune", "FA eval",
                                                  "median", "p90", "missed"), left=2, no_wrap=True)
    for r in res.rows:
        if r.group == group:
            t.add_row(r.detector, r.setting, f"{r.tuned_fa:.2f}", f"{r.fa:.2f}",
                      _fmt(r.median, horizon), _fmt(r.p90, horizon), f"{r.missed}/{r.streams}")
    return t


def _verdict(bench, res, group: str, cfg) -> str | None:
    """One line comparing our detectors with the best river one on a group (None when either
    side is missing)."""
    rows = {r.detector: r for r in res.rows if r.group == group}
    river = [r for d, r in rows.items() if d in bench.RIVER and r.tuned_fa <= cfg.fa_target]
    ours = [r for d, r in rows.items() if d in bench.OURS]
    if not river or not ours:
        return None
    best = min(river, key=lambda r: r.median)
    fastest = min(ours, key=lambda r: r.median)
    default = rows.get("binomial")
    msg = f"{group}: best river {best.detector} median {_fmt(best.median, cfg.horizon)}"
    if default is not None:
        verdict = "no worse" if default.median <= best.median else "WORSE"
        msg += f"; binomial {_fmt(default.median, cfg.horizon)} ({verdict})"
    beats = "beats it" if fastest.median < best.median else "does not beat it"
    return msg + f"; our fastest {fastest.detector} {_fmt(fastest.median, cfg.horizon)} ({beats})"
