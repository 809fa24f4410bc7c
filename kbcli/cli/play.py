"""``kbcli play`` (Algorithm 1, optional WAV of what was heard) and ``kbcli plot play``."""

from __future__ import annotations

import io
import wave
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from kbcli.cli import options as opts
from kbcli.cli.app import check_io, command, figure_output, note_arm, out, plot_app
from kbcli.cli.show import busy, drain
from kbcli.core.instrument.audio import SAMPLE_RATE, to_pcm16
from kbcli.core.instrument.melody import DEFAULT_MELODY, MAX_BEATS, MAX_NOTES, parse_melody
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import arm_file, load_arm
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import play as stage

#: Longest WAV ``play --wav`` writes, seconds (about 53 MB of 16-bit mono at 22,050 Hz).
MAX_WAV_SECONDS = 1200.0


def wav_seconds_bound(melody_text: str, keyboard, steps: int) -> float:
    """Upper bound on the WAV length of ``steps`` notes of a melody, seconds: every note at the
    keyboard's slowest tempo (a wrong key or a silence never lasts longer than that)."""
    melody = parse_melody(melody_text, keyboard)
    beats = np.asarray(melody.durations, float)
    cycles, rest = divmod(int(steps), len(beats))
    total = cycles * beats.sum() + beats[:rest].sum()
    slowest = float(np.min(np.asarray(keyboard.features, float)[:, 1]))
    return float(total * 60.0 / max(slowest, 1e-9))


def wav_bytes(samples: np.ndarray, sample_rate: int) -> bytes:
    """Mono 16-bit PCM as the bytes of a WAV file."""
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(sample_rate)
        w.writeframes(to_pcm16(samples))
    return buf.getvalue()


@command(name="play")
def play_cmd(
    model: opts.model_option(),
    output: opts.output_option("History artifact to write (.h5)."),
    scene: Annotated[Path | None, typer.Option(
        "--scene", help="Scene artifact (kbcli perturb): where the keyboard moves at --perturb-at.")] = None,
    melody: Annotated[str, typer.Option(
        "--melody", help=f"Notes NOTE:BEATS, looped (the paper's Fig. 3 example by default); at "
        f"most {MAX_NOTES} notes of at most {MAX_BEATS:g} beats each.")] = DEFAULT_MELODY,
    steps: Annotated[int, typer.Option(
        "--steps", help=f"Number of actions, at most {stage.MAX_PLAY_STEPS}.")] = 300,
    perturb_at: Annotated[int | None, typer.Option(
        "--perturb-at", help="Touches after which the keyboard moves (with --scene), fewer than "
        "--steps.", show_default="half of --steps")] = None,
    mode: opts.mode_option() = "ideal",
    reach_noise: opts.ReachNoise = 0.0,
    arm: opts.arm_option() = "ideal",
    seed: opts.Seed = 0,
    wav: Annotated[Path | None, typer.Option(
        "--wav", help=f"Also write what was heard as a WAV file (silence where the finger "
        f"missed); at most {MAX_WAV_SECONDS / 60:g} minutes: --steps notes at the keyboard's "
        f"slowest tempo.")] = None,
) -> None:
    """Play a melody in a loop with a model; the keyboard moves at --perturb-at (Algorithm 1).

    Reads MODEL (kind 'model') and optionally SCENE (kind 'scene'); writes OUTPUT (kind 'history':
    actions, landing points, heard features, aimed notes, MATCH/NO_MATCH per step) and optionally a
    WAV; prints the failure rates before and after the move.
    """
    check_io({"--model": model, "--scene": scene, "--arm": arm_file(arm)}, ("--output", output),
             ("--wav", wav))
    cfg = stage.PlayConfig(melody=melody, steps=steps, perturb_at=perturb_at, mode=mode,
                           reach_noise=reach_noise, arm=load_arm(arm))
    model_art = read_artifact(model, "model")
    scene_art = read_artifact(scene, "scene") if scene is not None else None
    if wav is not None:
        _check_wav(melody, keyboard_stage.load(model_art), steps)
    session = stage.Session(cfg, model_art, scene_art, rng=np.random.default_rng(seed), seed=seed)
    note_arm(cfg.arm, cfg.mode)
    drain(session, cfg.steps, "playing")
    art = session.artifact()
    samples, also = None, []
    if wav is not None:
        samples = stage.heard_audio(art, session.keyboard.features, sample_rate=SAMPLE_RATE)
        also = [(wav, wav_bytes(samples, SAMPLE_RATE))]
    write_artifact(art, output, also=also)  # both files or neither
    _report_play(art.attrs, output)
    if samples is not None:
        out.print(f"wrote {wav}: {len(samples) / SAMPLE_RATE:.1f} s of what the robot heard")


def _check_wav(melody: str, keyboard, steps: int) -> None:
    """Refuse, before playing, a ``--wav`` that could outgrow :data:`MAX_WAV_SECONDS`."""
    longest = wav_seconds_bound(melody, keyboard, steps)
    if longest > MAX_WAV_SECONDS:
        raise ConfigError(
            f"--wav: {steps} notes of this melody may last up to {longest:,.0f} s, more than "
            f"the {MAX_WAV_SECONDS:g} s a WAV may hold: play fewer --steps or shorter notes")


def _report_play(a: dict, output: Path) -> None:
    """The history written: its actions, NO_MATCHes and the failure rates around the move."""
    def rate(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.3f}"

    msg = f"wrote {output}: {a['steps']} actions, {a['no_match']} NO_MATCH"
    if a["perturb_at"] is not None:
        msg += (f"; failure rate {rate(a['failure_rate_before'])} before the move at step "
                f"{a['perturb_at']}, {rate(a['failure_rate_after'])} after")
    else:
        msg += f"; failure rate {rate(a['failure_rate_before'])}"
    out.print(msg)


@command(plot_app, name="play")
def plot_play_cmd(
    history: Annotated[Path, typer.Argument(help="History artifact (kbcli play).")],
    detection: Annotated[Path | None, typer.Option(
        "--detection", help="Detection artifact (kbcli detect) to mark where the detector fired.")] = None,
    output: opts.Figure = Path("play.png"),
) -> None:
    """Draw a play history: aimed note and result per step, running success rate, the move, and
    (with --detection) the detector's score and firings. Reads HISTORY; writes the figure (PNG, PDF or SVG by the suffix of -o)."""
    check_io({"HISTORY": history, "--detection": detection}, figure_output(output))
    from kbcli.viz.play import plot_play  # (matplotlib: seconds)
    hist = read_artifact(history, "history")
    det = read_artifact(detection, "detection") if detection is not None else None
    if det is not None and det.inputs.get("history", {}).get("sha256") not in (None, hist.sha256):
        raise ConfigError(f"{detection} was computed on another history than {history}")
    with busy("drawing"):
        plot_play(hist, output, det)
    out.print(f"wrote {output}")
