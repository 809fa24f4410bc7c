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
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from kbcli.core import transforms
from kbcli.core.adapt import POSTERIORS, Adapter, AdapterConfig, Step, adapt, build_table
from kbcli.core.config import check_known
from kbcli.core.keyboard import Keyboard
from kbcli.core.posterior import LikelihoodTable
from kbcli.core.robust import DEFAULT_BLURS, DEFAULT_OUTLIERS
from kbcli.errors import ArtifactError, ConfigError, KbcliError
from kbcli.sim import MODES, SimConfig, World, make_reacher
from kbcli.sim.arms import PRESETS, ArmConfig, arm_config
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.models import load_model

FEEDBACKS = ("landed", "aim")
DEFAULT_SNAPSHOTS = (0, 1, 2, 3, 5, 10, 20, 40)


@dataclass(frozen=True, kw_only=True)
class AdaptConfig:
    """One adaptation: the robot's settings (see :class:`kbcli.core.adapt.AdapterConfig`, whose
    fields are repeated here) plus the simulated arm's and the loop's.

    Parameters
    ----------
    mode : str
        ``ideal`` or ``dynamics`` (:class:`kbcli.sim.SimConfig`).
    reach_noise : float
        Landing scatter of the arm, px.
    feedback : str
        ``landed``: the robot observes where its finger landed (proprioception); ``aim``: only where
        it aimed, and blurs its likelihood by ``reach_noise``.
    arm : ArmConfig
        How the simulated arm errs (:mod:`kbcli.sim.arms`; a preset name or a table is accepted):
        its landing error, its finger and how well it feels where it landed.
    model_blur : float or None
        Extra softening of the model's map, px (see :class:`kbcli.core.adapt.AdapterConfig`;
        None: 1 px for a learned model, 0 for the exact one).
    max_steps : int
        T, observations at most.
    stop : bool
        End at the stopping rule (else always run T steps and record when the rule fired).
    """

    strategy: str = "infogain"
    posterior: str = "likelihood"
    family: str = "translation"
    mode: str = "ideal"
    reach_noise: float = 0.0
    feedback: str = "landed"
    arm: ArmConfig = PRESETS["ideal"]
    robust: bool = True
    robust_blurs: tuple[float, ...] = DEFAULT_BLURS
    robust_outliers: tuple[float, ...] = DEFAULT_OUTLIERS
    model_blur: float | None = None
    max_steps: int = 40
    stop: bool = False
    resolution: float = 0.5
    prior_halfwidth: float = 45.0
    max_angle: float = 5.0
    angle_resolution: float = 0.25
    outlier: float = 1e-3
    cell_average: bool = True
    raster_step: float | None = None
    candidates: int = 256
    hypotheses: int = 512
    active_keep: int = 8
    active_hypotheses: int = 2048
    kde_samples: int = 10000
    kde_bandwidth: float | None = None
    estimator: str = "mean"
    stop_ml: float | None = None
    stop_mass: float = 0.95
    stop_radius: float = 1.0
    stop_angle: float = 0.5
    max_memory_mb: float = 2048.0

    def __post_init__(self) -> None:
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
        for name in ("robust_blurs", "robust_outliers"):
            v = getattr(self, name)
            if isinstance(v, list):
                object.__setattr__(self, name, tuple(v))
        self.sim_config()
        self.adapter_config()

    def sim_config(self) -> SimConfig:
        return SimConfig(mode=self.mode, reach_noise=self.reach_noise, arm=self.arm)

    def adapter_config(self) -> AdapterConfig:
        """The robot-side config (``blur`` is the reach noise under ``aim`` feedback)."""
        d = {k: v for k, v in asdict(self).items() if k in AdapterConfig.__dataclass_fields__}
        d["blur"] = float(self.reach_noise) if self.feedback == "aim" else 0.0
        return AdapterConfig(**d)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["arm"] = self.arm.to_dict()
        d["robust_blurs"] = list(self.robust_blurs)
        d["robust_outliers"] = list(self.robust_outliers)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> AdaptConfig:
        """Build from a mapping (a TOML table, an artifact's config); unknown keys are rejected."""
        check_known(cls, d, "adapt")
        return cls(**d)


def _errors(est: np.ndarray, truth: np.ndarray, robot_family: str,
            world_family: str) -> tuple[float, float]:
    """Translation error (px) and angle error (deg) of an estimate against the truth."""
    t_err = float(np.hypot(*(est[-2:] - truth[-2:])))
    a_est = float(est[0]) if robot_family == "rigid" else 0.0
    a_true = float(truth[0]) if world_family == "rigid" else 0.0
    return t_err, abs(a_est - a_true)


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
        if self.adapter.cfg.posterior == "kde":
            out["bandwidths"] = np.asarray(self.adapter.bandwidths, float)
        return out


def end_angles(reacher) -> np.ndarray | None:
    """(n, 2) joint angles the reacher ended its last reaches in (dynamics mode), else None."""
    ang = getattr(reacher, "last_end_angles", None)
    return None if ang is None else np.asarray(ang, float).reshape(-1, 2)


