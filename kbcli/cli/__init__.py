"""Command-line interface: ``kbcli STAGE ...``. Each module registers the commands of one stage."""

from __future__ import annotations

import importlib

from kbcli.cli.app import app
from kbcli.io import signals

# Each stage's commands live in their own module; importing it registers them on ``app``.
_COMMAND_MODULES = ("keyboard", "inspect", "learn", "perturb", "play", "detect", "adapt", "robust",
                    "run", "evaluate", "report", "serve", "animate", "quality", "speed", "gym",
                    "repair")
for _name in _COMMAND_MODULES:
    try:
        importlib.import_module(f"kbcli.cli.{_name}")
    except ModuleNotFoundError as exc:  # a stage not built yet
        if exc.name != f"kbcli.cli.{_name}":
            raise


def main() -> None:
    """Console-script entry point."""
    signals.bound_the_stop()
    app()


__all__ = ["app", "main"]
