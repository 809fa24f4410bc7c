"""Stage ``serve``: the adaptation driven by a robot in another process, over JSON lines.

A robot that is not kbcli's simulator (a real arm, MuJoCo, Gazebo) touches, listens and feels
where it landed; kbcli decides where to touch next and keeps the posterior (the same
:class:`~kbcli.core.adaptation.loop.Adapter` the ``adapt`` and ``run`` stages use). :class:`Session`
is the protocol without the transport: one message in (a line of JSON), one reply out (a dict).
The CLI (``kbcli serve``) moves the lines over stdin/stdout or a local socket and writes the
session as an ordinary ``run`` artifact (:class:`kbcli.stages.adapt.Recorder`) after every touch;
the truth being unknown, its errors are NaN.

Protocol 1 (the whole schema: ``docs/tutorials/robot.md`` and ``kbcli serve --help``): kbcli
speaks first (``"type": "hello"``, with the first ``action``); the robot sends per touch::

    {"op": "observe", "heard": [pitch, tempo] or null, "felt": [x, y] or null,
     "action": [x, y], "id": any}

and kbcli answers::

    {"type": "step", "step": 1, "class": 13, "sound": "A4 106 bpm",
     "estimate": {"dx": 11.9, "dy": -7.1}, "entropy": 2.3, "mass": 0.81, "done": false,
     "action": [x, y]}

Other ops: ``suggest``, ``state`` and ``end`` (kbcli writes the artifact, replies ``bye`` and
exits). A message kbcli cannot use (longer than :data:`MAX_LINE` bytes, a number of more than
:data:`MAX_DIGITS` digits, an unknown op or field, an action outside the working area, a ``felt``
position beyond :data:`FELT_MARGIN`, heard features that match no sound unless
``"insist": true``, a touch beyond ``max_steps``) gets
``{"type": "error", "error": "...", "id": ...}``; nothing is recorded and the session goes on.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from pydantic import Field, field_validator

from kbcli import __version__
from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.loop import step_record
from kbcli.core.config import Config, Flag, Whole, as_table, between
from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import FEATURE_NAMES, sound_name
from kbcli.core.model.sounds import UNKNOWN
from kbcli.errors import ArtifactError, ConfigError, KbcliError
from kbcli.stages.adapt import Recorder, run_attrs, run_data
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.models import load_model

PROTOCOL = 1
#: Longest message line accepted, bytes.
MAX_LINE = 1 << 16
#: Fields each ``op`` accepts.
FIELDS = {
    "observe": ("op", "heard", "felt", "action", "insist", "id"),
    "suggest": ("op", "id"),
    "state": ("op", "id"),
    "end": ("op", "id"),
}


#: Most touches a session may observe (``max_steps``).
MAX_SERVE_STEPS = 10_000
#: How far outside the working area a ``felt`` position may be, as a fraction of the area's
#: larger side (a finger lands off the aim by the reach error; farther than this is a bad reading).
FELT_MARGIN = 0.5


class ServeConfig(Config):
    """A session with an external robot: the robot-side ``adapter`` settings; ``done`` holds once
    ``max_steps`` touches are observed and, with ``stop``, when the stopping rule does."""

    what = "serve"

    adapter: Any = Field(default_factory=AdapterConfig)
    max_steps: between(Whole, 1, MAX_SERVE_STEPS) = 40
    stop: Flag = True

    _adapter = field_validator("adapter", mode="before")(as_table(AdapterConfig))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ServeConfig:
        """From a flat mapping (a TOML ``[serve]`` table): any AdapterConfig field, ``max_steps``
        and ``stop``; unknown keys are rejected."""
        if not isinstance(d, Mapping):
            raise ConfigError(f"serve must be a table, got {d!r}")
        own = ("max_steps", "stop")
        known = (*AdapterConfig().to_dict(), *own)
        unknown = sorted(set(d) - set(known))
        if unknown:
            raise ConfigError(f"unknown serve option(s) {', '.join(unknown)}; valid: "
                              f"{', '.join(sorted(known))}")
        adapter = {k: v for k, v in d.items() if k not in own}
        return cls(adapter=AdapterConfig(**adapter), **{k: v for k, v in d.items() if k in own})

    def to_dict(self) -> dict:
        """Flat: the adapter's fields, ``max_steps`` and ``stop`` (what :meth:`from_dict` reads)."""
        return {**self.adapter.to_dict(), "max_steps": self.max_steps, "stop": self.stop}


class MessageError(KbcliError):
    """A message the session cannot use: answered with an error reply."""


#: Most digits of a whole number in a message (Python refuses to read more than 4300; an ``id`` of
#: a 128-bit number has 39).
MAX_DIGITS = 100


