"""What an animation shows (:class:`Replay`), read from a ``run`` or ``closed_loop`` artifact of any
schema, and which touches its frames show (:func:`frame_plan`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard, sound_name
from kbcli.core.options import flat_view
from kbcli.errors import KbcliError
from kbcli.sim.modes import MODES
from kbcli.stages.artifact import Artifact
from kbcli.viz.common import external


@dataclass
class Replay:
    """What an animation shows, read from an artifact (per touch ``i``, 0-based).

    ``belief`` and ``truth`` are transform parameters (``[angle,] dx, dy``) of ``family`` and
    ``world_family``; ``truth`` is None when unknown (a real robot). ``posteriors`` maps a number
    of touches ``k`` (0: the prior) to the log translation marginal after them.
    """

    kind: str
    keyboard: Keyboard
    landed: np.ndarray
    labels: list[str]
    heard: np.ndarray  # (n,) bool: a sound (not silence)
    belief: np.ndarray
    family: str
    truth: np.ndarray | None
    world_family: str
    arm: np.ndarray | None  # (n, 3, 2) shoulder, elbow, fingertip
    arm_note: str
    posteriors: dict[int, np.ndarray]
    dx: np.ndarray
    dy: np.ndarray
    attrs: dict
    data: dict
    config_loop: dict

    @property
    def n(self) -> int:
        return len(self.landed)

    def belief_at(self, k: int) -> np.ndarray:
        """The robot's belief after ``k`` touches (before the first: no displacement)."""
        if k == 0:
            return np.zeros(len(transforms.FAMILIES.get(self.family).params))
        return self.belief[k - 1]

    def moved_at(self, k: int) -> bool:
        """Whether the keyboard is at its true (moved) pose after ``k`` touches (a closed loop's
        first ``perturbed_at`` touches are at the reference pose)."""
        return self.kind != "closed_loop" or k > (self.attrs.get("perturbed_at") or 0)



