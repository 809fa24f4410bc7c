"""Stage ``adapt``: recover a displaced keyboard's pose with few touches (paper Sect. III-D, III-E).

:func:`experiment` runs one adaptation of the robot's :class:`~kbcli.core.adapt.Adapter` against a
simulated :class:`~kbcli.sim.World` at a given true pose; :func:`run` does it for a model artifact
and a scene artifact and returns a ``run`` artifact. The scene is read only to build the world and
to score the estimates: the robot's side never sees it.

Per step the artifact stores the action, where the finger landed, the perceived features and class,
the estimates (posterior mean and maximum-likelihood cell), the error against the truth (px, and
degrees for rotations), the entropy (nats), the probability of the most probable cell, the mass
near the estimate, whether the stopping rule held, and the robot's time (``timing/step_ms``: the
only dataset that is not reproducible bit for bit, being wall-clock); plus posterior snapshots at
chosen steps (``snapshots``: the log of the translation marginal; and, rigid family,
``snapshot_angles``: the angle marginal). Schema 2 adds ``joint_angles``, the simulated arm's pose
after each touch in dynamics mode, and the arm's geometry and the mode in the attributes.

:class:`Recorder` and :func:`run_attrs` build the same artifact for a session with a robot in
another process (``kbcli serve``, :mod:`kbcli.stages.serve`): there the truth is unknown and the
errors are NaN (their summaries None).

The stage's config, :class:`AdaptConfig`, holds the robot's :class:`~kbcli.core.adapt.AdapterConfig`
by composition (``AdaptConfig(robot=AdapterConfig(...), mode=..., reach_noise=...)``) beside the
simulated arm's and the loop's options; run artifacts of schema 2 store it nested
(``config["adapt"]["robot"]``), and the flat layout of schema 1 is still read.

:func:`play_success` measures the playing success around an adaptation by replaying the melody
with Algorithm 1 (:func:`kbcli.core.play.replay`): before the displacement, after it without
adaptation, and after it with the final estimate as the correction (``experiment(play=...)``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from kbcli.core import transforms
from kbcli.core.adapt import (
    POSTERIORS,
    Adapter,
    AdapterConfig,
    Step,
    adapt,
    build_samples,
    build_table,
)
from kbcli.core.estimators import ESTIMATORS
from kbcli.core.keyboard import Keyboard, KeyboardConfig
from kbcli.core.melody import DEFAULT_MELODY, parse_melody
from kbcli.core.play import MATCH, replay
from kbcli.core.posterior import ActionSamples, LikelihoodTable
from kbcli.errors import ArtifactError, ConfigError, KbcliError
from kbcli.sim import MODES, SimConfig, World, make_reacher
from kbcli.sim.arms import PRESETS, ArmConfig, arm_config
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.models import load_model

FEEDBACKS = ("landed", "aim")
DEFAULT_SNAPSHOTS = (0, 1, 2, 3, 5, 10, 20, 40)


#: The world-side and loop options of :class:`AdaptConfig` (everything else is the robot's).
LOOP_FIELDS = ("mode", "reach_noise", "arm", "feedback", "max_steps", "stop")


@dataclass(frozen=True, kw_only=True, init=False)
class AdaptConfig:
    """One adaptation: the robot's settings (``robot``, a :class:`kbcli.core.adapt.AdapterConfig`)
    plus the simulated arm's and the loop's.

    Parameters
    ----------
    robot : AdapterConfig
        How the robot adapts: strategy, posterior, estimator, grid, ... (its defaults are kbcli's
        best choice).
    mode : str
        ``ideal`` or ``dynamics`` (:class:`kbcli.sim.SimConfig`).
    reach_noise : float
        Landing scatter of the arm, px.
    arm : ArmConfig
        How the simulated arm errs (:mod:`kbcli.sim.arms`; a preset name or a table is accepted):
        its landing error, its finger and how well it feels where it landed.
    feedback : str
        ``landed``: the robot observes where its finger landed (proprioception); ``aim``: only where
        it aimed, and blurs its likelihood by ``reach_noise`` (``robot.blur`` is then set to it).
    max_steps : int
        T, observations at most.
    stop : bool
        End at the stopping rule (else always run T steps and record when the rule fired).

    Notes
    -----
    The robot's options read through as attributes (``cfg.strategy`` is ``cfg.robot.strategy``), and
    :meth:`from_dict` also takes the flat layout of schema-1 artifacts and older TOML files (robot
    options beside ``mode``): the layout before the robot's config was held by composition.
    """

    robot: AdapterConfig = field(default_factory=AdapterConfig)
    mode: str = "ideal"
    reach_noise: float = 0.0
    arm: ArmConfig = PRESETS["ideal"]
    feedback: str = "landed"
    max_steps: int = 40
    stop: bool = False

    def __init__(self, *, robot: AdapterConfig | None = None, mode: str = "ideal",
                 reach_noise: float = 0.0, arm: ArmConfig | str | dict = "ideal",
                 feedback: str = "landed", max_steps: int = 40, stop: bool = False,
                 **robot_options) -> None:
        # robot options given flat (``AdaptConfig(strategy="random")``, the layout before the
        # composition) still work: they override ``robot``'s
        unknown = sorted(set(robot_options) - set(AdapterConfig.model_fields))
        if unknown:
            raise ConfigError(f"unknown adapt option(s) {', '.join(unknown)}")
        if robot is None:
            robot = AdapterConfig(**robot_options)
        elif robot_options:
            if not isinstance(robot, AdapterConfig):
                raise ConfigError(f"robot must be an AdapterConfig, got {type(robot).__name__}")
            robot = robot.replace(**robot_options)
        for k, v in (("robot", robot), ("mode", mode), ("reach_noise", reach_noise),
                     ("arm", arm_config(arm)), ("feedback", feedback), ("max_steps", max_steps),
                     ("stop", stop)):
            object.__setattr__(self, k, v)
        self.__post_init__()

    def __post_init__(self) -> None:
        if not isinstance(self.robot, AdapterConfig):
            raise ConfigError(f"robot must be an AdapterConfig, got {type(self.robot).__name__}")
        if self.mode not in MODES:
            raise ConfigError(f"unknown mode {self.mode!r}; valid: {', '.join(MODES)}")
        if self.feedback not in FEEDBACKS:
            raise ConfigError(f"unknown feedback {self.feedback!r}; valid: {', '.join(FEEDBACKS)}")
        if not isinstance(self.max_steps, int) or isinstance(self.max_steps, bool) \
                or self.max_steps < 1:
            raise ConfigError(f"max_steps must be a whole number >= 1, got {self.max_steps!r}")
        if not isinstance(self.stop, bool):
            raise ConfigError(f"stop must be true or false, got {self.stop!r}")
        object.__setattr__(self, "arm", arm_config(self.arm))
        self.sim_config()
        self.adapter_config()

    def __getattr__(self, name: str):
        # the robot's options read through (``cfg.strategy``); only called for missing attributes
        if name != "robot" and not name.startswith("__") and name in AdapterConfig.model_fields:
            return getattr(self.robot, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @classmethod
    def flat(cls, **options) -> AdaptConfig:
        """Build from one flat set of options (robot and loop options mixed), as flags give them."""
        return cls.from_dict(options)

    def with_robot(self, **changes) -> AdaptConfig:
        """A copy with some robot options changed."""
        return replace(self, robot=self.robot.replace(**changes))

    def sim_config(self) -> SimConfig:
        return SimConfig(mode=self.mode, reach_noise=self.reach_noise, arm=self.arm)

    def adapter_config(self) -> AdapterConfig:
        """The robot-side config (``blur`` is the reach noise under ``aim`` feedback)."""
        if self.feedback == "aim":
            return self.robot.replace(blur=float(self.reach_noise))
        return self.robot

    def to_dict(self) -> dict:
        """Every resolved option, the robot's nested under ``robot``."""
        d = {k: getattr(self, k) for k in LOOP_FIELDS}
        d["arm"] = self.arm.to_dict()
        return {"robot": self.robot.to_dict(), **d}

    @classmethod
    def from_dict(cls, d: dict) -> AdaptConfig:
        """Build from a mapping (a TOML table, an artifact's config); unknown keys are rejected.

        Takes the nested layout (``robot = {...}`` beside the loop options) and the flat one of
        schema-1 artifacts (robot options at the top level); a robot option given at the top level
        overrides the same option in the ``robot`` table (as a command-line flag overrides a TOML
        file).
        """
        if not isinstance(d, dict):
            raise ConfigError("the adapt options must be a table")
        robot_keys = set(AdapterConfig.model_fields)
        flat = {k: v for k, v in d.items() if k in robot_keys}
        rest = {k: v for k, v in d.items() if k not in robot_keys}
        known = set(cls.__dataclass_fields__) | robot_keys
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"unknown adapt option(s) {', '.join(unknown)}; valid: "
                              f"{', '.join(sorted(known))}")
        robot = rest.pop("robot", None)
        if isinstance(robot, AdapterConfig):
            robot = robot.to_dict()
        if robot is None:
            robot = {}
        if not isinstance(robot, dict):
            raise ConfigError("robot must be a table of adapter options")
        robot_cfg = AdapterConfig.from_dict({**robot, **flat})
        return cls(robot=robot_cfg, **rest)