def _parse_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_DIGITS:
        raise MessageError(f"a whole number of {digits} digits: at most {MAX_DIGITS} are read")
    return int(text)


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _numbers(v: object, name: str, n: int | None) -> list[float]:
    """A JSON list of ``n`` finite numbers (booleans and strings refused), each refusal naming the
    entry and what is wrong with it."""
    want = f"{n} numbers" if n else "numbers"
    if not isinstance(v, list):
        raise MessageError(f"{name} must be a list of {want}, got {json.dumps(v)[:80]}")
    for i, x in enumerate(v):
        if not _is_number(x):
            raise MessageError(f"{name}[{i}] must be a number, got {json.dumps(x)[:40]}")
        if not math.isfinite(float(x)):  # a literal beyond a double's range, 1e400, reads as inf
            raise MessageError(f"{name}[{i}] is not a finite number (beyond the range of a "
                               f"double, about 1.8e308)")
    if n is not None and len(v) != n:
        raise MessageError(f"{name} must be a list of {n} numbers, got {len(v)}")
    return [float(x) for x in v]


def _reject_constant(name: str) -> float:
    raise MessageError(f"{name} is not a number JSON allows")


def _json_object(text: str) -> dict:
    """A message line as a JSON object; MessageError otherwise."""
    try:
        msg = json.loads(text, parse_constant=_reject_constant, parse_int=_parse_int)
    except json.JSONDecodeError as exc:
        raise MessageError(f"not JSON ({exc.msg} at column {exc.colno})") from None
    except RecursionError:  # "[[[[..." within MAX_LINE: json recurses per level
        raise MessageError("not JSON this side reads: nested too deeply") from None
    if not isinstance(msg, dict):
        raise MessageError(f"a message is a JSON object, got {type(msg).__name__}")
    return msg


def _check_fields(msg: dict) -> str:
    """The message's ``op`` (``observe`` when left out); MessageError for an unknown op or a field
    the op does not take."""
    op = msg.get("op", "observe")
    if op not in FIELDS:
        raise MessageError(f"unknown op {op!r}; valid: {', '.join(FIELDS)}")
    unknown = sorted(set(msg) - set(FIELDS[op]))
    if unknown:
        raise MessageError(f"unknown field(s) {', '.join(unknown)} for op {op!r}; "
                           f"valid: {', '.join(FIELDS[op])}")
    return op


