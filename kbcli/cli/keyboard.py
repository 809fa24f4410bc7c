"""``kbcli keyboard`` and ``kbcli plot keyboard``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from kbcli.cli import options as opts
from kbcli.cli.app import check_io, command, figure_output, out, plot_app
from kbcli.cli.show import busy
from kbcli.core.config import refused_option
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.core.instrument.layouts import MAX_KEYS
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import load_toml, with_file
from kbcli.stages import keyboard as stage

#: The flags of the keyboard, each a field of its config (over the TOML table's); ``--origin-x``
#: and ``--origin-y`` set the two of its ``origin``.
_FLAGS = {
    "layout": opts.layout_option("Layout of the keys. {described}.", show_default="grid"),
    "rows": Annotated[int | None, typer.Option(
        help=f"Rows of keys (grid, hex, pads); rows x cols at most {MAX_KEYS} keys.",
        show_default="4")],
    "cols": Annotated[int | None, typer.Option(
        help=f"Columns of keys (grid, hex, pads); white keys (piano); at most {MAX_KEYS} keys in "
        "all.", show_default="8; piano 12")],
    "key_size": Annotated[float | None, typer.Option(
        help="Key size, px: a square's side (grid), a hexagon's width across the flats (hex), a "
        "white key's width (piano), the distance between pad centres (pads).",
        show_default="50; piano 36")],
    "key_height": Annotated[float | None, typer.Option(
        help="piano: height of the white keys, px.", show_default="160")],
    "black_width": Annotated[float | None, typer.Option(
        help="piano: width of the black keys, px.", show_default="20")],
    "black_height": Annotated[float | None, typer.Option(
        help="piano: height of the black keys, px.", show_default="100")],
    "pad_radius": Annotated[float | None, typer.Option(
        help="pads: radius of a pad, px.", show_default="20")],
    "origin_x": Annotated[float | None, typer.Option(
        help="Pad x of the keyboard's lower-left corner, px.",
        show_default="the keyboard centred on x = 400; grid 200; polygons 0")],
    "origin_y": Annotated[float | None, typer.Option(
        help="Pad y of the keyboard's lower-left corner, px.",
        show_default="centred on y = 350; grid 250; polygons 0")],
    "margin": Annotated[float | None, typer.Option(
        help="Width of the working band around the keyboard, px.", show_default="50")],
    "base_note": Annotated[str | None, typer.Option(
        help="Note of the first key (a name like C3, F#4 or Bb2).", show_default="C3")],
    "scale": Annotated[str | None, typer.Option(
        help="Scale the keys climb: diatonic, chromatic or pentatonic (grid, pads, polygons).",
        show_default="diatonic")],
    "noise_std": Annotated[float | None, typer.Option(
        "--noise", help="Standard deviation of the perception noise on pitch (semitones) and tempo "
        "(bpm).", show_default="0")],
    "match_threshold": Annotated[float | None, typer.Option(
        "--threshold", help="Match threshold (Eq. 2): the largest Manhattan distance, in semitones "
        "plus bpm, between a heard sound and a key's.", show_default="1.5")],
}


@command(name="keyboard")
@opts.with_flags("flags", _FLAGS)
def keyboard_cmd(
    output: opts.output_option("Keyboard artifact to write (.h5)."),
    config: opts.config_option(
        "TOML file with a [keyboard] table (e.g. pipelines/keyboard.toml; pipelines/layouts/*.toml "
        "for the other layouts, polygons' keys included).") = None,
    flags: dict | None = None,
) -> None:
    """Build a virtual keyboard of any layout and write its artifact.

    Reads an optional TOML config; flags override it. Refuses (one line naming the key or option,
    exit 1, nothing written) an unknown layout, overlapping keys, degenerate polygons, keys that
    sound alike (Eq. 2) and keys out of the (default) arm's reach. Writes OUTPUT (kind 'keyboard')
    and prints a one-line summary.
    """
    from kbcli.core.instrument.keyboard import Keyboard
    from kbcli.sim import SimConfig, check_keyboard_reachable

    check_io({"--config": config}, ("--output", output))
    table = dict(load_toml(config, "keyboard")) if config is not None else {}
    flags = dict(flags or {})
    origin_x, origin_y = flags.pop("origin_x", None), flags.pop("origin_y", None)
    if origin_x is not None or origin_y is not None:
        ox, oy = table.get("origin") or with_file(
            KeyboardConfig, {k: v for k, v in table.items() if k != "origin"}, flags, config).origin
        flags["origin"] = (ox if origin_x is None else origin_x, oy if origin_y is None else origin_y)
    labels = {k: "--" + k.replace("_", "-") for k, v in flags.items() if v is not None}
    try:
        cfg = with_file(KeyboardConfig, table, flags, config)
    except ConfigError as exc:  # a layout refusing a flag's option: name the flag
        raise refused_option(exc, labels, "keyboard", "this layout") from None
    check_keyboard_reachable(SimConfig(), Keyboard(cfg))
    art = stage.run(cfg)
    write_artifact(art, output)
    kb = stage.load(art)
    out.print(f"wrote {output}: {cfg.layout.name} layout, {kb.describe()}, working area "
              f"{tuple(round(v) for v in kb.area)}")


@command(plot_app, name="keyboard")
def plot_keyboard_cmd(
    artifact: Annotated[Path, typer.Argument(help="Keyboard artifact (or any artifact made from one).")],
    output: opts.Figure = Path("keyboard.png"),
) -> None:
    """Draw the keyboard (any layout): keys labelled with note and tempo, the working area dashed.
    Writes the figure (PNG, PDF or SVG by the suffix of -o)."""
    check_io({"ARTIFACT": artifact}, figure_output(output))
    from kbcli.viz.keyboard import plot_keyboard  # (matplotlib: seconds)
    art = read_artifact(artifact, "keyboard")
    with busy("drawing"):
        plot_keyboard(stage.load(art), output)
    out.print(f"wrote {output}")
