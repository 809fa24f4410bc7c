"""The robot's side of the adaptation: :class:`Adapter` decides, observes, estimates and stops.

It never sees the true pose. An ask/tell loop: ``suggest()``, ``observe(action, heard,
felt_position=None)``, then ``estimate()``, ``entropy()``, ``done()``. An unknown sound (class -1)
is skipped; silence is an observation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.config import AdapterConfig, learning_rate, redundancy_radius
from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.inputs import check_action, check_heard, check_point
from kbcli.core.adaptation.posteriors import Observation
from kbcli.core.adaptation.posteriors.kde.samples import ActionSamples
from kbcli.core.adaptation.posteriors.likelihood.blur import blurred_map, planning_table
from kbcli.core.adaptation.posteriors.likelihood.robust import RobustPosterior
from kbcli.core.adaptation.posteriors.posterior import Posterior
from kbcli.core.adaptation.repair import RepairBelief, absorb
from kbcli.core.adaptation.setup import build_table, hypothesis_grid, spot_count
from kbcli.core.adaptation.strategies import STRATEGIES, Context
from kbcli.core.model.sounds import UNKNOWN
from kbcli.core.model.table import LikelihoodTable
from kbcli.errors import ConfigError


@dataclass(frozen=True)
class Estimate:
    """Estimates of the transform parameters, in family order (``[angle,] dx, dy``)."""

    ml: np.ndarray
    mean: np.ndarray
    ml_prob: float


class Adapter:
    """The robot's side of the adaptation: decide, observe, estimate, stop.

    Parameters
    ----------
    model : SoundModel
        The learned (or exact) model of the instrument at its reference pose.
    cfg : AdapterConfig
    rng : numpy.random.Generator
        Drives the strategy's candidate sampling and the KDE's samples.
    area : tuple of float, optional
        Where actions may go (default: the model's working area).
    centre : (2,) ndarray, optional
        Rotation centre of the rigid family (default: the centre of ``area``, which is the
        keyboard's centre at its reference pose).
    table : LikelihoodTable, optional
        A prebuilt :func:`build_table` (saves rasterising the model again).
    samples : ActionSamples, optional
        The ``kde`` posterior's samples of p(action | sound), shared (:func:`build_samples`);
        default: this adapter's own, seeded from ``rng``.
    max_steps : int, optional
        A touch budget after which :meth:`done` holds (None: only the stopping rule).

    Examples
    --------
    The ask/tell loop, with a touch of the bundled simulator::

        adapter = Adapter.from_model("data/default-model.h5", strategy="infogain", seed=0)
        while not adapter.done():
            action = adapter.suggest()
            felt, heard = robot_touch(action)   # your robot: where it felt it landed, what it heard
            adapter.observe(action, heard, felt_position=felt)
        print(adapter.estimate(), adapter.entropy())
    """

    def __init__(self, model, cfg: AdapterConfig, *, rng: np.random.Generator,
                 area: tuple[float, float, float, float] | None = None,
                 centre: np.ndarray | None = None, table: LikelihoodTable | None = None,
                 samples: ActionSamples | None = None,
                 max_steps: int | None = None) -> None:
        if max_steps is not None and (not isinstance(max_steps, int) or isinstance(max_steps, bool)
                                      or max_steps < 1):
            raise ConfigError(f"max_steps must be a whole number >= 1, got {max_steps!r}")
        self.max_steps = max_steps
        #: touches observed so far (unknown sounds included; ``posterior.n_obs`` counts updates)
        self.touches = 0
        self.model = model
        self.cfg = cfg
        self.rng = rng
        self.area = tuple(float(v) for v in (model.area if area is None else area))
        self.grid = hypothesis_grid(cfg, self.area, centre)
        self.table = build_table(model, cfg, self.area) if table is None else table
        # own generators (spawning does not move ``rng``'s stream): ML ties, fresh KDE samples
        self.kind = cfg.kind  #: the kind of posterior (:data:`~.posteriors.POSTERIORS`)
        own = dict(zip(("ties", "kde"), rng.spawn(2), strict=True)) \
            if cfg.ml_ties == "random" or self.kind.draws_fresh(cfg) else {}
        #: seed of the ML cell's tie-breaking (None: the lowest index wins, ``ml_ties = "first"``)
        self.tie_seed = int(own["ties"].integers(2**63)) if cfg.ml_ties == "random" else None
        self.posterior = Posterior.uniform(self.grid, tie_seed=self.tie_seed)
        #: the robust posterior (None with the plain one); ``posterior`` is then its marginal
        self.robust: RobustPosterior | None = (
            RobustPosterior(self.grid, cfg.nuisance(model), eta=learning_rate(model, cfg))
            if cfg.is_robust and not cfg.repairs else None)
        #: the joint belief over the shift and the repaired map (``repair``; None otherwise):
        #: ``posterior`` is then its marginal over the shift (:mod:`kbcli.core.adaptation.repair`)
        self.repair: RepairBelief | None = (
            RepairBelief.for_model(self.grid, self.table, model, cfg) if cfg.repairs else None)
        self._strategy = STRATEGIES.get(cfg.strategy.name)
        #: px: touches this close count as one spot (robust posterior; see AdapterConfig)
        self.redundancy_radius = redundancy_radius(model, cfg) if self.robust is not None else 0.0
        #: where each observed touch was read (felt position, or the aim)
        self.points: list[np.ndarray] = []
        self._edges: np.ndarray | None = None
        self._corners: np.ndarray | None = None
        self.bandwidths: list[float] = []
        #: what the kind's terms read besides the model (the KDE's samples of p(action | sound)),
        #: and what the simulated touches of ``paper-active`` read (the kind's ``sources``)
        self.samples, self.simulation_samples = self.kind.sources(self, own.get("kde"), rng,
                                                                   samples)

    @classmethod
    def from_model(cls, model, *, strategy: str = "infogain", family: str = "translation",
                   seed: int | None = None, rng: np.random.Generator | None = None,
                   config: AdapterConfig | None = None, max_steps: int | None = None,
                   **options) -> Adapter:
        """An adapter for a model object (:class:`kbcli.api.Adapter` also reads a model file).

        Parameters
        ----------
        model : SoundModel
        strategy, family : str
            See :class:`AdapterConfig`.
        seed : int, optional
            Seed of the robot's generator; or pass ``rng``.
        config : AdapterConfig, optional
            A whole config (then ``strategy``, ``family`` and ``options`` must not be given).
        max_steps : int, optional
            Touch budget after which :meth:`done` holds.
        **options
            Any other :class:`AdapterConfig` field (``posterior``, ``resolution``, ``stop_mass``...).

        Raises
        ------
        ConfigError
            An unknown or invalid option, or a model that is not a model object.
        """
        if config is None:
            config = AdapterConfig.from_dict({"strategy": strategy, "family": family, **options})
        elif options:
            raise ConfigError(f"give either config or options, not both ({', '.join(options)})")
        if rng is None:
            rng = np.random.default_rng(seed)
        elif seed is not None:
            raise ConfigError("give either seed or rng, not both")
        return cls(cls.load(model), config, rng=rng, max_steps=max_steps)

    @staticmethod
    def load(model):
        """The model object :meth:`from_model` adapts with (:class:`kbcli.api.Adapter` reads files)."""
        if not hasattr(model, "classify"):
            raise ConfigError(f"Adapter.from_model needs a sound model here, got {model!r}; read a "
                              f"model file with kbcli.Adapter.from_model (kbcli.api)")
        return model

    # -- deciding ----------------------------------------------------------------------------------
    def planning_table(self) -> LikelihoodTable:
        """The map the strategies plan with: the model's, or the robust posterior's (or the
        repaired belief's) most probable blur and outlier rate applied to it."""
        if self.repair is not None:
            return self.repair.planning_table()
        if self.robust is None:
            return self.table
        i, j = self.robust.map_index()
        nz = self.robust.nuisance
        return planning_table(self.table, float(nz.blurs[i]), float(nz.outliers[j]))

    def action_source(self):
        """What draws actions from p(action | sound) (``cfg.kde_sampler``): the model's own
        sampler, or the model's raster (:class:`~kbcli.core.model.sampling.RasterSampler`)."""
        return self.table.sampler() if self.cfg.kde_sampler == "raster" else self.model

    def simulate(self, action: np.ndarray, cls: int) -> np.ndarray:
        """The log term a touch read at ``action`` that gave ``cls`` would multiply the posterior
        by (this adapter's kind of posterior, plain, reading :attr:`simulation_samples`)."""
        return self.kind.term(self._observation(action, cls, self.simulation_samples))[0]

    def simulate_many(self, actions: np.ndarray, classes: np.ndarray) -> np.ndarray:
        """``(k, *grid.shape)``: :meth:`simulate` of ``k`` touches (``actions`` (k, 2),
        ``classes`` (k,)), together when the kind of posterior can (its ``terms``)."""
        pairs = zip(np.asarray(actions, float).reshape(-1, 2), np.asarray(classes).reshape(-1),
                    strict=True)
        obs = [self._observation(a, c, self.simulation_samples) for a, c in pairs]
        many = getattr(self.kind, "terms", None)
        if many is not None:
            return many(obs)
        return np.stack([self.kind.term(o)[0] for o in obs])

    def prepare(self) -> Adapter:
        """Build now what the first touches would build (boundaries, planning map, blurred maps);
        draws nothing. Returns the adapter."""
        self.context()
        if self.robust is not None:
            for blur in self.robust.nuisance.blurs:
                blurred_map(self.table, float(blur))
        return self

    def context(self) -> Context:
        if self._edges is None:
            self._edges, self._corners = self.table.boundary_points()
        return Context(self.posterior, self.planning_table(), self.area, self._edges,
                       self._corners, self.cfg, touched=self.touched(),
                       redundancy_radius=self.redundancy_radius,
                       sampler=self.action_source(), simulate=self.simulate,
                       simulate_many=self.simulate_many,
                       outcome=None if self.repair is None else self.repair.outcome)

    def touched(self) -> np.ndarray:
        """(k, 2) where the observed touches were read (felt positions, or the aims)."""
        return np.asarray(self.points, float).reshape(-1, 2)

    def spot_count(self, points: np.ndarray) -> np.ndarray:
        """(n,) for each point, how many observed touches lie within ``redundancy_radius``."""
        pts = np.asarray(points, float).reshape(-1, 2)
        return spot_count(pts, self.touched(), self.redundancy_radius)

    def suggest(self) -> np.ndarray:
        """(2,) the next action (pad px) chosen by the strategy."""
        return np.asarray(self._strategy(self.context(), self.rng), float)

    def propose(self) -> np.ndarray:
        """The older name of :meth:`suggest`."""
        return self.suggest()

    # -- observing ---------------------------------------------------------------------------------
    def observe(self, action: np.ndarray, heard: np.ndarray | None,
                felt_position: np.ndarray | None = None) -> int:
        """Classify a heard sound (``model.classify``) and update the posterior with it.

        Parameters
        ----------
        action : (2,) array_like
            Where the robot aimed (pad px, inside the working area).
        heard : (D,) array_like or None
            The heard features; None (or all NaN) for silence.
        felt_position : (2,) array_like, optional
            Where the robot felt its finger land (proprioception): the point the posterior is
            updated at. None: the aim is used (set ``AdapterConfig.blur`` to the reach noise).

        Returns
        -------
        int
            The class (0 silence, -1 unknown: skipped).

        Raises
        ------
        ObservationError
            Non-numeric or wrongly sized input, an action outside the working area; the posterior
            is left unchanged.
        """
        a = self.check_action(action, "action")
        point = a if felt_position is None else check_point(felt_position, "felt_position")
        h = self.check_heard(heard)
        cls = int(self.model.classify(h.reshape(1, -1))[0])
        self.observe_class(point, cls)
        self.touches += 1
        return cls

    def check_action(self, action, name: str = "action") -> np.ndarray:
        """``action`` as a (2,) array inside the working area (:func:`~.inputs.check_action`)."""
        return check_action(action, self.area, name)

    def check_heard(self, heard) -> np.ndarray:
        """``heard`` as a (D,) float array, all NaN for silence (:func:`~.inputs.check_heard`)."""
        return check_heard(heard, int(np.shape(self.model.class_features_)[1]))

    def observe_class(self, action: np.ndarray, cls: int) -> None:
        """Update the posterior with an already classified observation (Eq. 8)."""
        if cls == UNKNOWN:
            return
        obs = self._observation(action, cls, self.samples)
        if self.repair is not None:
            self.points.append(obs.action)
            self.repair = self.repair.update(obs.action, obs.cls)
            self.posterior = self._tied(self.repair.marginal())
            return
        if self.robust is not None:
            self._observe_robust(obs)
            return
        term, bandwidth = self.kind.term(obs)
        if bandwidth is not None:
            self.bandwidths.append(bandwidth)
        self.posterior = self.posterior.update(term)

    def _observation(self, action: np.ndarray, cls: int, samples) -> Observation:
        """A touch read at ``action`` (2,) that gave ``cls``, its terms reading ``samples``."""
        return Observation(self.grid, self.table, self.model, self.cfg, samples,
                           np.asarray(action, float).reshape(2), int(cls))

    def _observe_robust(self, obs: Observation) -> None:
        """The robust posterior's update: the kind's terms under every nuisance value, the
        ``(k + 1)``-th touch at one spot weighted ``1 / (k + 1)``."""
        terms = self.kind.robust_terms(obs, self.robust.nuisance)
        k = int(self.spot_count(obs.action)[0])
        if k:  # the (k + 1)-th touch at one spot: weight 1 / (k + 1)
            terms = terms * np.float32(1.0 / (k + 1))
        self.points.append(obs.action)
        self.robust = self.robust.update(terms)
        self.posterior = self._tied(self.robust.marginal())

    def _tied(self, posterior: Posterior) -> Posterior:
        """``posterior`` with this adapter's tie rule (``ml_ties``)."""
        return posterior if self.tie_seed is None else posterior.with_tie_seed(self.tie_seed)

    def repaired_model(self):
        """The model refitted with this adaptation's touches, mapped back into its reference
        frame by the estimate (:func:`kbcli.core.adaptation.repair.absorb`).

        Raises
        ------
        ConfigError
            Without ``repair``, or with the exact model (nothing to repair).
        """
        if self.repair is None:
            raise ConfigError("repaired_model needs an adapter with repair = true")
        if not hasattr(self.model, "actions_"):
            raise ConfigError("the exact model has nothing to repair: repair a learned model")
        t = self.repair.touches
        return absorb(self.model, t.points, t.classes, self.estimate())

    # -- reading -----------------------------------------------------------------------------------
    def estimates(self) -> Estimate:
        post = self.posterior
        return Estimate(ml=post.ml(), mean=post.mean(), ml_prob=post.ml_prob())

    def estimate(self) -> np.ndarray:
        """(P,) the estimate of the config's estimator (the posterior mean, the ML cell, ...)."""
        est = self.cfg.estimator
        return ESTIMATORS.get(est.name).read(self.posterior, est)

    def entropy(self) -> float:
        """Posterior entropy, nats (over grid cells)."""
        return self.posterior.entropy()

    def mass_near_estimate(self) -> float:
        """Posterior mass within ``stop_radius`` (and ``stop_angle``) of the estimate."""
        return self.posterior.mass_within(self.estimate(), self.cfg.stop_radius, self.cfg.stop_angle)

    def should_stop(self) -> bool:
        """The paper's rule (ML probability >= ``stop_ml``, when set) or ours (mass near the
        estimate >= ``stop_mass``)."""
        if self.posterior.n_obs == 0:
            return False
        if self.cfg.stop_ml is not None and self.posterior.ml_prob() >= self.cfg.stop_ml:
            return True
        if not self.cfg.stop_mass:  # 0 or None: ours is off
            return False
        return self.mass_near_estimate() >= self.cfg.stop_mass

    def done(self) -> bool:
        """Whether the stopping rule holds or the ``max_steps`` budget is used up."""
        return (self.max_steps is not None and self.touches >= self.max_steps) or \
            self.should_stop()