class Session:
    """One adaptation with an external robot: JSON messages in, replies out.

    ``rng`` is the robot's generator; ``seed`` and ``transport`` (``stdio``, ``unix`` or ``tcp``)
    are recorded. ArtifactError when ``model_artifact`` is not of kind ``model``.
    """

    def __init__(self, cfg: ServeConfig, model_artifact: Artifact, *, rng: np.random.Generator,
                 seed: int | None = None, transport: str = "stdio", model=None) -> None:
        if model_artifact.kind != "model":
            raise ArtifactError(f"{model_artifact.path or 'model'}: is a {model_artifact.kind} "
                                f"artifact, expected model")
        self.cfg = cfg
        self.model_artifact = model_artifact
        self.seed = seed
        self.transport = transport
        self.model = load_model(model_artifact) if model is None else model
        self.adapter = Adapter(self.model, cfg.adapter, rng=rng, max_steps=cfg.max_steps)
        self.recorder = Recorder(self.adapter, range(cfg.max_steps + 1))
        self.names = transforms.FAMILIES.get(cfg.adapter.family).params
        self.n_features = int(np.shape(self.model.class_features_)[1])
        self.errors = 0
        self.ended: str | None = None
        self._decide_ms = 0.0
        self.pending: np.ndarray | None = self._suggest()

    # -- state -------------------------------------------------------------------------------------
    @property
    def steps(self) -> int:
        return len(self.recorder)

    def _suggest(self) -> np.ndarray | None:
        if self.steps >= self.cfg.max_steps:
            return None
        t0 = time.perf_counter()
        a = self.adapter.suggest()
        self._decide_ms = 1e3 * (time.perf_counter() - t0)
        return a

    def done(self) -> bool:
        """Stop touching: the budget is used up, or (with ``stop``) the stopping rule holds."""
        if self.steps >= self.cfg.max_steps:
            return True
        return self.cfg.stop and self.adapter.should_stop()

    def _state(self) -> dict:
        ad = self.adapter
        return {
            "step": self.steps,
            "estimate": {n: float(v) for n, v in zip(self.names, ad.estimate(), strict=True)},
            "entropy": float(ad.entropy()),
            "mass": float(ad.mass_near_estimate()),
            "done": bool(self.done()),
            "action": self._action(),
        }

    def _action(self) -> list[float] | None:
        """The pending action as JSON (None once ``max_steps`` touches were observed)."""
        return None if self.pending is None else [float(v) for v in self.pending]

    def hello(self) -> dict:
        """The first line kbcli sends."""
        names = list(FEATURE_NAMES[: self.n_features])
        names += [f"feature{i}" for i in range(len(names), self.n_features)]
        return {"type": "hello", "protocol": PROTOCOL, "kbcli": __version__, "features": names,
                "area": [float(v) for v in self.adapter.area], "family": self.cfg.adapter.family,
                "parameters": list(self.names), "max_steps": self.cfg.max_steps, **self._state()}

    # -- messages ----------------------------------------------------------------------------------
    def handle(self, line: str | bytes) -> dict | None:
        """The reply to one message line (None for a blank line)."""
        msg: dict = {}
        try:
            text = line.decode("utf-8") if isinstance(line, bytes) else line
            if not text.strip():
                return None
            msg = _json_object(text)
            reply = getattr(self, f"_op_{_check_fields(msg)}")(msg)
        except UnicodeDecodeError:
            return self.error_reply("a message must be UTF-8 text", None)
        except (MessageError, KbcliError) as exc:
            return self.error_reply(str(exc), msg.get("id"))
        if msg.get("id") is not None:
            reply["id"] = msg["id"]
        return reply

    def error_reply(self, text: str, msg_id=None) -> dict:
        """An error reply (counted in the artifact's ``message_errors``)."""
        self.errors += 1
        out = {"type": "error", "error": text}
        if msg_id is not None:
            out["id"] = msg_id
        return out

    def _op_suggest(self, msg: dict) -> dict:
        return {"type": "suggestion", "step": self.steps, "action": self._action()}

    def _op_state(self, msg: dict) -> dict:
        return {"type": "state", **self._state()}

    def _op_end(self, msg: dict) -> dict:
        self.ended = "end"
        return {"type": "bye", "steps": self.steps}

    def _op_observe(self, msg: dict) -> dict:
        if "heard" not in msg:
            raise MessageError("an observe message needs heard (the features, or null for "
                               "silence)")
        if self.steps >= self.cfg.max_steps:
            raise MessageError(f"the session has observed its max_steps ({self.cfg.max_steps}) "
                               f"touches; send {{\"op\": \"end\"}}")
        heard = msg["heard"]
        heard = None if heard is None else _numbers(heard, "heard", self.n_features)
        felt = msg.get("felt")
        felt = None if felt is None else self._check_felt(_numbers(felt, "felt", 2))
        insist = msg.get("insist", False)
        if not isinstance(insist, bool):
            raise MessageError(f"insist must be true or false, got {json.dumps(insist)[:40]}")
        if msg.get("action") is not None:
            action = self.adapter.check_action(_numbers(msg["action"], "action", 2))
        elif self.pending is not None:
            action = self.pending
        else:
            raise MessageError("no action: send the action the robot took")
        ad = self.adapter
        h = ad.check_heard(heard)
        if not insist and int(self.model.classify(h.reshape(1, -1))[0]) == UNKNOWN:
            raise MessageError(f"heard {[float(v) for v in h]} matches no sound of the model: not "
                               "recorded (send it again with \"insist\": true to record it as an "
                               "unknown touch, which does not move the posterior)")
        t0 = time.perf_counter()
        cls = ad.observe(action, h, felt_position=felt)
        landed = np.full(2, np.nan) if felt is None else np.asarray(felt, float)
        st = step_record(ad, self.steps + 1, action, landed, h, cls, t0=t0,
                         extra_ms=self._decide_ms)
        self.recorder.add(st)
        self.pending = self._suggest()
        label = "unknown" if cls == UNKNOWN else sound_name(h)
        return {"type": "step", "class": cls, "sound": label, **self._state()}

    def _check_felt(self, felt: list[float]) -> list[float]:
        """``felt`` within :data:`FELT_MARGIN` of the working area; MessageError otherwise."""
        x0, y0, x1, y1 = (float(v) for v in self.adapter.area)
        m = FELT_MARGIN * max(x1 - x0, y1 - y0)
        if not (x0 - m <= felt[0] <= x1 + m and y0 - m <= felt[1] <= y1 + m):
            raise MessageError(f"felt ({felt[0]:g}, {felt[1]:g}) is far outside the working area "
                               f"({x0:g}, {y0:g})-({x1:g}, {y1:g}) (more than {m:g} px): a "
                               "bad reading; not recorded")
        return felt

    # -- the record --------------------------------------------------------------------------------
    def artifact(self) -> Artifact:
        """The session as a ``run`` artifact (the touches so far)."""
        res = self.recorder.arrays()
        attrs = run_attrs(res, self.cfg.adapter)
        attrs.update(source="external", mode="external", arm=None, ended=self.ended,
                     message_errors=self.errors, stop=self.cfg.stop)
        return Artifact(
            kind="run",
            config={"adapt": self.cfg.to_dict(),
                    "serve": {"protocol": PROTOCOL, "transport": self.transport},
                    "keyboard": self.model_artifact.config["keyboard"],
                    "snapshot_steps": [int(s) for s in range(self.cfg.max_steps + 1)]},
            seed=self.seed,
            data=run_data(res),
            attrs=attrs,
            inputs={"model": ref(self.model_artifact)},
        )


__all__ = ["ServeConfig", "Session", "MessageError", "PROTOCOL", "MAX_LINE", "MAX_DIGITS", "FIELDS",
           "FELT_MARGIN"]
