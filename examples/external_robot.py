"""A robot in its own process that adapts through ``kbcli serve`` (JSON lines, protocol 1).

The robot here is kbcli's pymunk arm touching the bundled keyboard, moved by a displacement only
this process knows; replace ``touch`` with your robot's (a real arm, MuJoCo, Gazebo). It starts
``kbcli serve`` with pipes (or connects to one listening on a socket), then, until kbcli says done:
reads the action, touches, and sends what it heard and where it felt it landed.

    python examples/external_robot.py --model data/default-model.h5 --dx 12 --dy -7 -o session.h5
    kbcli plot adapt session.h5 -o session.png
    kbcli animate session.h5 -o session.gif

    kbcli serve --model data/default-model.h5 -o session.h5 --socket /tmp/kbcli.sock &
    python examples/external_robot.py --connect unix:/tmp/kbcli.sock --dx 12 --dy -7
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys

import numpy as np

from kbcli import load_keyboard
from kbcli.sim import SimConfig, World, make_reacher


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="data/default-model.h5", help="kbcli model artifact")
    p.add_argument("--dx", type=float, default=12.0, help="true displacement, px (hidden)")
    p.add_argument("--dy", type=float, default=-7.0, help="true displacement, px (hidden)")
    p.add_argument("--mode", default="dynamics", help="ideal or dynamics (the pymunk arm)")
    p.add_argument("--reach-noise", type=float, default=0.0, help="landing scatter, px")
    p.add_argument("--max-steps", type=int, default=40, help="touches at most")
    p.add_argument("--seed", type=int, default=0, help="seed of kbcli's and the world's draws")
    p.add_argument("-o", "--output", default="session.h5", help="session artifact kbcli writes")
    p.add_argument("--connect", help="unix:PATH or tcp:HOST:PORT of a running kbcli serve "
                   "(default: start one with pipes)")
    p.add_argument("--transcript", help="also write every JSON line exchanged to this file, "
                   "each prefixed with who sent it ('kbcli' or 'robot')")
    p.add_argument("--quit-after", type=int, help="leave without a goodbye after this many "
                   "touches (to try a robot that disconnects)")
    return p.parse_args(argv)


class Link:
    """A line-oriented JSON link to kbcli: a child process's pipes, or a socket."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.proc = None
        self.log = open(args.transcript, "w") if args.transcript else None  # noqa: SIM115
        if args.connect is None:
            cmd = [sys.executable, "-m", "kbcli", "serve", "--model", args.model,
                   "-o", args.output, "--max-steps", str(args.max_steps), "--seed", str(args.seed)]
            self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
            self.rfile, self.wfile = self.proc.stdout, self.proc.stdin
        else:
            kind, _, where = args.connect.partition(":")
            if kind == "unix":
                sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                sock.connect(where)
            else:
                host, _, port = where.rpartition(":")
                sock = socket.create_connection((host, int(port)))
            self.rfile, self.wfile = sock.makefile("rb"), sock.makefile("wb")

    def send(self, msg: dict) -> None:
        line = json.dumps(msg)
        self.wfile.write((line + "\n").encode())
        self.wfile.flush()
        if self.log:
            self.log.write(f"robot {line}\n")

    def receive(self) -> dict:
        line = self.rfile.readline()
        if not line:
            raise SystemExit("kbcli closed the connection")
        if self.log:
            self.log.write(f"kbcli {line.decode().strip()}\n")
        return json.loads(line)

    def close(self) -> int:
        self.wfile.close()
        if self.log:
            self.log.close()
        return 0 if self.proc is None else self.proc.wait()


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    truth = np.array([args.dx, args.dy])
    # The world side: the keyboard at its true pose and the arm. kbcli never sees `truth`.
    world = World(load_keyboard(args.model),
                  make_reacher(SimConfig(mode=args.mode, reach_noise=args.reach_noise)), truth)
    rng = np.random.default_rng([args.seed, 1])

    def touch(action: list[float]) -> tuple[list[float], list[float] | None]:
        felt, heard = world.touch(np.array([action]), rng)
        h = heard[0]
        return felt[0].tolist(), None if np.isnan(h).all() else h.tolist()

    link = Link(args)
    msg = link.receive()
    assert msg["type"] == "hello", msg
    touches = 0
    while not msg["done"] and msg["action"] is not None:
        if args.quit_after is not None and touches >= args.quit_after:
            link.close()
            print(f"left after {touches} touches without saying goodbye")
            return 0
        action = msg["action"]
        felt, heard = touch(action)
        link.send({"op": "observe", "action": action, "heard": heard, "felt": felt})
        msg = link.receive()
        if msg["type"] == "error" and "matches no sound" in msg["error"]:
            # we did touch: record it as an unknown sound (it does not move the posterior)
            link.send({"op": "observe", "action": action, "heard": heard, "felt": felt,
                       "insist": True})
            msg = link.receive()
        if msg["type"] == "error":
            raise SystemExit(f"kbcli refused a touch: {msg['error']}")
        touches += 1
        print(f"touch {msg['step']:2d} at ({felt[0]:6.1f}, {felt[1]:6.1f}): {msg['sound']:14s} "
              f"estimate dx {msg['estimate']['dx']:+6.2f} dy {msg['estimate']['dy']:+6.2f}, "
              f"entropy {msg['entropy']:5.2f}")
    link.send({"op": "end"})
    bye = link.receive()
    est = np.array([msg["estimate"]["dx"], msg["estimate"]["dy"]])
    print(f"done after {bye['steps']} touches: estimate ({est[0]:+.2f}, {est[1]:+.2f}), truth "
          f"({truth[0]:+.2f}, {truth[1]:+.2f}), error {np.hypot(*(est - truth)):.2f} px; "
          f"kbcli wrote {bye['file']}")
    return link.close()


if __name__ == "__main__":
    sys.exit(main())
