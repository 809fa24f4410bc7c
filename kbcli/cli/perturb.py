"""``kbcli perturb``: put the keyboard at a new pose (a scene artifact)."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
import typer

from kbcli.cli import options as opts
from kbcli.cli.app import check_io, command, err, out
from kbcli.core.instrument.transforms import FAMILIES, wrap_degrees
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import perturb as stage


@command(name="perturb")
def perturb_cmd(
    keyboard: opts.keyboard_option("Keyboard artifact (.h5) to move."),
    output: opts.output_option("Scene artifact to write (.h5)."),
    dx: Annotated[float | None, typer.Option("--dx", help="Displacement along x, px.",
                                             show_default="0 when --dy or --angle is given")] = None,
    dy: Annotated[float | None, typer.Option("--dy", help="Displacement along y, px.",
                                             show_default="0 when --dx or --angle is given")] = None,
    angle: Annotated[float | None, typer.Option(
        "--angle", help="Rotation about the keyboard centre, degrees counter-clockwise (makes the "
        "move rigid); wrapped to (-180, 180].", show_default="0 when --dx or --dy is given")] = None,
    category: Annotated[str | None, typer.Option(
        "--category", help="Draw a random move instead: small, medium or large (translation size, "
        "the Euclidean norm, in (0,10], (10,20] or (20,40] px).")] = None,
    family: opts.family_option("translation, rigid with --angle", help="Transform family of the "
                               "move (rigid draws also turn up to 5 degrees)") = None,
    seed: opts.seed_option("Seed of a --category draw.") = 0,
) -> None:
    """Move the keyboard: explicit --dx/--dy [--angle], or a random --category draw.

    Reads KEYBOARD (kind 'keyboard'); writes OUTPUT (kind 'scene', the true pose, for the simulated
    world and the evaluation only); prints the pose. A move that takes any key out of the arm's
    reach is refused (exit 1, nothing written).
    """
    check_io({"--keyboard": keyboard}, ("--output", output))
    explicit = dx is not None or dy is not None or angle is not None
    if explicit and category is not None:
        raise ConfigError("give either --dx/--dy/--angle or --category, not both")
    if not explicit and category is None:
        raise ConfigError("give a displacement (--dx, --dy, optionally --angle) or a --category")
    if family is None:
        family = "rigid" if angle is not None else "translation"
    fam = FAMILIES.get(family)
    if angle is not None and not fam.rotates:
        raise ConfigError(f"--angle makes a rigid move; it cannot be used with --family {family}")
    if angle is not None and math.isfinite(angle):
        wrapped = wrap_degrees(angle)
        if wrapped != angle:
            err.print(f"kbcli: note: --angle {angle:g} is the rotation {wrapped:g} (angles are "
                      f"wrapped to (-180, 180])", markup=False)
        angle = wrapped
    if explicit:
        params = tuple(float(v) for v in fam.compose(angle or 0.0, (dx or 0.0, dy or 0.0)))
        cfg = stage.PerturbConfig(family=family, params=params)
    else:
        cfg = stage.PerturbConfig(family=family, category=category)
    kb_art = read_artifact(keyboard, ("keyboard", "model"))
    art = stage.run(cfg, kb_art, rng=np.random.default_rng(seed), seed=seed)
    write_artifact(art, output)
    pose = ", ".join(f"{k}={v:.2f}" for k, v in art.attrs["pose"].items())
    what = f"{category} {family} draw (seed {seed})" if category else f"{family} move"
    out.print(f"wrote {output}: {what}: {pose}")