@dataclass(frozen=True, kw_only=True)
class PlayCheck:
    """Playing success measured by replaying the melody (Algorithm 1) around an adaptation.

    Parameters
    ----------
    melody : str
        Notes ``NOTE:BEATS`` (:mod:`kbcli.core.melody`).
    notes : int
        Touches per replay.
    reference : bool
        Also replay before the displacement and after it without adaptation (else only after
        adaptation, with the final estimate).
    """

    melody: str = DEFAULT_MELODY
    notes: int = 200
    reference: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.notes, int) or isinstance(self.notes, bool) or self.notes < 1:
            raise ConfigError(f"play notes must be a whole number >= 1, got {self.notes!r}")


def play_success(model, keyboard: Keyboard, sim: SimConfig, family: str, truth: np.ndarray,
                 estimate: np.ndarray | None, check: PlayCheck, *, rng: np.random.Generator,
                 pool: ActionSamples | None = None) -> dict[str, float]:
    """Success rates (MATCH share) of ``check.notes`` touches of Algorithm 1 with the model's
    actions and the arm of ``sim``: ``before`` (keyboard at its reference pose), ``unadapted``
    (at ``truth``, no correction) and ``adapted`` (at ``truth``, actions corrected by
    ``estimate``); NaN for what was not measured. ``pool``: per-class draws of p(action | sound)
    to resample instead of calling ``model.sample_actions`` (see :func:`kbcli.core.play.replay`).
    """
    melody = parse_melody(check.melody, keyboard)
    n = len(transforms.FAMILIES.get(family).params)
    out = {"before": math.nan, "unadapted": math.nan, "adapted": math.nan}
    runs = []
    if check.reference:
        runs += [("before", np.zeros(n), None), ("unadapted", truth, None)]
    if estimate is not None:
        runs.append(("adapted", truth, np.asarray(estimate, float)))
    for (name, pose, corr), r in zip(runs, rng.spawn(len(runs)), strict=True):
        world = World(keyboard, make_reacher(sim), np.asarray(pose, float), family)

        def touch(actions: np.ndarray, world=world, r=r) -> tuple[np.ndarray, np.ndarray]:
            return world.touch(actions, r)

        hist = replay(model, melody, touch, rng=r, n_notes=check.notes, correction=corr,
                      family=family, sampler=None if pool is None else pool.draw)
        out[name] = float(np.mean(hist == MATCH))
    return out


