"""``kbcli keyboard`` and ``kbcli plot keyboard``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli.app import FIGURE_HELP, busy, check_io, command, figure_output, out, plot_app
from kbcli.core.keyboard import KeyboardConfig
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import load_toml
from kbcli.stages import keyboard as stage


@command(name="keyboard")
def keyboard_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="Keyboard artifact to write (.h5).")],
    config: Annotated[
        Path | None,
        typer.Option("--config", help="TOML file with a [keyboard] table (e.g. pipelines/keyboard.toml)."),
    ] = None,
    rows: Annotated[int | None, typer.Option(help="Rows of keys [default 4].")] = None,
    cols: Annotated[int | None, typer.Option(help="Columns of keys [default 8].")] = None,
    key_size: Annotated[float | None, typer.Option(help="Side of a square key, px [default 50].")] = None,
    origin_x: Annotated[float | None, typer.Option(help="Pad x of the lower-left corner, px [default 200].")] = None,
    origin_y: Annotated[float | None, typer.Option(help="Pad y of the lower-left corner, px [default 250].")] = None,
    margin: Annotated[float | None, typer.Option(help="Working band around the keyboard, px [default 50].")] = None,
    base_note: Annotated[str | None, typer.Option(help="Note of the bottom-left key [default C3].")] = None,
    scale: Annotated[str | None, typer.Option(help="diatonic, chromatic or pentatonic [default diatonic].")] = None,
    noise: Annotated[float | None, typer.Option("--noise", help="Std of perception noise on pitch and tempo [default 0].")] = None,
    threshold: Annotated[float | None, typer.Option("--threshold", help="Manhattan match threshold, Eq. 2 [default 1.5].")] = None,
) -> None:
    """Build a virtual keyboard and write its artifact.

    Reads an optional TOML config; flags override it. Writes OUTPUT (kind 'keyboard') and prints
    a one-line summary.
    """
    check_io({"--config": config}, ("--output", output))
    values = dict(load_toml(config, "keyboard")) if config is not None else {}
    flags = {
        "rows": rows, "cols": cols, "key_size": key_size, "margin": margin,
        "base_note": base_note, "scale": scale, "noise_std": noise, "match_threshold": threshold,
    }
    values.update({k: v for k, v in flags.items() if v is not None})
    if origin_x is not None or origin_y is not None:
        ox, oy = values.get("origin", KeyboardConfig().origin)
        values["origin"] = (ox if origin_x is None else origin_x, oy if origin_y is None else origin_y)
    cfg = KeyboardConfig.from_dict(values)
    art = stage.run(cfg)
    write_artifact(art, output)
    kb = stage.load(art)
    out.print(f"wrote {output}: {cfg.rows} x {cfg.cols} keys of {cfg.key_size:g} px, "
              f"{kb.names[0]} to {kb.names[-1]}, working area {tuple(round(v) for v in kb.area)}")


@command(plot_app, name="keyboard")
def plot_keyboard_cmd(
    artifact: Annotated[Path, typer.Argument(help="Keyboard artifact (or any artifact made from one).")],
    output: Annotated[Path, typer.Option("-o", "--output", help=FIGURE_HELP)] = Path("keyboard.png"),
) -> None:
    """Draw the keyboard: keys labelled with note and tempo, the working area dashed. Writes the figure (PNG, PDF or SVG by the suffix of -o)."""
    from kbcli.viz.keyboard import plot_keyboard

    check_io({"ARTIFACT": artifact}, figure_output(output))
    art = read_artifact(artifact, "keyboard")
    with busy("drawing"):
        plot_keyboard(stage.load(art), output)
    out.print(f"wrote {output}")
