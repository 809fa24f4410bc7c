"""``kbcli animate``: an animated replay (GIF, or MP4 with ffmpeg) of an adaptation or a closed loop."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli import options as opts
from kbcli.cli.app import bench_app, check_io, command, err, out
from kbcli.cli.record import show_table
from kbcli.cli.show import table, wide
from kbcli.io.paths import DEFAULT_MODEL, default_model_path
from kbcli.stages.config import MAX_ADAPT_STEPS


@command(name="animate")
def animate_cmd(
    artifact: Annotated[Path, typer.Argument(help="Run artifact (kbcli adapt, kbcli serve) or "
                                             "closed-loop artifact (kbcli run).")],
    output: opts.output_option("Animation to write: .gif, or .mp4 where ffmpeg is installed.") = Path(
        "run.gif"),
    fps: Annotated[float, typer.Option("--fps", min=0.2, max=30.0,
                                       help="Touches per second.")] = 3.0,
    max_frames: Annotated[int, typer.Option(
        "--max-frames", min=2, help="At most this many touch frames: a long closed loop keeps "
        "every adaptation touch, the touches around the move and the detection, and evenly "
        "spaced play touches.")] = 150,
    dpi: Annotated[int, typer.Option("--dpi", min=40, max=300,
                                     help="Resolution (80: 800 x 448 px).")] = 80,
) -> None:
    """Replay a run touch by touch: the arm, the moved keyboard and the robot's belief of where it
    is, each touch with the sound heard, the posterior evolving, and the entropy and error curves
    (success and detector score for a closed loop).

    Reads ARTIFACT (kind 'run' or 'closed_loop'); writes OUTPUT; prints its path and the number
    of frames. The arm is drawn from the joint angles recorded per touch in dynamics mode (from
    inverse kinematics of the landing point in ideal mode; not at all for an external robot). A
    run stores the posterior at its --snapshots steps: between them the last stored one is shown
    (kbcli adapt --snapshots all stores every step).
    """
    from kbcli.io.artifact import read_artifact
    check_io({"ARTIFACT": artifact}, ("--output", output))
    from kbcli.viz.animate import animate, make_writer  # (matplotlib: seconds)
    make_writer(output.suffix.lower(), fps)  # a bad format or no ffmpeg: fail before reading
    art = read_artifact(artifact, ("run", "closed_loop"))
    n = animate(art, output, fps=fps, max_frames=max_frames, dpi=dpi)
    out.print(f"wrote {output}: {n} frames at {fps:g} per second")


@command(bench_app, name="animate")
def bench_animate_cmd(
    model: opts.model_option("Model artifact the runs adapt with.") = Path(DEFAULT_MODEL),
    repeats: Annotated[int, typer.Option("--repeats", help=opts.at_most(
        "Renders per run (the median is reported)", opts.MAX_REPEATS))] = 3,
    touches: Annotated[int, typer.Option("--touches", help=opts.at_most(
        "Touches of the adaptation", MAX_ADAPT_STEPS))] = 40,
    loop: Annotated[bool, typer.Option("--loop/--no-loop", help="Also render a 600-touch "
                                       "closed loop.")] = True,
) -> None:
    """Seconds to render an adaptation of 40 touches (dynamics mode, the posterior at every step)
    and a closed loop to a GIF (target: 15 s or less on one core).

    Reads MODEL. Writes nothing (renders into a temporary folder). Prints per run the frames, the
    median CPU seconds and wall seconds of the rendering, and the GIF's size.
    """
    from kbcli.bench import animate as bench
    from kbcli.io.artifact import read_artifact

    opts.check_counts(("--repeats", repeats, opts.MAX_REPEATS),
                      ("--touches", touches, MAX_ADAPT_STEPS))
    cfg = bench.BenchConfig(repeats=repeats, touches=touches, loop=loop)
    if model == Path(DEFAULT_MODEL):
        model = default_model_path()
    runs = bench.make_runs(cfg, read_artifact(model, "model"))
    t = table(f"kbcli animate: median of {repeats} renders to GIF (target: a 40-touch run in "
              f"{bench.TARGET_S:g} s or less on one core)",
              ("run", "frames", "CPU s", "wall s", "s per frame (CPU)", "GIF MB"))
    for name, art in runs.items():
        m = bench.measure(art, repeats)
        t.add_row(name, str(m["frames"]), f"{m['cpu_s']:.2f}", f"{m['wall_s']:.2f}",
                  f"{m['cpu_s'] / m['frames']:.3f}", f"{m['mb']:.1f}")
    show_table(wide(120), t)
    err.print("CPU s: process time of the rendering (one thread); wall s includes waiting for "
              "a shared machine; neither includes kbcli's start-up (~2 s)", markup=False)
