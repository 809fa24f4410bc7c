"""``kbcli animate``: an animated replay (GIF, or MP4 with ffmpeg) of an adaptation or a closed loop."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli.app import command, out, output_path


@command(name="animate")
def animate_cmd(
    artifact: Annotated[Path, typer.Argument(help="Run artifact (kbcli adapt, kbcli serve) or "
                                             "closed-loop artifact (kbcli run).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Animation to write: .gif, or "
                                         ".mp4 where ffmpeg is installed.")] = Path("run.gif"),
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
    from kbcli.viz.animate import animate, make_writer

    make_writer(output.suffix.lower(), fps)  # a bad format or no ffmpeg: fail before reading
    art = read_artifact(artifact, ("run", "closed_loop"))
    output_path(output)
    if output.resolve() == artifact.resolve():
        from kbcli.errors import KbcliError

        raise KbcliError(f"{output}: is the input artifact; write the animation elsewhere")
    n = animate(art, output, fps=fps, max_frames=max_frames, dpi=dpi)
    out.print(f"wrote {output}: {n} frames at {fps:g} per second")
