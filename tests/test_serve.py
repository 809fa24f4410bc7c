"""``kbcli serve``: the JSON-lines protocol, bad messages, disconnections, sockets, the example robot."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from kbcli.cli import app
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import IdealReacher, SimConfig, World
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact
from kbcli.stages.serve import ServeConfig, Session

ROOT = Path(__file__).resolve().parents[1]
KB_ART = keyboard_stage.run(KeyboardConfig())
KB = keyboard_stage.load(KB_ART)
MODEL_ART = exact_artifact(KB_ART)
TRUTH = np.array([6.0, -4.0])
#: a small grid keeps every test fast
SMALL = ["--resolution", "1", "--prior-halfwidth", "15"]


def _session(max_steps: int = 6, stop: bool = True) -> Session:
    cfg = ServeConfig(adapter=AdapterConfig(resolution=1.0, prior_halfwidth=15.0),
                      max_steps=max_steps, stop=stop)
    return Session(cfg, MODEL_ART, rng=np.random.default_rng(0), seed=0)


def _robot(seed: int = 1):
    world = World(KB, IdealReacher(SimConfig()), TRUTH)
    rng = np.random.default_rng(seed)

    def touch(action):
        felt, heard = world.touch(np.array([action], float), rng)
        h = heard[0]
        return felt[0].tolist(), None if np.isnan(h).all() else h.tolist()

    return touch


def _observe(session: Session, touch, action=None) -> dict:
    action = session.pending.tolist() if action is None else action
    felt, heard = touch(action)
    return session.handle(json.dumps({"op": "observe", "action": action, "heard": heard,
                                      "felt": felt}))


def test_hello_then_touches_converge_and_record():
    s = _session(max_steps=25)
    hello = s.hello()
    assert hello["type"] == "hello" and hello["protocol"] == 1 and hello["step"] == 0
    assert hello["features"] == ["pitch", "tempo"] and hello["parameters"] == ["dx", "dy"]
    assert hello["done"] is False and len(hello["action"]) == 2
    touch = _robot()
    reply = hello
    while not reply["done"]:
        reply = _observe(s, touch)
        assert reply["type"] == "step" and reply["step"] == s.steps
    est = np.array([reply["estimate"]["dx"], reply["estimate"]["dy"]])
    assert np.hypot(*(est - TRUTH)) < 1.0 and s.steps < 25
    art = s.artifact()
    assert art.kind == "run" and art.attrs["source"] == "external"
    assert art.attrs["steps"] == s.steps and art.attrs["truth"] is None
    assert art.attrs["final_error_px"] is None and np.isnan(art.data["errors"]).all()
    assert len(art.data["snapshot_steps"]) == s.steps + 1  # the posterior after every touch
    assert art.data["landed"].shape == (s.steps, 2)


BAD = [
    ("this is not json", "not JSON"),
    ("[1, 2]", "a message is a JSON object"),
    ('{"op": "dance"}', "unknown op 'dance'"),
    ('{"op": "observe", "heard": null, "colour": 1}', "unknown field(s) colour"),
    ('{"op": "state", "heard": null}', "unknown field(s) heard"),
    ('{"heard": ["C4", 100]}', 'heard[0] must be a number, got "C4"'),
    ('{"heard": [60, true]}', "heard[1] must be a number, got true"),
    ('{"heard": [1e400, 90]}', "heard[0] is not a finite number"),
    ('{"heard": [%s, 90]}' % ("9" * 5000), "a whole number of 5000 digits: at most 100"),
    ('{"op": "state", "id": %s}' % ("1" * 5000), "a whole number of 5000 digits: at most 100"),
    ('{"heard": [60, NaN]}', "NaN is not a number JSON allows"),
    ('{"heard": [60, 100, 3]}', "heard must be a list of 2 numbers, got 3"),
    ('{"heard": 60}', "heard must be a list"),
    ('{"op": "observe"}', "needs heard"),
    ('{"heard": null, "felt": [1]}', "felt must be a list of 2 numbers"),
    ('{"heard": null, "action": [5000, 300]}', "outside the working area"),
    (b'\xff\xfe{}', "UTF-8"),
]


@pytest.mark.parametrize("line, fragment", BAD)
def test_bad_message_gets_an_error_and_the_session_goes_on(line, fragment):
    s = _session()
    touch = _robot()
    assert _observe(s, touch)["type"] == "step"
    before = s.adapter.posterior.logp.copy()
    reply = s.handle(line)
    assert reply["type"] == "error" and fragment in reply["error"], reply
    np.testing.assert_array_equal(s.adapter.posterior.logp, before)
    assert s.steps == 1 and s.errors == 1
    assert _observe(s, touch)["step"] == 2  # and on it goes


def test_other_ops_ids_blank_lines_and_the_budget():
    s = _session(max_steps=2, stop=False)
    touch = _robot()
    assert s.handle("   \n") is None
    sug = s.handle('{"op": "suggest", "id": "a1"}')
    assert sug == {"type": "suggestion", "step": 0, "action": s.pending.tolist(), "id": "a1"}
    r1 = _observe(s, touch)
    assert r1["done"] is False and r1["action"] is not None
    r2 = _observe(s, touch)
    assert r2["done"] is True and r2["action"] is None  # the budget is used up
    err = s.handle('{"heard": null, "id": 7}')
    assert err["type"] == "error" and "max_steps" in err["error"] and err["id"] == 7
    state = s.handle('{"op": "state"}')
    assert state["type"] == "state" and state["step"] == 2 and state["done"] is True
    assert s.handle('{"op": "end"}') == {"type": "bye", "steps": 2}
    assert s.ended == "end" and s.artifact().attrs["message_errors"] == 1


def test_a_robot_may_touch_elsewhere_and_without_a_felt_position():
    s = _session()
    r = s.handle(json.dumps({"action": [300.0, 320.0], "heard": KB.features[9].tolist()}))
    assert r["type"] == "step" and r["class"] == 10 and r["sound"].startswith(KB.names[9])
    art = s.artifact()
    np.testing.assert_array_equal(art.data["actions"][0], [300.0, 320.0])
    assert np.isnan(art.data["landed"][0]).all()  # no felt position: recorded as unknown


def test_session_artifact_is_read_by_plot_adapt_and_animate(tmp_path, runner):
    s = _session(max_steps=4, stop=False)
    touch = _robot()
    for _ in range(4):
        _observe(s, touch)
    write_artifact(s.artifact(), tmp_path / "session.h5")
    r = runner.invoke(app, ["plot", "adapt", str(tmp_path / "session.h5"), "-o",
                            str(tmp_path / "s.png")])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["animate", str(tmp_path / "session.h5"), "-o",
                            str(tmp_path / "s.gif")])
    assert r.exit_code == 0, r.output
    from PIL import Image

    assert Image.open(tmp_path / "s.gif").n_frames == 5  # the prior and four touches


def test_a_session_with_no_touch_is_refused_by_plot_adapt(tmp_path, runner):
    write_artifact(_session().artifact(), tmp_path / "empty.h5")
    assert read_artifact(tmp_path / "empty.h5", "run").attrs["steps"] == 0
    r = runner.invoke(app, ["plot", "adapt", str(tmp_path / "empty.h5"), "-o",
                            str(tmp_path / "e.png")])
    assert r.exit_code == 1 and "holds no touches" in r.output
    assert not (tmp_path / "e.png").exists()


# -- the command, in other processes ------------------------------------------------------------
@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("serve")
    write_artifact(MODEL_ART, d / "model.h5")
    write_artifact(KB_ART, d / "kb.h5")
    return d


def _serve(model_file, out, *extra, **popen):
    cmd = [sys.executable, "-m", "kbcli", "serve", "--model", str(model_file / "model.h5"),
           "-o", str(out), *SMALL, *extra]
    return subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, **popen)


def _send(proc, msg) -> dict:
    proc.stdin.write((msg if isinstance(msg, str) else json.dumps(msg)).encode() + b"\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())


def test_serve_over_pipes_bad_lines_and_end_of_input(model_file, tmp_path):
    out = tmp_path / "session.h5"
    proc = _serve(model_file, out, "--max-steps", "10")
    hello = json.loads(proc.stdout.readline())
    touch = _robot()
    msg = hello
    for i in range(3):
        felt, heard = touch(msg["action"])
        msg = _send(proc, {"heard": heard, "felt": felt})
        assert msg["type"] == "step" and msg["step"] == i + 1
        bad = _send(proc, '{"heard": "loud"}')
        assert bad["type"] == "error"
    proc.stdin.close()  # the robot goes away: end of input
    assert proc.wait(timeout=60) == 0
    err = proc.stderr.read().decode()
    assert "3 touch(es), 3 bad message(s), ended by eof" in err
    art = read_artifact(out, "run")
    assert art.attrs["steps"] == 3 and art.attrs["ended"] == "eof"
    assert art.attrs["message_errors"] == 3
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def _one_touch(model_file, out):
    """A serve process that has recorded one touch."""
    proc = _serve(model_file, out)
    hello = json.loads(proc.stdout.readline())
    felt, heard = _robot()(hello["action"])
    assert _send(proc, {"heard": heard, "felt": felt})["step"] == 1
    return proc


def test_serve_survives_a_broken_pipe(model_file, tmp_path):
    out = tmp_path / "session.h5"
    proc = _one_touch(model_file, out)
    proc.stdout.close()  # the robot stops listening, then sends one more touch
    proc.stdin.write((json.dumps({"heard": None}) + "\n").encode())
    proc.stdin.flush()
    assert proc.wait(timeout=60) == 0
    err = proc.stderr.read().decode()
    assert "ended by disconnected" in err and "Traceback" not in err
    assert read_artifact(out, "run").attrs["steps"] == 2


@pytest.fixture
def sigint_heard():
    """Children that hear Ctrl-C. A process inherits an *ignored* SIGINT (so does a test suite
    started in the background by a shell without job control, and every child it spawns), but a
    handled one is reset to the default at exec, where Python turns it into KeyboardInterrupt."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_serve_interrupted_keeps_the_touches(model_file, tmp_path, sig, code, sigint_heard):
    out = tmp_path / "session.h5"
    proc = _one_touch(model_file, out)
    proc.send_signal(sig)
    assert proc.wait(timeout=60) == code
    assert "Traceback" not in proc.stderr.read().decode()
    art = read_artifact(out, "run")
    assert art.attrs["steps"] == 1 and art.attrs["ended"] == "interrupted"