# -- the arm ---------------------------------------------------------------------------------------
def _arm_points(base: np.ndarray, links: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(n, 3, 2) shoulder, elbow and fingertip of a two-link arm at joint angles (n, 2)."""
    q1, q12 = angles[:, 0], angles[:, 0] + angles[:, 1]
    elbow = base + links[0] * np.column_stack([np.cos(q1), np.sin(q1)])
    tip = elbow + links[1] * np.column_stack([np.cos(q12), np.sin(q12)])
    return np.stack([np.broadcast_to(base, elbow.shape), elbow, tip], axis=1)



def _sim_mode(art: Artifact) -> str | None:
    """The simulator mode the artifact was made in (a run's attrs or adapt config, a closed
    loop's adapt config; None when not recorded)."""
    a = art.attrs
    return a.get("mode") or (art.config.get("adapt") or {}).get("mode") or \
        ((art.config.get("loop") or {}).get("adapt") or {}).get("mode")


def _arm_shown(art: Artifact, mode: str | None) -> bool:
    """Whether there is an arm to draw: not for a robot in another process (``external``).
    This and :func:`_ik_note` are the one place this module names sim modes."""
    return not (mode == "external" or external(art.attrs))


def _ik_note(mode: str | None) -> str:
    """How an arm pose computed by inverse kinematics is labelled: the finger's ideal reach,
    except in ``dynamics`` mode (whose joint angles were not recorded)."""
    physics = mode in MODES and MODES.get(mode).physics
    return "arm (pose from inverse kinematics)" if physics else \
        "arm (ideal reach: pose from inverse kinematics)"


def _arm(art: Artifact, angles: np.ndarray | None, landed: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The arm per touch, and how its pose was obtained."""
    mode = _sim_mode(art)
    if not _arm_shown(art, mode):
        return None, ""
    geo = art.attrs.get("arm")
    if geo is None:  # schema 1: the default arm
        from kbcli.sim import SimConfig

        sc = SimConfig()
        geo = {"base": sc.base, "link_lengths": sc.link_lengths}
    base = np.asarray(geo["base"], float)
    links = np.asarray(geo["link_lengths"], float)
    if angles is not None and len(angles) == len(landed):
        return _arm_points(base, links, np.asarray(angles, float)), "arm (recorded joint angles)"
    from kbcli.sim import SimConfig, inverse_kinematics

    q = inverse_kinematics(SimConfig(base=tuple(base), link_lengths=tuple(links)), landed)
    return _arm_points(base, links, q), _ik_note(mode)


# -- reading ---------------------------------------------------------------------------------------
def _labels(perceived: np.ndarray, classes: np.ndarray | None = None) -> list[str]:
    out = []
    for i, f in enumerate(perceived):
        if classes is not None and classes[i] == -1:
            out.append(f"{sound_name(f)} (unknown)")
        else:
            out.append(sound_name(f))
    return out



def _truth(truth_d: dict, family: str) -> np.ndarray:
    return np.array([truth_d[k] for k in transforms.FAMILIES.get(family).params], float)


def _from_run(art: Artifact, kb: Keyboard) -> Replay:
    d, a = art.data, art.attrs
    actions = np.asarray(d["actions"], float).reshape(-1, 2)
    landed = np.asarray(d["landed"], float).reshape(-1, 2)
    landed = np.where(np.isfinite(landed), landed, actions)  # no felt position: the aim
    if "perceived" in d:  # optional in a run (schema 1): without it, no sound is named
        perceived = np.asarray(d["perceived"], float).reshape(len(actions), -1)
    else:
        perceived = np.full((len(actions), 2), np.nan)
    family = a.get("family", "translation")
    adapt_cfg = art.config.get("adapt") or {}
    # run schema 3 nests the robot's options under "robot"; sessions and schema <= 2: flat
    robot = flat_view(adapt_cfg.get("robot") or adapt_cfg, ("estimator",))
    estimator = ESTIMATORS.get(robot.get("estimator", "mean"))
    belief = np.asarray(d[estimator.record], float)
    belief = belief.reshape(len(actions), -1)
    truth_d = a.get("truth")
    world_family = a.get("world_family") or family
    truth = _truth(truth_d, world_family) if truth_d else None
    steps = np.asarray(d.get("snapshot_steps", np.zeros(0, int)), int)
    snaps = d.get("snapshots")
    posteriors = {int(t): np.asarray(snaps[j], float) for j, t in enumerate(steps)} \
        if snaps is not None else {}
    arm, note = _arm(art, d.get("joint_angles"), landed)
    return Replay("run", kb, landed, _labels(perceived, d.get("classes")),
                  ~np.isnan(perceived).all(axis=1), belief, family, truth, world_family, arm,
                  note, posteriors, np.asarray(d["dx"], float), np.asarray(d["dy"], float),
                  a, d, {})


def _from_loop(art: Artifact, kb: Keyboard) -> Replay:
    st, a = art.data["steps"], art.attrs
    landed = np.asarray(st["landed"], float).reshape(-1, 2)
    perceived = np.asarray(st["perceived"], float).reshape(len(landed), -1)
    loop_cfg = art.config.get("loop") or {}
    loop_adapt = loop_cfg.get("adapt") or {}
    family = (loop_adapt.get("robot") or loop_adapt).get("family", "translation")
    belief = np.asarray(st["correction"], float).reshape(len(landed), -1)
    if "estimate" in st:  # schema 2: the adapter's estimate while adapting
        est = np.asarray(st["estimate"], float).reshape(belief.shape)
        belief = np.where(np.isfinite(est), est, belief)
    truth_d = a.get("truth") or {}
    world_family = transforms.family_for(truth_d).name if truth_d else "translation"
    truth = _truth(truth_d, world_family)
    posteriors: dict[int, np.ndarray] = {}
    dx = dy = np.zeros(0)
    if "posterior" in art.data:
        p = art.data["posterior"]
        dx, dy = np.asarray(p["dx"], float), np.asarray(p["dy"], float)
        for t, lp in zip(np.asarray(p["touch"], int), p["log_translation"], strict=True):
            posteriors[int(t) + 1] = np.asarray(lp, float)
    arm, note = _arm(art, st.get("joint_angles"), landed)
    return Replay("closed_loop", kb, landed, _labels(perceived), ~np.isnan(perceived).all(axis=1),
                  belief, family, truth, world_family, arm, note, posteriors, dx, dy, a, st,
                  loop_cfg)


#: How each kind of artifact that can be animated is read.
_READERS = {"run": _from_run, "closed_loop": _from_loop}


def load_replay(art: Artifact) -> Replay:
    """Read a ``run`` or ``closed_loop`` artifact (any schema) into a :class:`Replay`."""
    from kbcli.stages import keyboard as keyboard_stage

    kb = keyboard_stage.load(art)
    read = _READERS.get(art.kind)
    if read is None:
        raise KbcliError(f"{art.path or 'artifact'}: is a {art.kind} artifact; animate reads run "
                         f"(kbcli adapt, kbcli serve) and closed_loop (kbcli run) artifacts")
    return read(art, kb)


# -- frames ----------------------------------------------------------------------------------------
def frame_plan(rep: Replay, max_frames: int) -> list[int]:
    """Numbers of touches ``k`` shown by successive frames (``k`` touches done).

    An adaptation shows every touch (and the prior, ``k = 0``), subsampled evenly beyond
    ``max_frames``. A closed loop keeps every adaptation touch, the touches around the move and
    the detection, and fills the rest of ``max_frames`` with evenly spaced play touches.
    """
    n = rep.n
    if rep.kind == "run":
        ks = np.arange(0, n + 1)
        if len(ks) > max_frames:
            ks = np.unique(np.rint(np.linspace(0, n, max_frames)).astype(int))
        return [int(k) for k in ks]
    phase = np.asarray(rep.data["phase"])
    must = set((np.flatnonzero(phase == 1) + 1).tolist())
    for event in (rep.attrs.get("perturbed_at"), rep.attrs.get("detected_at")):
        if event is not None:
            must.update(range(max(1, event - 2), min(n, event + 3) + 1))
    after = np.flatnonzero((phase[1:] == 0) & (phase[:-1] == 1)) + 2  # first play after adapting
    for k in after:
        must.update(range(int(k), min(n, int(k) + 3) + 1))
    must.update({1, n})
    budget = max(max_frames - len(must), 0)
    rest = np.setdiff1d(np.arange(1, n + 1), np.fromiter(must, int))
    if budget and len(rest):
        pick = rest[np.unique(np.rint(np.linspace(0, len(rest) - 1, min(budget, len(rest))))
                              .astype(int))]
        must.update(int(k) for k in pick)
    return sorted(k for k in must if 1 <= k <= n)

