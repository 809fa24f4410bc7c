"""``kbcli run`` (the closed loop: play, detect, adapt, resume) and ``kbcli plot run``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from kbcli.cli import options as opts
from kbcli.cli.app import (
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
from kbcli.cli.repair import check_model_out, write_repaired
from kbcli.cli.show import busy, drain
from kbcli.core.adaptation.config import refuse_inactive
from kbcli.core.config import refused_option
from kbcli.core.detection.detectors import MAX_N_LT, MAX_N_ST, DetectorConfig
from kbcli.core.instrument.melody import DEFAULT_MELODY
from kbcli.core.instrument.transforms import DEFAULT_FAMILY
from kbcli.core.playing.loop import PLAY
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import arm_file, load_arm
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import repair as repair_stage
from kbcli.stages import run as stage
from kbcli.stages.adapt import AdaptConfig
from kbcli.stages.config import MAX_ADAPT_STEPS

#: The detector's defaults: its config's, the one source of them.
DEFAULT = DetectorConfig()


#: Success before the move below which ``run`` says the model is weak.
WEAK_MODEL = 0.95


def _pct(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:.1f}%"


@command(name="run")
@with_paper_flags
def run_cmd(
    model: opts.model_option("Model artifact (kind 'model'), e.g. data/default-model.h5."),
    scene: Annotated[Path, typer.Option("--scene", help="Scene artifact (kbcli perturb): where the keyboard moves.")],
    output: opts.output_option("Closed-loop artifact to write (.h5)."),
    melody: Annotated[str, typer.Option(help="Notes NOTE:BEATS, looped.")] = DEFAULT_MELODY,
    steps: Annotated[int, typer.Option(
        help=f"Play touches (adaptation touches come on top), at most {stage.MAX_LOOP_STEPS}.")] = 600,
    perturb_at: Annotated[int, typer.Option(
        help="Touches after which the keyboard moves, fewer than --steps.")] = 200,
    strategy: opts.strategy_option() = "infogain",
    posterior: opts.posterior_option() = "likelihood",
    estimator: opts.estimator_option() = None,
    family: opts.family_option("the scene's family") = None,
    mode: opts.mode_option() = "ideal",
    reach_noise: opts.ReachNoise = 0.0,
    arm: opts.arm_option() = "ideal",
    max_adapt_steps: Annotated[int, typer.Option(
        help=f"Touches at most per adaptation (at most {MAX_ADAPT_STEPS}).")] = 40,
    repair: opts.Repair = None,
    model_out: opts.ModelOut = None,
    detector: opts.detector_option() = DEFAULT.detector.name,
    n_lt: Annotated[int, typer.Option(
        help=f"Detector long-term window N_LT, at most {MAX_N_LT}.")] = DEFAULT.n_lt,
    n_st: Annotated[int, typer.Option(
        help=f"Detector short-term window N_ST, at most {MAX_N_ST}.")] = DEFAULT.n_st,
    threshold: Annotated[float, typer.Option(help="Detector threshold, in (0, 1).")] = DEFAULT.threshold,
    paper_flags: dict | None = None,
    seed: opts.Seed = 0,
) -> None:
    """Play, notice the move, adapt, resume: the closed loop as the robot lives it.

    Reads MODEL and SCENE; the keyboard moves to the scene's pose after --perturb-at touches (the
    robot is not told). Writes OUTPUT (kind 'closed_loop': every touch with its phase, result and
    detector score) and prints the success rate before the move, after it, and after adaptation.
    With --repair --model-out, also writes the model repaired by the adaptations' touches.
    """
    check_io({"--model": model, "--scene": scene, "--arm": arm_file(arm)}, ("--output", output),
             ("--model-out", model_out))
    check_model_out(model_out, bool(repair))
    model_art = read_artifact(model, "model")
    scene_art = read_artifact(scene, "scene")
    scene_family = family is None  # like adapt: estimate what the scene moved (rigid: an angle)
    family = scene_art.config.get("family", "translation") if scene_family else family
    adapt = _adapt_config({"strategy": strategy, "posterior": posterior, "family": family,
                           "mode": mode, "reach_noise": reach_noise, "arm": load_arm(arm)},
                          {"estimator": estimator, "repair": repair, **(paper_flags or {})})
    cfg = stage.LoopConfig(
        melody=melody, steps=steps, perturb_at=perturb_at, max_adapt_steps=max_adapt_steps,
        detector=DetectorConfig(detector=detector, n_lt=n_lt, n_st=n_st, threshold=threshold),
        adapt=adapt)
    session = stage.LoopSession(cfg, model_art, scene_art, rng=np.random.default_rng(seed), seed=seed)
    art = _live(session, cfg)
    write_artifact(art, output)
    if scene_family and family != DEFAULT_FAMILY:  # (said once the inputs passed every check)
        note_default("family", family, "the scene's (--family to choose)")
    _report_loop(art.attrs, output)
    if model_out is not None:
        adaptations = repair_stage.session_adaptations(session.steps, session.model)
        write_repaired(model_art, session.model, adaptations, model_out, "run")


def _adapt_config(flags: dict, given: dict) -> AdaptConfig:
    """The loop's adapter, stopping at the rules: the run's ``flags`` and the robot options
    ``given`` (those not None); an option the method does not read is refused, naming its flag."""
    try:
        adapt = AdaptConfig.flat(**flags, stop=True,
                                 **{k: v for k, v in given.items() if v is not None})
    except ConfigError as exc:
        raise refused_option(exc, robot_given(given), "run") from None
    refuse_inactive(adapt.robot, robot_given(given), "run")
    return adapt


def _live(session, cfg: stage.LoopConfig):
    """The closed loop's artifact, once run behind a progress bar of its play touches that names
    each adaptation touch as it comes."""
    note_arm(cfg.adapt.arm, cfg.adapt.mode)
    adapting = [0]

    def describe(s) -> str:
        if s.phase == PLAY:
            return "playing, touches"
        adapting[0] += 1
        return f"adapting (touch {adapting[0]}); play touches"

    drain(session, cfg.steps, "playing, touches", advance=lambda s: 1 if s.phase == PLAY else 0,
          describe=describe)
    return session.artifact()


def _report_loop(a: dict, output: Path) -> None:
    """What the session measured: success before, after the move, after adaptation; the
    detection and the adaptation."""
    out.print(f"wrote {output}")
    out.print(f"success before the move {_pct(a['success_before'])}, after it "
              f"{_pct(a['success_after_perturbation'])}, after adaptation "
              f"{_pct(a['success_after_adaptation'])}")
    true = ", ".join(f"{k} {v:+.2f}" for k, v in a["truth"].items())
    moved = a["perturbed_at"]
    if a["detected_at"] is None:
        out.print("the detector did not fire after the move")
    end = None  # the last touch of the previous adaptation
    for i, ad in enumerate(a.get("adaptation_list", []), 1):
        corr = ", ".join(f"{k} {v:+.2f}" for k, v in ad["correction"].items())
        if ad["fired_at"] < moved:
            when = "before the move: a false alarm"
        elif end is None or end < moved:
            when = f"{ad['fired_at'] - moved + 1} touches after the move"
        else:
            when = f"again, {ad['fired_at'] - end} touches after adaptation {i - 1}"
        end = ad["first"] + ad["touches"] - 1
        out.print(f"adaptation {i}: the detector fired at touch {ad['fired_at']} ({when}); "
                  f"{ad['touches']} touches: estimate {corr} (truth {true}, error "
                  f"{ad['error_px']:.2f} px)")
    before = a["success_before"]
    if before is not None and before < WEAK_MODEL:
        err.print(f"kbcli: note: the model plays only {_pct(before)} of its notes right before "
                  "anything moved: a weak model (learn it with more reaches, kbcli learn "
                  "--budget); its misses look like a move to the detector", markup=False)
    if len(a.get("adaptation_list", [])) > 1:
        out.print(f"{len(a['adaptation_list'])} adaptations, {a['adapt_touches']} touches in all; "
                  "the last one's estimate is in force at the end")


@command(plot_app, name="run")
def plot_run_cmd(
    artifact: Annotated[Path, typer.Argument(help="Closed-loop artifact (kbcli run).")],
    output: opts.Figure = Path("run.png"),
) -> None:
    """Draw a closed-loop session: success over time, the move, the detection, the adaptation
    touches on the keyboard. Writes the figure (PNG, PDF or SVG by the suffix of -o)."""
    check_io({"ARTIFACT": artifact}, figure_output(output))
    from kbcli.viz.loop import plot_loop  # (matplotlib: seconds)
    art = read_artifact(artifact, "closed_loop")
    with busy("drawing"):
        plot_loop(art.data["steps"], art.attrs, keyboard_stage.load(art), output, config=art.config)
    out.print(f"wrote {output}")
