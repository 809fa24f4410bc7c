"""``kbcli serve``: adapt with a robot in another process, JSON lines over stdin/stdout or a socket.

The protocol lives in :mod:`kbcli.stages.serve`; this module moves its lines. Stdout carries the
protocol only (every human message goes to stderr). The session is written atomically after every
touch, so a robot that disconnects, a Ctrl-C or a kill leaves a valid ``run`` artifact of the
touches so far.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import sys
from pathlib import Path
from typing import Annotated, BinaryIO

import typer

from kbcli.cli import options as opts
from kbcli.cli.app import check_io, command, err
from kbcli.io.signals import Terminated
from kbcli.stages.serve import MAX_SERVE_STEPS

_HELP = """Adapt with a robot in another process: JSON lines on stdin/stdout (or a local socket).

Reads MODEL (kind 'model'). kbcli decides where to touch; the robot touches, and tells what it
heard and where it felt it landed; kbcli answers with the next action, its estimate of the
keyboard's displacement and whether to stop. Writes OUTPUT (kind 'run', the same as kbcli adapt
writes, with the errors unknown: NaN) after every touch, so a robot that disconnects leaves a valid
artifact of the touches so far; 'kbcli plot adapt' and 'kbcli animate' read it. Messages on
stderr; stdout carries the protocol only.

\b
Protocol 1, one JSON object per line each way. kbcli first sends:
  {"type": "hello", "protocol": 1, "features": ["pitch", "tempo"], "area": [x0, y0, x1, y1],
   "family": "translation", "parameters": ["dx", "dy"], "max_steps": 40, "step": 0,
   "action": [x, y], "estimate": {"dx": 0, "dy": 0}, "entropy": 10.4, "mass": 0, "done": false}
The robot, per touch ("op" may be left out):
  {"op": "observe", "heard": [pitch, tempo] | null, "felt": [x, y] | null, "action": [x, y],
   "id": any}
  heard: the perceived features, null for silence (required); felt: where the finger landed, pad
  px (optional: without it the aim is used, set --blur); action: where it aimed (optional: the
  suggested action; must be in the working area); id: echoed back.
kbcli answers:
  {"type": "step", "step": 1, "class": 13, "sound": "A4 106 bpm", "estimate": {"dx": 11.9,
   "dy": -7.1}, "entropy": 2.3, "mass": 0.81, "done": false, "action": [x, y] | null}
  done: stop touching (stopping rule with --stop, or --max-steps touches); action: the next touch
  (null after --max-steps touches).
