"""SIGTERM handled like Ctrl-C: the same clean stop, checkpoint kept, exit 143 instead of 130.

:func:`install` makes SIGTERM raise :class:`Terminated`, a :class:`KeyboardInterrupt`, so every
``except KeyboardInterrupt`` that keeps a checkpoint or removes a temporary file also runs on
SIGTERM (what a batch system or ``kill`` sends); :func:`exit_code` gives the shell's convention,
128 plus the signal number. In the ``kbcli`` process itself (:func:`bound_the_stop`, called by
its entry point, never by kbcli used as a library), a stop that Python drops (raised inside a
weakref callback or a ``__del__``) is delivered again, and a clean stop that does not end within
:data:`GRACE_S` seconds (a worker pool that will not shut down) is cut short: the process exits
143 all the same, as a batch system's SIGKILL would end it.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType

#: Exit codes of a run stopped by Ctrl-C (SIGINT) and by SIGTERM: 128 + the signal number.
EXIT_SIGINT = 128 + int(signal.SIGINT)
EXIT_SIGTERM = 128 + int(signal.SIGTERM)


#: Seconds a clean stop after SIGTERM may take before the process exits at once.
GRACE_S = 20.0
#: Seconds after which a stop Python dropped is delivered again.
AGAIN_S = 0.05
_bounded = False  # this process runs the CLI (bound_the_stop)
_heard = False  # a SIGTERM arrived
_again = False  # the handler's next call delivers a dropped stop again, not a second SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: stop as on Ctrl-C."""


def _raise(signum: int, frame: FrameType | None) -> None:
    global _heard, _again
    if not _bounded:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM kills at once
        raise Terminated()
    if _heard and not _again:
        os._exit(EXIT_SIGTERM)  # a second SIGTERM kills at once
    if not _heard:
        _heard = True
        watchdog = threading.Timer(GRACE_S, os._exit, (EXIT_SIGTERM,))
        watchdog.daemon = True  # a stop that ends in time ends the watchdog with it
        watchdog.start()
    _again = False
    raise Terminated()


def _dropped(unraisable) -> None:
    """``sys.unraisablehook``: Python drops an exception raised inside a weakref callback or a
    ``__del__`` (CI saw a SIGTERM lost so, and evaluate ran on); a dropped stop (SIGTERM or
    Ctrl-C) is delivered again, where it can be caught. Anything else goes to the hook this one
    replaced."""
    exc = unraisable.exc_value
    if isinstance(exc, KeyboardInterrupt):
        sig = signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT
        # from another thread, a moment later: delivered here, it would be dropped again
        again = threading.Timer(AGAIN_S, _deliver_again, (sig,))
        again.daemon = True
        again.start()
    else:
        _previous_hook(unraisable)


def _deliver_again(sig: signal.Signals) -> None:
    global _again
    if signal.getsignal(sig) in (_raise, signal.default_int_handler):
        _again = sig == signal.SIGTERM
        # a real signal, to the main thread: it wakes a blocking call there
        signal.pthread_kill(threading.main_thread().ident, sig)


_previous_hook = sys.unraisablehook


def bound_the_stop() -> None:
    """For the process that runs the CLI: from now on a SIGTERM or Ctrl-C dropped by Python is
    delivered again, and the process exits 143 at the latest :data:`GRACE_S` seconds after the
    signal."""
    global _bounded, _previous_hook
    _bounded = True
    if sys.unraisablehook is not _dropped:
        _previous_hook, sys.unraisablehook = sys.unraisablehook, _dropped


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
