"""The ``lines`` model class: M_INST = p(sound, action) with straight boundaries, from exploration.

The sound classes are found by leader clustering of the perceived features (Eq. 2,
:mod:`kbcli.core.model.sounds`). Each pair of sounds' straddling Delaunay edges get the max-margin
line separating their ends, split into pieces where no line does and merged where lines nearly
coincide (:mod:`kbcli.core.model.pieces`). A pair's contest at an action is ``Phi(s / sigma)``, s
the signed distance to the line and sigma the width of the band between the two sides' hulls over
sqrt(12) (:mod:`kbcli.core.model.boundaries`); the contests, softmax, floor (the paper's confusion
factor, Sect. III-E) and sampling are :class:`~kbcli.core.model.pairwise.ModelBase`'s.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from pydantic import model_validator
from scipy.spatial import cKDTree
from scipy.special import log_ndtr

from kbcli.core.config import NonNegative, Positive, Whole, between
from kbcli.core.model import boundaries
from kbcli.core.model.pairwise import DEFAULT_AREA, ModelBase
from kbcli.core.model.pieces import fit_pieces, line_sides
from kbcli.core.model.sounds import prepare_samples
from kbcli.core.options import Options
from kbcli.errors import ConfigError

#: The parameter checks of :meth:`LearnedModel._check_params`: (name, is it valid, what is allowed).
_CHECKS = (
    ("n_neighbors", lambda m, v: int(v) >= 2, ">= 2"),
    ("min_sd", lambda m, v: v > 0, "> 0 px"),
    ("max_sd", lambda m, v: v >= m.min_sd, ">= min_sd"),
    ("sd_scale", lambda m, v: v > 0, "> 0"),
    ("noise_sd", lambda m, v: v >= 0, ">= 0 px"),
    ("noise_tol", lambda m, v: v >= 0, ">= 0 px"),
    ("floor", lambda m, v: 0 <= v < 1, "in [0, 1)"),
    ("extrapolation", lambda m, v: v >= 0, ">= 0"),
    ("merge_angle", lambda m, v: 0 <= v < 90, "in [0, 90) degrees"),
    ("merge_offset", lambda m, v: v >= 0, ">= 0 px"),
    ("piece_reach", lambda m, v: v >= 0, ">= 0 px"),
)


def _stored_params(d: dict) -> dict:
    """The parameters of a stored learned model (:meth:`LearnedModel.from_arrays`)."""
    return {
        "n_neighbors": int(d["n_neighbors"]),
        "min_sd": float(d["min_sd"]),
        "max_sd": float(d["max_sd"]),
        "sd_scale": float(d.get("sd_scale", 1.0)),  # absent before model schema 2
        "noise_sd": float(d.get("noise_sd", 0.0)),
        "floor": float(d.get("floor", 0.0)),
        "noise_tol": float(d.get("noise_tol", 0.0)),
        "extrapolation": float(d["extrapolation"]),
        "merge_angle": float(d["merge_angle"]),
        "merge_offset": float(d["merge_offset"]),
        "piece_reach": float(d["piece_reach"]),
    }


def _stored_pieces(d: dict) -> tuple[np.ndarray, ...]:
    """The boundary pieces and lines of a stored learned model, as ``_set_fitted`` takes them."""
    return (np.asarray(d["edges"], np.int64).reshape(-1, 2),
            np.asarray(d["edge_piece"], np.int64),
            np.asarray(d["piece_pair"], np.int64),
            np.asarray(d["piece_line"], np.int64),
            np.asarray(d["piece_sign"], float),
            np.asarray(d["lines"], float))


class LinesOptions(Options):
    """``lines``' options, the fit's parameters of :class:`LearnedModel` (its defaults; those
    the calibration chooses, ``noise_tol``, ``noise_sd``, ``sd_scale`` and ``floor``, aside)."""

    what: ClassVar[str] = "model class lines"
    n_neighbors: between(Whole, 2, 1_000) = 8
    min_sd: Positive = 0.05
    max_sd: Positive = 25.0
    extrapolation: NonNegative = 1.0
    merge_angle: between(NonNegative, 0, 90, high_open=True) = 10.0
    merge_offset: NonNegative = 10.0
    piece_reach: NonNegative = 10.0

    @model_validator(mode="after")
    def _sd_order(self) -> LinesOptions:
        if self.max_sd < self.min_sd:
            raise ConfigError(f"max_sd must be >= min_sd ({self.min_sd:g}), got {self.max_sd:g}")
        return self


class LearnedModel(ModelBase):
    """p(sound | action) learned from exploration samples (see the module docstring).

    Parameters
    ----------
    match_threshold, area
        As every class (:class:`~kbcli.core.model.pairwise.ModelBase`).
    n_neighbors : int
        Samples looked at around an action to find the sounds it could make.
    min_sd, max_sd : float
        Bounds (px) of a boundary line's uncertainty sigma_b.
    sd_scale : float
        Factor on every boundary's uncertainty (calibration).
    noise_sd : float
        Std (px) of the label noise near a boundary, combined as ``hypot(sigma_b, noise_sd)``.
    noise_tol : float
        Label-noise tolerance (px) of the boundary fit: a soft-margin line is accepted when every
        sample on its wrong side is within ``noise_tol`` of it (0: exact separation).
    floor : float
        Share of probability spread evenly over all sounds (``p = (1 - floor) p + floor / C``).
    extrapolation : float
        Growth (px per px) of a boundary band's width beyond the samples along its line.
    merge_angle, merge_offset : float
        Pieces whose lines are within this angle (degrees) and offset (px) may share a line.
    piece_reach : float
        Where a pair of sounds has several boundary pieces, those within this many px of the
        nearest one decide together; further ones have no say.

    Attributes
    ----------
    edges_, edge_piece_, piece_pair_, piece_line_, piece_sign_ : ndarray
        The boundary pieces (:func:`~kbcli.core.model.pieces.fit_pieces`): the straddling edges
        (sample indices), the piece of each edge, each piece's pair of classes, line and side.
    lines_ : (L, 3) ndarray
        Boundary lines (nx, ny, c), unit normal: signed distance ``nx * x + ny * y - c``.
    """

    def __init__(self, *, match_threshold: float = 1.5,
                 area: tuple[float, float, float, float] = DEFAULT_AREA, n_neighbors: int = 8,
                 min_sd: float = 0.05, max_sd: float = 25.0, sd_scale: float = 1.0,
                 noise_sd: float = 0.0, floor: float = 0.0, noise_tol: float = 0.0,
                 extrapolation: float = 1.0, merge_angle: float = 10.0, merge_offset: float = 10.0,
                 piece_reach: float = 10.0) -> None:
        self.match_threshold = match_threshold
        self.area = area
        self.n_neighbors = n_neighbors
        self.min_sd = min_sd
        self.max_sd = max_sd
        self.sd_scale = sd_scale
        self.noise_sd = noise_sd
        self.floor = floor
        self.noise_tol = noise_tol
        self.extrapolation = extrapolation
        self.merge_angle = merge_angle
        self.merge_offset = merge_offset
        self.piece_reach = piece_reach

    # -- parameters -----------------------------------------------------------------------------
    def _check_params(self) -> None:
        self._check_common()
        for name, ok, allowed in _CHECKS:
            v = getattr(self, name)
            finite = name == "n_neighbors" or np.isfinite(v)
            if not (finite and ok(self, v)):
                raise ConfigError(f"{name} must be {allowed}, got {v!r}")

    @staticmethod
    def fit_grid() -> dict[str, tuple[float, ...]]:
        """Candidate values of the fit's own calibration parameter, the label-noise tolerance
        (px; :func:`kbcli.core.model.reliability.assess` keeps the best held-out score)."""
        return {"noise_tol": (0.0, 2.0, 4.0)}

    @staticmethod
    def calibration_grid() -> dict[str, tuple[float, ...]]:
        """Candidate values of the calibration parameters (read at prediction time)."""
        return {"noise_sd": (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.5, 6.0), "floor": (0.0, 0.002, 0.01)}

    # -- fitting --------------------------------------------------------------------------------
    def fit(
        self, actions: np.ndarray, perceived: np.ndarray, targets: np.ndarray | None = None
    ) -> LearnedModel:
        """As :meth:`ModelBase.fit`, the boundary pieces fitted to the samples too."""
        self._check_params()
        x, features, labels, reach_sd = prepare_samples(actions, perceived, targets,
                                                        self.match_threshold)
        e, piece, pairs, group, sign, lines = fit_pieces(
            x, labels, len(features), merge_angle=self.merge_angle,
            merge_offset=self.merge_offset, tol=self.noise_tol)
        self._set_fitted(features, x, labels, e, piece, pairs, group, sign, lines, reach_sd)
        return self

    def _set_fitted(
        self, features, actions, labels, edges, edge_piece, pairs, group, sign, lines, reach_sd
    ) -> None:
        self.class_features_ = np.asarray(features, float)
        self.actions_ = np.asarray(actions, float)
        self.labels_ = np.asarray(labels, np.int64)
        self.edges_ = np.asarray(edges, np.int64).reshape(-1, 2)
        self.edge_piece_ = np.asarray(edge_piece, np.int64)
        self.piece_pair_ = np.asarray(pairs, np.int64).reshape(-1, 2)
        self.piece_line_ = np.asarray(group, np.int64)
        self.piece_sign_ = np.asarray(sign, float)
        self.lines_ = np.asarray(lines, float).reshape(-1, 3)
        self.reach_sd_ = float(reach_sd)
        self._tree = cKDTree(self.actions_)
        # samples on the positive / negative side of each line: the pieces' lower-class ends,
        # or higher-class ends where the piece runs the other way
        pos, neg = line_sides(self.edges_, self.edge_piece_, self.piece_sign_)
        self._hulls, self._line_range = boundaries.line_hulls(
            self.actions_, pos, neg, self.piece_line_[self.edge_piece_], self.lines_)
        self._piece_extent = boundaries.piece_extents(
            self.actions_, self.edges_, self.edge_piece_, self.piece_line_, self.lines_)
        nc = len(self.class_features_)
        pcode = self.piece_pair_[:, 0] * nc + self.piece_pair_[:, 1]
        #: pair code -> its pieces (the contests of :class:`~kbcli.core.model.pairwise.ModelBase`)
        self._pairs = {int(c): np.flatnonzero(pcode == c) for c in np.unique(pcode)}
        # with several pieces, one sound of the pair is "inside" (a key within silence's L around
        # a corner): it must be on its side of every piece, the other of any one
        self._pair_inside = {
            c: boundaries.pair_inside(self.actions_, self.edges_, self.edge_piece_, pieces,
                                      self.lines_[self.piece_line_[pieces]],
                                      self.piece_sign_[pieces])
            for c, pieces in self._pairs.items()}

    # -- the boundary lines ---------------------------------------------------------------------
    def _band(self, g: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Width (px) and centre (v) of the band where line ``g`` can be, at positions ``t``
        (:func:`kbcli.core.model.boundaries.band`)."""
        return boundaries.band(self._hulls[g], self._line_range[g], self.extrapolation, t)

    def _pair_logp(self, code: int, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Log-probability that each point is on the lower / higher class's side of their boundary.

        With one piece, ``log Phi(+-s / sigma)``. With several, only the nearest and those within
        ``piece_reach`` px more count; the sound inside must be on its side of all of them, the
        other of any.
        """
        pieces = self._pairs[code]
        g = self.piece_line_[pieces]
        lines = self.lines_[g]
        v = (q @ lines[:, :2].T - lines[:, 2]) * self.piece_sign_[pieces]  # (n, k)
        t = q @ np.column_stack([-lines[:, 1], lines[:, 0]]).T
        sd = np.empty_like(v)
        for j in range(len(pieces)):  # a few pieces per pair
            sd[:, j] = self._band(int(g[j]), t[:, j])[0] / np.sqrt(12.0)
        sd = np.clip(sd * self.sd_scale, self.min_sd, self.max_sd)
        if self.noise_sd > 0:
            sd = np.hypot(sd, self.noise_sd)
        lp_lo, lp_hi = log_ndtr(v / sd), log_ndtr(-v / sd)
        if len(pieces) == 1:
            return lp_lo[:, 0], lp_hi[:, 0]
        ext = self._piece_extent[pieces]
        over = np.maximum(ext[:, 0] - t, 0) + np.maximum(t - ext[:, 1], 0)
        dist = np.hypot(v, over)
        far = dist > dist.min(axis=1, keepdims=True) + self.piece_reach
        lp_lo, lp_hi = np.where(far, 0.0, lp_lo), np.where(far, 0.0, lp_hi)  # far: no say
        if self._pair_inside[code]:  # lower class inside: on its side of all pieces
            return lp_lo.sum(axis=1), boundaries.log_any(lp_lo)
        return boundaries.log_any(lp_hi), lp_hi.sum(axis=1)

    def boundary_sites(
        self, step: float = 1.0, extend: float = 25.0, phase: float = 0.0
    ) -> dict[str, np.ndarray]:
        """Points along every boundary piece, every ``step`` px (shifted by ``phase`` in [0, 1))
        from ``extend`` px before its first straddling sample to ``extend`` px after its last,
        each in the middle of the band the boundary must lie in, with the band's ``width`` (px).
        Points the model does not put between the piece's two sounds are dropped.

        Returns
        -------
        dict with ``points`` (m, 2), ``width`` (m,), ``piece`` (m,), ``t`` (m,)
        """
        self._check_fitted()
        pts, wid, pcs, ts = [], [], [], []
        for p in range(len(self.piece_pair_)):
            g = int(self.piece_line_[p])
            nx, ny, c = self.lines_[g]
            t = np.arange(self._piece_extent[p, 0] - extend + phase * step,
                          self._piece_extent[p, 1] + extend, step)
            w, v = self._band(g, t)
            pts.append(np.outer(t, (-ny, nx)) + np.outer(v + c, (nx, ny)))
            wid.append(w)
            pcs.append(np.full(len(t), p))
            ts.append(t)
        if not pts:
            return {"points": np.empty((0, 2)), "width": np.empty(0),
                    "piece": np.empty(0, dtype=np.int64), "t": np.empty(0)}
        xy, w, pc, t = np.vstack(pts), np.concatenate(wid), np.concatenate(pcs), np.concatenate(ts)
        nrm = self.lines_[self.piece_line_[pc], :2] * self.piece_sign_[pc, None]
        pair = self.piece_pair_[pc]
        off = np.maximum(w / 2, 0.5)[:, None] * nrm
        ok = (self.predict_class(xy + off) == pair[:, 0]) & (
            self.predict_class(xy - off) == pair[:, 1]
        )
        return {"points": xy[ok], "width": w[ok], "piece": pc[ok], "t": t[ok]}

    # -- storage --------------------------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model as named arrays (for an HDF5 artifact group)."""
        self._check_fitted()
        return self._arrays(
            edges=self.edges_.copy(),
            edge_piece=self.edge_piece_.copy(),
            piece_pair=self.piece_pair_.copy(),
            piece_line=self.piece_line_.copy(),
            piece_sign=self.piece_sign_.copy(),
            lines=self.lines_.copy(),
            merge_angle=np.float64(self.merge_angle),
            merge_offset=np.float64(self.merge_offset),
            piece_reach=np.float64(self.piece_reach),
            n_neighbors=np.int64(self.n_neighbors),
            min_sd=np.float64(self.min_sd),
            max_sd=np.float64(self.max_sd),
            sd_scale=np.float64(self.sd_scale),
            noise_sd=np.float64(self.noise_sd),
            floor=np.float64(self.floor),
            noise_tol=np.float64(self.noise_tol),
            extrapolation=np.float64(self.extrapolation),
        )

    @classmethod
    def from_arrays(cls, d: dict) -> LearnedModel:
        """Rebuild a fitted model from :meth:`to_arrays` output (exactly the same predictions)."""
        return cls._from_stored(d, "learned", _stored_params, _stored_pieces)