def _errors(est: np.ndarray, truth: np.ndarray, robot_family: str,
            world_family: str) -> tuple[float, float]:
    """Translation error (px) and angle error (deg) of an estimate against the truth."""
    t_err = float(np.hypot(*(est[-2:] - truth[-2:])))
    a_est = transforms.FAMILIES.get(robot_family).angle(est)
    a_true = transforms.FAMILIES.get(world_family).angle(truth)
    return t_err, abs(transforms.wrap_degrees(a_est - a_true))


#: Per-step records of a ``run`` artifact, in the order :meth:`Recorder.add` takes them.
RECORDS = ("actions", "landed", "perceived", "classes", "estimates", "means", "errors", "ml_errors",
           "angle_errors", "entropy", "ml_prob", "mass", "stop", "step_ms")


class Recorder:
    """The per-step records and posterior snapshots of one adaptation: what a ``run`` artifact
    holds, whoever touched (the simulated world in :func:`experiment`, or a robot in another
    process through ``kbcli serve``, :mod:`kbcli.stages.serve`).

    Parameters
    ----------
    adapter : Adapter
        The robot's adapter (read after each step).
    snapshot_steps : iterable of int
        Steps (0: the prior) at which to keep the posterior.
    """

    def __init__(self, adapter: Adapter, snapshot_steps=()) -> None:
        self.adapter = adapter
        self.snaps = {int(s) for s in snapshot_steps if int(s) >= 0}
        self.rec: dict[str, list] = {k: [] for k in RECORDS}
        self.joint_angles: list[np.ndarray] = []
        self.model_error: list[tuple[float, float]] = []
        self.snap_t: list[int] = []
        self.snap_log: list[np.ndarray] = []
        self.snap_ang: list[np.ndarray] = []
        if 0 in self.snaps:
            self.snapshot(0)

    def __len__(self) -> int:
        return len(self.rec["actions"])

    def snapshot(self, t: int) -> None:
        """Keep the current posterior as the one after step ``t``."""
        post = self.adapter.posterior
        self.snap_t.append(t)
        with np.errstate(divide="ignore"):
            self.snap_log.append(np.log(post.translation_marginal()).astype(np.float32))
        pa = post.marginals()[0]
        self.snap_ang.append(np.ones(1) if pa is None else pa)

    def add(self, st: Step, errors: tuple[float, float, float] = (np.nan, np.nan, np.nan),
            joint_angles: np.ndarray | None = None) -> None:
        """Record one step; ``errors`` = (px error of the estimate, of the ML cell, angle error
        in degrees) against the truth (NaN when it is unknown, as for a real robot)."""
        err, ml_err, aerr = errors
        for k, v in zip(RECORDS, (st.action, st.landed, st.perceived, st.cls, st.ml, st.mean, err,
                                  ml_err, aerr, st.entropy, st.ml_prob, st.mass, st.stop, st.ms),
                        strict=True):
            self.rec[k].append(v)
        if joint_angles is not None:
            self.joint_angles.append(np.asarray(joint_angles, float).reshape(2))
        robust = getattr(self.adapter, "robust", None)
        if robust is not None:
            self.model_error.append((robust.blur_mean(), robust.outlier_mean()))
        if st.t in self.snaps:
            self.snapshot(st.t)

    def arrays(self) -> dict[str, np.ndarray]:
        """The records as arrays (see :func:`experiment`'s Returns)."""
        g = self.adapter.grid
        d = int(np.shape(self.adapter.model.class_features_)[1])
        out = {k: np.asarray(v) for k, v in self.rec.items()}
        for k, width in (("actions", 2), ("landed", 2), ("perceived", d),
                         ("estimates", g.n_params), ("means", g.n_params)):
            out[k] = np.asarray(out[k], float).reshape(-1, width)
        for k in ("errors", "ml_errors", "angle_errors", "entropy", "ml_prob", "mass", "step_ms"):
            out[k] = np.asarray(out[k], float)
        out["classes"] = out["classes"].astype(np.int64)
        out["stop"] = out["stop"].astype(bool)
        if self.joint_angles and len(self.joint_angles) == len(self):
            out["joint_angles"] = np.stack(self.joint_angles)
        if self.model_error and len(self.model_error) == len(self):
            me = np.asarray(self.model_error, float)
            out["blur_mean"], out["outlier_mean"] = me[:, 0], me[:, 1]
        out.update(dx=g.dx, dy=g.dy, angles=g.angles,
                   snapshot_steps=np.asarray(self.snap_t, np.int64))
        if self.snap_t:
            out["snapshots"] = np.stack(self.snap_log)
            out["snapshot_angles"] = np.stack(self.snap_ang)
        if POSTERIORS.get(self.adapter.cfg.posterior).uses_samples:
            out["bandwidths"] = np.asarray(self.adapter.bandwidths, float)
        out["redundancy_radius"] = np.float64(getattr(self.adapter, "redundancy_radius", 0.0))
        rob = getattr(self.adapter, "robust", None)
        out["robust_blurs"] = (np.asarray(rob.nuisance.blurs, float) if rob is not None
                               else np.empty(0))
        out["robust_eta"] = np.float64(rob.eta if rob is not None else 1.0)
        return out


