"""The repaired model of ``kbcli adapt --repair --model-out`` and ``kbcli run --repair
--model-out`` (issue 42): writing it and saying what it absorbed."""

from __future__ import annotations

from pathlib import Path

from kbcli.cli.app import busy, out
from kbcli.errors import ConfigError
from kbcli.io.artifact import write_artifact
from kbcli.stages import repair as repair_stage


def check_model_out(model_out: Path | None, repair: bool) -> None:
    """``--model-out`` needs the repaired belief."""
    if model_out is not None and not repair:
        raise ConfigError("--model-out writes the model repaired by the adaptation: add --repair "
                          "(or repair = true in the [adapt] table)")


def write_repaired(model_art, model, adaptations, model_out: Path, source: str) -> None:
    """Refit, calibrate and score the repaired model, write it to ``model_out``, say what it
    absorbed and how its boundary error moved (against the simulator's keyboard)."""
    with busy("refitting the repaired model (5-fold cross-validation)"):
        art, s = repair_stage.repaired_model(model_art, model, adaptations, source=source)
    write_artifact(art, model_out)
    before = s["parent_boundary_error_px"]
    moved = (f"boundary error {before:.2f} -> {s['boundary_error_px']:.2f} px"
             if before is not None else f"boundary error {s['boundary_error_px']:.2f} px")
    skipped = (f"; {s['skipped']} adaptation(s) not absorbed (90 % credible radius above "
               f"{repair_stage.ABSORB_RADIUS:g} px)" if s["skipped"] else "")
    out.print(f"wrote {model_out}: generation {s['generation']}, {s['absorbed']} touches absorbed, "
              f"accuracy {100 * s['accuracy']:.2f} %, {moved}{skipped}")
