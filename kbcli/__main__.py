"""``python -m kbcli``: the same as the ``kbcli`` command.

Loading kbcli's modules takes a few seconds; a Ctrl-C or SIGTERM then (before any command runs,
nothing written yet) ends it with the one line and exit code a command gives (130, 143), not a
traceback of the import or a silent death by the signal.
"""

import os
import signal
import sys


def _stop_while_loading(signum: int, frame: object) -> None:
    sys.stderr.write(f"kbcli: {'terminated' if signum == signal.SIGTERM else 'interrupted'}\n")
    sys.stderr.flush()
    os._exit(128 + signum)


def _load_guarded():
    """Import the CLI with SIGINT and SIGTERM ending it in one line (where they are not ignored);
    their handlers are put back before the command runs (it installs its own)."""
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) in (signal.default_int_handler, signal.SIG_DFL):
            old[sig] = signal.signal(sig, _stop_while_loading)
    try:
        from kbcli.cli import main
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return main


def run() -> None:
    """The ``kbcli`` console script: the CLI, loaded under :func:`_load_guarded`."""
    _load_guarded()()


if __name__ == "__main__":
    run()