def test_serve_on_a_unix_socket(model_file, tmp_path):
    out, sock_path = tmp_path / "session.h5", tmp_path / "kb.sock"
    proc = _serve(model_file, out, "--socket", str(sock_path), "--max-steps", "3")
    deadline = time.monotonic() + 60
    while not sock_path.exists():
        assert time.monotonic() < deadline and proc.poll() is None, proc.stderr.read()
        time.sleep(0.05)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.connect(str(sock_path))
    rfile, wfile = sock.makefile("rb"), sock.makefile("wb")
    msg = json.loads(rfile.readline())
    touch = _robot()
    while not msg["done"]:
        felt, heard = touch(msg["action"])
        wfile.write((json.dumps({"heard": heard, "felt": felt}) + "\n").encode())
        wfile.flush()
        msg = json.loads(rfile.readline())
    wfile.write(b'{"op": "end"}\n')
    wfile.flush()
    bye = json.loads(rfile.readline())
    assert bye["type"] == "bye" and bye["steps"] == 3 and bye["file"] == str(out)
    sock.close()
    assert proc.wait(timeout=60) == 0
    assert not sock_path.exists()  # the socket is removed at the end
    assert read_artifact(out, "run").attrs["ended"] == "end"


def test_serve_on_a_tcp_port(model_file, tmp_path):
    out = tmp_path / "session.h5"
    proc = _serve(model_file, out, "--port", "0", "--max-steps", "2", "--no-stop")
    line = proc.stderr.readline().decode()
    assert "listening on tcp:127.0.0.1:" in line, line
    port = int(line.strip().rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
        rfile, wfile = sock.makefile("rb"), sock.makefile("wb")
        msg = json.loads(rfile.readline())
        touch = _robot()
        for _ in range(2):
            felt, heard = touch(msg["action"])
            wfile.write((json.dumps({"heard": heard, "felt": felt}) + "\n").encode())
            wfile.flush()
            msg = json.loads(rfile.readline())
        assert msg["done"] is True and msg["action"] is None
        rfile.close()
        wfile.close()
    assert proc.wait(timeout=60) == 0  # the robot closed the connection
    art = read_artifact(out, "run")
    assert art.attrs["steps"] == 2 and art.attrs["ended"] == "eof"
    assert art.config["serve"]["transport"] == "tcp"


def test_serve_bad_input_one_line(model_file, tmp_path, runner):
    def one_line(r, fragment):
        assert r.exit_code == 1, r.output
        lines = [ln for ln in r.output.strip().splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("kbcli: error:") and fragment in lines[0]

    base = ["serve", "-o", str(tmp_path / "s.h5")]
    one_line(runner.invoke(app, [*base, "--model", str(model_file / "kb.h5")]),
             "is a keyboard artifact, expected model")
    one_line(runner.invoke(app, [*base, "--model", str(model_file / "model.h5"), "--strategy",
                                 "psychic"]), "unknown strategy")
    one_line(runner.invoke(app, ["serve", "--model", str(model_file / "model.h5"), "-o",
                                 str(model_file / "model.h5")]), "is the input")
    sock = tmp_path / "taken"
    sock.write_text("a user's file")
    one_line(runner.invoke(app, [*base, "--model", str(model_file / "model.h5"), "--socket",
                                 str(sock)]), "already exists")
    assert sock.read_text() == "a user's file"
    assert not (tmp_path / "s.h5").exists()


def test_help_documents_the_protocol(runner):
    r = runner.invoke(app, ["serve", "--help"])
    assert r.exit_code == 0
    for fragment in ('"type": "hello"', '"op": "observe"', '"heard"', '"felt"', '"done"',
                     '"op": "end"', '"type": "error"'):
        assert fragment in r.output, fragment


def test_example_robot_end_to_end(tmp_path):
    """examples/external_robot.py: the pymunk arm in another process, kbcli serve over pipes."""
    out = tmp_path / "session.h5"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "external_robot.py"),
                        "--model", str(ROOT / "data" / "default-model.h5"), "--dx", "12",
                        "--dy", "-7", "--mode", "dynamics", "--max-steps", "25", "-o", str(out)],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    assert "done after" in r.stdout
    art = read_artifact(out, "run")
    est = np.array([art.attrs["estimate"]["dx"], art.attrs["estimate"]["dy"]])
    assert art.attrs["steps"] >= 1 and art.attrs["steps"] <= 25 and art.attrs["ended"] == "end"
    assert np.hypot(*(est - [12.0, -7.0])) < 1.0
    assert np.isfinite(art.data["landed"]).all()  # the robot sent where it felt it landed