def experiment(cfg: AdaptConfig, model, keyboard: Keyboard, true_params: np.ndarray, *,
               rng: np.random.Generator, world_family: str | None = None,
               table: LikelihoodTable | None = None,
               snapshot_steps: tuple[int, ...] = ()) -> dict[str, np.ndarray]:
    """One adaptation against a world whose keyboard sits at ``true_params``.

    Parameters
    ----------
    model : SoundModel
        The robot's model (exact or learned).
    keyboard : Keyboard
        The instrument (world side).
    true_params : (P,) ndarray
        The true displacement in ``world_family`` parameters (default: ``cfg.family``).
    rng : numpy.random.Generator
        Split into the robot's and the world's generators.
    table : LikelihoodTable, optional
        A prebuilt :func:`kbcli.core.adapt.build_table` for ``model`` (rasterise once, reuse).
    snapshot_steps : tuple of int
        Steps (0: the prior) at which to keep the posterior.

    Returns
    -------
    dict of ndarrays, per step t = 1..T (T = ``max_steps``, fewer when ``cfg.stop`` ends early)
        ``actions`` (T, 2), ``landed`` (T, 2) where the robot felt it landed, ``true_landed``
        (T, 2) where it did (world side), ``perceived`` (T, D), ``classes`` (T,),
        ``estimates`` (T, P) maximum-likelihood cell, ``means`` (T, P) posterior mean,
        ``errors`` (T,) px error of the estimate (``cfg.estimator``) vs truth, ``ml_errors`` (T,),
        ``angle_errors`` (T,) deg, ``entropy`` (T,) nats, ``ml_prob`` (T,), ``mass`` (T,),
        ``stop`` (T,) bool, ``step_ms`` (T,); ``joint_angles`` (T, 2) the arm's pose after each
        touch (dynamics mode); ``snapshot_steps`` (S,), ``snapshots`` (S, ny, nx)
        log translation marginals, ``snapshot_angles`` (S, A) angle marginals (rigid); ``dx``,
        ``dy``, ``angles`` grid axes.
    """
    world_family = cfg.family if world_family is None else world_family
    truth = np.asarray(true_params, float)
    robot_rng, world_rng = rng.spawn(2)
    acfg = cfg.adapter_config()
    adapter = Adapter(model, acfg, rng=robot_rng, table=table)
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
        err, aerr = _errors(st.estimate, truth, cfg.family, world_family)
        ml_err, _ = _errors(st.ml, truth, cfg.family, world_family)
        rec.add(st, (err, ml_err, aerr), poses[-1] if poses else None)
    out = rec.arrays()
    out["true_landed"] = np.asarray(true_landed, float).reshape(-1, 2)
    return out


def _inside_prior(cfg: AdaptConfig, truth: np.ndarray, world_family: str) -> bool:
    """Whether the true pose lies in the robot's prior box (else no estimate can reach it)."""
    inside = bool(np.all(np.abs(truth[-2:]) <= cfg.prior_halfwidth))
    angle = float(truth[0]) if world_family == "rigid" else 0.0
    limit = cfg.max_angle if cfg.family == "rigid" else 0.0
    return inside and abs(angle) <= limit + 1e-9


def steps_below(errors: np.ndarray, threshold: float) -> int | None:
    """First step (1-based) with ``errors < threshold``; None if never."""
    hit = np.flatnonzero(np.asarray(errors) < threshold)
    return int(hit[0] + 1) if len(hit) else None


def check_inputs(model_artifact: Artifact, scene_artifact: Artifact) -> None:
    """Refuse artifacts of the wrong kind and a scene whose keyboard is not the model's."""
    if model_artifact.kind != "model":
        raise ArtifactError(f"{model_artifact.path or 'model'}: is a {model_artifact.kind} "
                            f"artifact, expected model")
    if scene_artifact.kind != "scene":
        raise ArtifactError(f"{scene_artifact.path or 'scene'}: is a {scene_artifact.kind} "
                            f"artifact, expected scene")
    km, ks = model_artifact.config.get("keyboard"), scene_artifact.config.get("keyboard")
    if km != ks:
        diff = sorted(k for k in set(km or {}) | set(ks or {})
                      if (km or {}).get(k) != (ks or {}).get(k))
        raise KbcliError(f"the scene's keyboard does not match the model's (differs in "
                         f"{', '.join(diff) or 'everything'}): perturb the keyboard the model "
                         f"was learned on")


def run(cfg: AdaptConfig, model_artifact: Artifact, scene_artifact: Artifact, *,
        rng: np.random.Generator, seed: int | None = None,
        snapshot_steps: tuple[int, ...] = DEFAULT_SNAPSHOTS, model=None) -> Artifact:
    """Adapt to a scene with a model: the ``run`` artifact.

    Parameters
    ----------
    seed : int, optional
        Recorded in the artifact (``rng`` should be ``default_rng(seed)``).
    model : SoundModel, optional
        The already loaded model of ``model_artifact`` (saves loading it again).

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
                     snapshot_steps=snapshot_steps)
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
    names = transforms.FAMILIES[acfg.family]
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
        final = res["means"][-1] if acfg.estimator == "mean" else res["estimates"][-1]
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
        {k: float(v) for k, v in zip(transforms.FAMILIES[wf], truth, strict=True)},
        "grid_cells": acfg.grid_cells,
        "median_step_ms": float(np.median(res["step_ms"])) if n else None,
    }


def run_data(res: dict[str, np.ndarray]) -> dict:
    """The datasets of a ``run`` artifact: the records, with the wall-clock times in ``timing/``."""
    data = {k: v for k, v in res.items() if k != "step_ms"}
    data["timing"] = {"step_ms": res["step_ms"]}
    return data


def build_shared_table(cfg: AdaptConfig, model) -> LikelihoodTable:
    """The model raster for ``cfg`` (to share across many :func:`experiment` calls)."""
    return build_table(model, cfg.adapter_config())


__all__ = ["AdaptConfig", "experiment", "run", "check_inputs", "steps_below", "build_shared_table",
           "Recorder", "run_attrs", "run_data", "RECORDS", "POSTERIORS", "FEEDBACKS",
           "DEFAULT_SNAPSHOTS"]