def end_angles(reacher) -> np.ndarray | None:
    """(n, 2) joint angles the reacher ended its last reaches in (dynamics mode), else None."""
    ang = getattr(reacher, "last_end_angles", None)
    return None if ang is None else np.asarray(ang, float).reshape(-1, 2)


def experiment(cfg: AdaptConfig, model, keyboard: Keyboard, true_params: np.ndarray, *,
               rng: np.random.Generator, world_family: str | None = None,
               table: LikelihoodTable | None = None,
               snapshot_steps: tuple[int, ...] = (), samples: ActionSamples | None = None,
               play: PlayCheck | None = None,
               play_pool: ActionSamples | None = None,
               on_step: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """One adaptation against a world whose keyboard sits at ``true_params``.

    Parameters
    ----------
    model : SoundModel
        The robot's model (exact or learned).
    keyboard : Keyboard
        The instrument (world side).
    true_params : (P,) ndarray
        The true displacement in ``world_family`` parameters (default: ``cfg.robot.family``).
    rng : numpy.random.Generator
        Split into the robot's and the world's generators.
    table : LikelihoodTable, optional
        A prebuilt :func:`kbcli.core.adapt.build_table` for ``model`` (rasterise once, reuse).
    snapshot_steps : tuple of int
        Steps (0: the prior) at which to keep the posterior.
    samples : ActionSamples, optional
        The ``kde`` posterior's per-class samples (:func:`kbcli.core.adapt.build_samples`), shared
        across experiments; default: drawn per run.
    play : PlayCheck, optional
        Also measure the playing success (adds ``play_before``, ``play_unadapted``,
        ``play_adapted``, each a float, NaN when not measured), from a third child of ``rng``.
    play_pool : ActionSamples, optional
        Per-class draws of p(action | sound) the replays resample (default: the model samples).
    on_step : callable, optional
        Called with the step number after each observation (a progress bar).

    Returns
    -------
    dict of ndarrays, per step t = 1..T (T = ``max_steps``, fewer when ``cfg.stop`` ends early)
        ``actions`` (T, 2), ``landed`` (T, 2) where the robot felt it landed, ``true_landed``
        (T, 2) where it did (world side), ``perceived`` (T, D), ``classes`` (T,),
        ``estimates`` (T, P) maximum-likelihood cell, ``means`` (T, P) posterior mean,
        ``errors`` (T,) px error of the estimate (``cfg.robot.estimator``) vs truth, ``ml_errors`` (T,),
        ``angle_errors`` (T,) deg, ``entropy`` (T,) nats, ``ml_prob`` (T,), ``mass`` (T,),
        ``stop`` (T,) bool, ``step_ms`` (T,); ``joint_angles`` (T, 2) the arm's pose after each
        touch (dynamics mode); ``snapshot_steps`` (S,), ``snapshots`` (S, ny, nx)
        log translation marginals, ``snapshot_angles`` (S, A) angle marginals (rigid); ``dx``,
        ``dy``, ``angles`` grid axes.
    """
    world_family = cfg.robot.family if world_family is None else world_family
    truth = np.asarray(true_params, float)
    robot_rng, world_rng = rng.spawn(2)
    acfg = cfg.adapter_config()
    adapter = Adapter(model, acfg, rng=robot_rng, table=table, samples=samples)
    world = World(keyboard, make_reacher(cfg.sim_config()), truth, world_family)
    poses: list[np.ndarray] = []

    true_landed: list[np.ndarray] = []

    def touch(action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        felt, heard = world.touch(action[None, :], world_rng)
        true_landed.append(world.last_landed[0])
        ang = end_angles(world.reacher)
        if ang is not None and len(ang):
            poses.append(ang[-1])
        return felt[0], heard[0]

    snaps = [s for s in snapshot_steps if 0 <= int(s) <= cfg.max_steps]
    rec = Recorder(adapter, snaps)
    for st in adapt(adapter, touch, cfg.max_steps, use_landed=cfg.feedback == "landed",
                    stop=cfg.stop):
        err, aerr = _errors(st.estimate, truth, cfg.robot.family, world_family)
        ml_err, _ = _errors(st.ml, truth, cfg.robot.family, world_family)
        rec.add(st, (err, ml_err, aerr), poses[-1] if poses else None)
        if on_step is not None:
            on_step(st.t)
    out = rec.arrays()
    out["true_landed"] = np.asarray(true_landed, float).reshape(-1, 2)
    if play is not None:
        final = ESTIMATORS.get(cfg.robot.estimator).final(out)
        if world_family != cfg.robot.family:  # correct in the world's parameters
            final = _as_family(final, cfg.robot.family, world_family)
        res = play_success(model, keyboard, cfg.sim_config(), world_family, truth, final, play,
                           rng=rng.spawn(1)[0], pool=play_pool)
        out.update({f"play_{k}": np.float64(v) for k, v in res.items()})
    return out


def _as_family(est: np.ndarray, family: str, world_family: str) -> np.ndarray:
    """An estimate in ``family`` parameters as ``world_family`` parameters (angle 0 added or
    dropped)."""
    est = np.asarray(est, float)
    if family == world_family:
        return est
    fam = transforms.FAMILIES.get(family)
    return transforms.FAMILIES.get(world_family).compose(fam.angle(est), fam.shift(est))


def _inside_prior(cfg: AdaptConfig, truth: np.ndarray, world_family: str) -> bool:
    """Whether the true pose lies in the robot's prior box (else no estimate can reach it)."""
    inside = bool(np.all(np.abs(truth[-2:]) <= cfg.robot.prior_halfwidth))
    angle = transforms.FAMILIES.get(world_family).angle(truth)
    limit = cfg.robot.max_angle if transforms.FAMILIES.get(cfg.robot.family).rotates else 0.0
    return inside and abs(angle) <= limit + 1e-9


def steps_below(errors: np.ndarray, threshold: float) -> int | None:
    """First step (1-based) with ``errors < threshold``; None if never."""
    hit = np.flatnonzero(np.asarray(errors) < threshold)
    return int(hit[0] + 1) if len(hit) else None


def _resolved(kb: dict | None) -> dict | None:
    """A keyboard table with every default filled in (schema 1 tables lack ``layout``)."""
    if kb is None:
        return None
    try:
        return KeyboardConfig.from_dict(kb).to_dict()
    except KbcliError:
        return kb


def check_inputs(model_artifact: Artifact, scene_artifact: Artifact) -> None:
    """Refuse artifacts of the wrong kind and a scene whose keyboard is not the model's."""
    if model_artifact.kind != "model":
        raise ArtifactError(f"{model_artifact.path or 'model'}: is a {model_artifact.kind} "
                            f"artifact, expected model")
    if scene_artifact.kind != "scene":
        raise ArtifactError(f"{scene_artifact.path or 'scene'}: is a {scene_artifact.kind} "
                            f"artifact, expected scene")
    km, ks = (_resolved(a.config.get("keyboard")) for a in (model_artifact, scene_artifact))
    if km != ks:
        diff = sorted(k for k in set(km or {}) | set(ks or {})
                      if (km or {}).get(k) != (ks or {}).get(k))
        raise KbcliError(f"the scene's keyboard does not match the model's (differs in "
                         f"{', '.join(diff) or 'everything'}): perturb the keyboard the model "
                         f"was learned on")


def run(cfg: AdaptConfig, model_artifact: Artifact, scene_artifact: Artifact, *,
        rng: np.random.Generator, seed: int | None = None,
        snapshot_steps: tuple[int, ...] = DEFAULT_SNAPSHOTS, model=None,
        on_step: Callable[[int], None] | None = None) -> Artifact:
    """Adapt to a scene with a model: the ``run`` artifact.

    Parameters
    ----------
    seed : int, optional
        Recorded in the artifact (``rng`` should be ``default_rng(seed)``).
    model : SoundModel, optional
        The already loaded model of ``model_artifact`` (saves loading it again).
    on_step : callable, optional
        Called with the step number after each observation (a progress bar).

    Raises
    ------
    ArtifactError, KbcliError
        Wrong kinds, mismatching keyboards.
    """
    check_inputs(model_artifact, scene_artifact)
    model = load_model(model_artifact) if model is None else model
    kb = keyboard_stage.load(scene_artifact)
    world_family = scene_artifact.config["family"]
    truth = np.asarray(scene_artifact.config["params"], float)
    res = experiment(cfg, model, kb, truth, rng=rng, world_family=world_family,
                     snapshot_steps=snapshot_steps, on_step=on_step)
    attrs = run_attrs(res, cfg.adapter_config(), truth=truth, world_family=world_family)
    attrs["truth_inside_prior"] = _inside_prior(cfg, truth, world_family)
    sim = cfg.sim_config()
    attrs["mode"] = cfg.mode
    attrs["arm"] = {"base": list(sim.base), "link_lengths": list(sim.link_lengths)}
    return Artifact(
        kind="run",
        config={"adapt": cfg.to_dict(), "keyboard": model_artifact.config["keyboard"],
                "snapshot_steps": [int(s) for s in snapshot_steps]},
        seed=seed,
        data=run_data(res),
        attrs=attrs,
        inputs={"model": ref(model_artifact), "scene": ref(scene_artifact)},
    )


def run_attrs(res: dict[str, np.ndarray], acfg: AdapterConfig, *, truth: np.ndarray | None = None,
              world_family: str | None = None) -> dict:
    """The summary of a ``run`` artifact from its records (:meth:`Recorder.arrays`).

    Without a ``truth`` (a real robot, ``kbcli serve``) the errors are unknown: ``truth``,
    ``final_error_px``, ``final_angle_error_deg`` and ``steps_to_1px`` are None. A run of no step
    has no estimate.
    """
    names = transforms.FAMILIES.get(acfg.family).params
    errors = np.asarray(res["errors"], float)
    n = int(len(errors))
    known = truth is not None and n > 0
    reach1 = None
    if known:
        angle_ok = res["angle_errors"] < 0.5
        reach1 = steps_below(np.where(angle_ok, errors, np.inf), 1.0)
    stop_at = np.flatnonzero(res["stop"])
    final = None
    if n:
        final = ESTIMATORS.get(acfg.estimator).final(res)
    wf = world_family or acfg.family
    return {
        "strategy": acfg.strategy,
        "posterior": acfg.posterior,
        "family": acfg.family,
        "world_family": wf if truth is not None else None,
        "steps": n,
        "final_error_px": float(errors[-1]) if known else None,
        "final_angle_error_deg": float(res["angle_errors"][-1]) if known else None,
        "steps_to_1px": reach1,
        "stop_step": int(stop_at[0] + 1) if len(stop_at) else None,
        "final_entropy": float(res["entropy"][-1]) if n else None,
        "estimate": None if final is None else
        {k: float(v) for k, v in zip(names, final, strict=True)},
        "truth": None if truth is None else
        {k: float(v) for k, v in zip(transforms.FAMILIES.get(wf).params, truth, strict=True)},
        "grid_cells": acfg.grid_cells,
        "median_step_ms": float(np.median(res["step_ms"])) if n else None,
        # resolved from the model's own reliability when the config leaves it None
        "redundancy_radius": float(res["redundancy_radius"]) if "redundancy_radius" in res else None,
        # the boundary blurs the robust posterior weighed (widened for a weak model; [] if plain)
        "robust_blurs": ([float(v) for v in res["robust_blurs"]] if "robust_blurs" in res
                         else None),
        # the learning rate the robust posterior tempered each touch with (1: untempered)
        "robust_eta": float(res["robust_eta"]) if "robust_eta" in res else None,
    }


def run_data(res: dict[str, np.ndarray]) -> dict:
    """The datasets of a ``run`` artifact: the records, with the wall-clock times in ``timing/``."""
    data = {k: v for k, v in res.items()
            if k not in ("step_ms", "redundancy_radius", "robust_blurs", "robust_eta")}
    data["timing"] = {"step_ms": res["step_ms"]}
    return data


def build_shared_table(cfg: AdaptConfig, model) -> LikelihoodTable:
    """The model raster for ``cfg`` (to share across many :func:`experiment` calls)."""
    return build_table(model, cfg.adapter_config())


def build_shared_samples(cfg: AdaptConfig, model, seed) -> ActionSamples | None:
    """The ``kde`` posterior's per-class samples for ``cfg`` (None for other posteriors), drawn
    from ``seed`` once per class, to share across many :func:`experiment` calls."""
    if not POSTERIORS.get(cfg.robot.posterior).uses_samples:
        return None
    return build_samples(model, cfg.adapter_config(), seed)


__all__ = ["AdaptConfig", "PlayCheck", "play_success", "experiment", "run", "check_inputs",
           "steps_below", "build_shared_table", "build_shared_samples", "LOOP_FIELDS",
           "Recorder", "run_attrs", "run_data", "RECORDS", "POSTERIORS", "FEEDBACKS",
           "DEFAULT_SNAPSHOTS"]
