"""SIGTERM handled like Ctrl-C: the same clean stop, checkpoint kept, exit 143 instead of 130.

:func:`install` makes SIGTERM raise :class:`Terminated`, a :class:`KeyboardInterrupt`, so every
``except KeyboardInterrupt`` that keeps a checkpoint or removes a temporary file also runs on
SIGTERM (what a batch system or ``kill`` sends); :func:`exit_code` gives the shell's convention,
128 plus the signal number. In the ``kbcli`` process itself (:func:`bound_the_stop`, called by
its entry point, never by kbcli used as a library), a clean stop that does not end within
:data:`GRACE_S` seconds (a worker pool that will not shut down) is cut short: the process exits
143 all the same, as a batch system's SIGKILL would end it.
"""

from __future__ import annotations

import os
import signal
import threading
from types import FrameType

#: Exit codes of a run stopped by Ctrl-C (SIGINT) and by SIGTERM: 128 + the signal number.
EXIT_SIGINT = 128 + int(signal.SIGINT)
EXIT_SIGTERM = 128 + int(signal.SIGTERM)


#: Seconds a clean stop after SIGTERM may take before the process exits at once.
GRACE_S = 20.0
_bounded = False


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: stop as on Ctrl-C."""


def _raise(signum: int, frame: FrameType | None) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM kills at once
    if _bounded:
        watchdog = threading.Timer(GRACE_S, os._exit, (EXIT_SIGTERM,))
        watchdog.daemon = True  # a stop that ends in time ends the watchdog with it
        watchdog.start()
    raise Terminated()


def bound_the_stop() -> None:
    """From now on, this process exits 143 at the latest :data:`GRACE_S` seconds after SIGTERM
    (for the process that runs the CLI: it ends after the command anyway)."""
    global _bounded
    _bounded = True


def install() -> object:
    """Make SIGTERM raise :class:`Terminated` in the main thread (no-op elsewhere, or when SIGTERM
    is ignored by the parent, e.g. ``nohup``); returns the handler it replaced (for
    :func:`restore`), or None when nothing changed."""
    if threading.current_thread() is not threading.main_thread():
        return None
    old = signal.getsignal(signal.SIGTERM)
    if old is signal.SIG_IGN:
        return None
    signal.signal(signal.SIGTERM, _raise)
    return signal.SIG_DFL if old is None else old  # (None: a handler not set from Python)


def restore(old: object) -> None:
    """Put back the SIGTERM handler :func:`install` replaced."""
    if old is not None and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, old)


def exit_code(exc: BaseException) -> int:
    """143 for SIGTERM, 130 for Ctrl-C."""
    return EXIT_SIGTERM if isinstance(exc, Terminated) else EXIT_SIGINT


def what(exc: BaseException) -> str:
    """``terminated`` (SIGTERM) or ``interrupted`` (Ctrl-C)."""
    return "terminated" if isinstance(exc, Terminated) else "interrupted"