Also: {"op": "suggest"} (the pending action), {"op": "state"} (estimate, done, action),
{"op": "end"} (write the artifact, reply {"type": "bye", "steps": n, "file": ...}, exit).
A bad message (not JSON, unknown op or field, non-numeric features, an action outside the
working area, a touch beyond --max-steps) gets {"type": "error", "error": "..."}; the session
goes on. End of input or a closed socket ends the session (exit 0); Ctrl-C exits 130; both write
the artifact first.
"""


def _listen(socket_path: Path | None, host: str, port: int | None) -> tuple[socket.socket, str]:
    """A socket listening for one robot (a Unix socket at ``socket_path``, else TCP on
    ``host:port``) and where, as said on stderr."""
    from kbcli.errors import KbcliError

    if socket_path is not None:
        if socket_path.exists() or socket_path.is_symlink():
            raise KbcliError(f"{socket_path}: already exists (a file or a socket in use); remove "
                             f"it or choose another --socket path")
        srv, address = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM), str(socket_path)
        refusal = f"{socket_path}: cannot listen"
    else:
        srv, address = socket.socket(socket.AF_INET, socket.SOCK_STREAM), (host, port)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        refusal = f"cannot listen on {host}:{port}"
    try:
        srv.bind(address)
    except OSError as exc:
        srv.close()
        raise KbcliError(f"{refusal} ({exc.strerror})") from None
    srv.listen(1)
    if socket_path is not None:
        return srv, f"unix:{socket_path}"
    return srv, f"tcp:{host}:{srv.getsockname()[1]}"


_Terminated = Terminated  # SIGTERM, handled like Ctrl-C (the artifact is written first; exit 143)


def _on_sigterm(signum, frame) -> None:
    raise _Terminated()


def _run(session, rfile: BinaryIO, wfile: BinaryIO, save) -> str:
    """Exchange lines until the robot ends or leaves; return how the session ended."""
    from kbcli.stages.serve import MAX_LINE

    def send(reply: dict) -> None:
        wfile.write((json.dumps(reply) + "\n").encode())
        wfile.flush()

    try:
        send(session.hello())
        while True:
            line = rfile.readline(MAX_LINE + 1)
            if not line:
                return "eof"
            if len(line) > MAX_LINE and not line.endswith(b"\n"):
                while line and not line.endswith(b"\n"):  # drop the rest of the long line
                    line = rfile.readline(MAX_LINE)
                send(session.error_reply(f"a message line is limited to {MAX_LINE} bytes"))
                continue
            reply = session.handle(line)
            if reply is None:
                continue
            if reply["type"] == "step":
                save()
            elif reply["type"] == "bye":
                reply["file"] = save()
                send(reply)
                return "end"
            send(reply)
    except (BrokenPipeError, ConnectionResetError):
        return "disconnected"


@command(name="serve", help=_HELP)
def serve_cmd(
    model: opts.model_option("Model artifact (kind 'model')."),
    output: opts.output_option("Run artifact to write (.h5), rewritten after every touch."),
    config: opts.config_option(
        "TOML file with a [serve] table (any adapt option of the robot's side, max_steps, stop); "
        "flags override it.") = None,
    strategy: opts.strategy_option("infogain") = None,
    posterior: opts.posterior_option("likelihood") = None,
    estimator: opts.estimator_option() = None,
    family: opts.family_option("translation") = None,
    max_steps: opts.max_steps_option(f"Touches at most, at most {MAX_SERVE_STEPS}.",
                                     show_default="40") = None,
    stop: Annotated[bool | None, typer.Option(
        "--stop/--no-stop", help="Say done at the stopping rule (posterior mass within 1 px of "
        "the estimate >= 0.95), or only after --max-steps. On unless --no-stop: a robot should touch "
        "no more than it needs (adapt, which measures, takes every touch by default).",
        show_default="--stop")] = None,
    blur: Annotated[float | None, typer.Option(
        "--blur", help="The robot's reach noise (standard deviation), px, used when it does not "
        "send where it felt it landed.", show_default="0")] = None,
    model_blur: opts.ModelBlur = None,
    resolution: opts.Resolution = None,
    prior_halfwidth: opts.PriorHalfwidth = None,
    socket_path: Annotated[Path | None, typer.Option(
        "--socket", help="Listen on this Unix socket for one robot instead of stdin/stdout.")
    ] = None,
    port: Annotated[int | None, typer.Option(
        "--port", min=0, max=65535, help="Listen on this TCP port (0: any free one, printed on "
        "stderr) for one robot instead of stdin/stdout.")] = None,
    host: Annotated[str, typer.Option(
        "--host", help="Address to listen on with --port.")] = "127.0.0.1",
    seed: opts.seed_option("Seed of the strategy's draws.") = 0,
) -> None:
    import numpy as np

    from kbcli.errors import KbcliError
    from kbcli.io.artifact import read_artifact
    from kbcli.io.config import load_toml
    from kbcli.stages.serve import ServeConfig, Session

    check_io({"--model": model, "--config": config}, ("--output", output),
             ("--socket", socket_path))
    if socket_path is not None and port is not None:
        raise KbcliError("give either --socket or --port, not both")
    values = dict(load_toml(config, "serve")) if config is not None else {}
    flags = {"strategy": strategy, "posterior": posterior, "estimator": estimator,
             "family": family, "max_steps": max_steps, "stop": stop, "blur": blur,
             "model_blur": model_blur, "resolution": resolution,
             "prior_halfwidth": prior_halfwidth}
    values.update({k: v for k, v in flags.items() if v is not None})
    cfg = ServeConfig.from_dict(values)
    model_art = read_artifact(model, "model")
    transport = "stdio" if socket_path is None and port is None else \
        ("unix" if socket_path is not None else "tcp")
    session = Session(cfg, model_art, rng=np.random.default_rng(seed), seed=seed,
                      transport=transport)
    _serve(session, output, socket_path, host, port)


def _serve(session, output: Path, socket_path: Path | None, host: str, port: int | None) -> None:
    """Run ``session`` over its transport; write the artifact after every touch and at the end
    (however it ends), then say how it ended on stderr."""
    from kbcli.io.artifact import write_artifact

    def save() -> str:
        write_artifact(session.artifact(), output)
        return str(output)

    old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    srv = conn = None
    started = False
    ended = "interrupted"
    try:
        if session.transport == "stdio":
            started = True
            ended = _run(session, sys.stdin.buffer, sys.stdout.buffer, save)
        else:
            srv, where = _listen(socket_path, host, port)
            err.print(f"kbcli serve: listening on {where}", markup=False)
            conn, _ = srv.accept()
            started = True
            with conn.makefile("rb") as rfile, conn.makefile("wb") as wfile:
                ended = _run(session, rfile, wfile, save)
    finally:
        signal.signal(signal.SIGTERM, old_term)
        if started:
            _finish(session, ended, save, output)
        _close(session.transport, ended, (conn, srv), socket_path if srv is not None else None)


def _finish(session, ended: str, save, output: Path) -> None:
    """Record how the session ended, write the artifact (unless "end" already did) and say so."""
    session.ended = session.ended or ended
    if ended != "end":  # "end" saved before its reply
        save()
    err.print(f"kbcli serve: wrote {output}: {session.steps} touch(es), "
              f"{session.errors} bad message(s), ended by {session.ended}", markup=False)


def _close(transport: str, ended: str, sockets: tuple, socket_path: Path | None) -> None:
    """Close the sockets, remove a Unix socket's file, and keep a closed stdout quiet at exit."""
    if ended == "disconnected" and transport == "stdio":
        with contextlib.suppress(OSError):  # no error at exit flushing a closed stdout
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
    for s in sockets:
        if s is not None:
            with contextlib.suppress(OSError):
                s.close()
    if socket_path is not None:
        with contextlib.suppress(OSError):
            socket_path.unlink()
