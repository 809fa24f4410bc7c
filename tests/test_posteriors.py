"""The posterior kinds are a registry: adding one is one class plus its registration.

A toy kind, a "deaf" posterior that ignores what it hears, is registered for the duration of a
test and run end to end through ``kbcli adapt``; the registered kinds follow the protocol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from kbcli.cli import app
from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.posteriors import POSTERIORS, KindBase, Observation, PosteriorKind
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact
from kbcli.stages.perturb import PerturbConfig
from kbcli.stages.perturb import run as perturb_run


@dataclass(frozen=True)
class DeafPosterior(KindBase):
    """Hears nothing: every touch leaves the posterior as it was (a flat term)."""

    name = "deaf"

    def term(self, obs: Observation) -> tuple[np.ndarray, None]:
        return np.zeros(obs.grid.shape), None


def test_every_registered_kind_follows_the_protocol():
    assert POSTERIORS.names()[:2] == ("likelihood", "kde")
    for name, kind in POSTERIORS.items():
        assert isinstance(kind, PosteriorKind) and kind.name == name
        assert not kind.robust or callable(kind.robust_terms)
    assert isinstance(DeafPosterior(), PosteriorKind)


def test_an_unknown_posterior_lists_the_registered_ones():
    with pytest.raises(ConfigError, match="unknown posterior 'deaf'; valid: likelihood, kde"):
        AdapterConfig(posterior="deaf")
    with POSTERIORS.temporarily("deaf", DeafPosterior()):
        assert AdapterConfig(posterior="deaf").posterior.name == "deaf"
    assert "deaf" not in POSTERIORS


def test_a_toy_posterior_runs_in_the_adapter():
    model = ExactModel(Keyboard(KeyboardConfig()))
    with POSTERIORS.temporarily("deaf", DeafPosterior()):
        ad = Adapter(model, AdapterConfig(posterior="deaf", prior_halfwidth=5.0),
                     rng=np.random.default_rng(0))
        g = ad.grid.size
        for _ in range(3):
            a = ad.suggest()
            ad.observe_class(a, int(model.predict_class(a[None])[0]))
        assert ad.posterior.n_obs == 3 and ad.robust is None
        assert ad.entropy() == pytest.approx(math.log(g))


def test_a_toy_posterior_runs_through_kbcli_adapt(runner, tmp_path):
    kb = keyboard_stage.run(KeyboardConfig())
    write_artifact(exact_artifact(kb), tmp_path / "model.h5")
    scene = perturb_run(PerturbConfig(params=(2.0, -1.0)), kb, rng=np.random.default_rng(0))
    write_artifact(scene, tmp_path / "scene.h5")
    with POSTERIORS.temporarily("deaf", DeafPosterior(), summary="hears nothing"):
        r = runner.invoke(app, ["adapt", "--model", str(tmp_path / "model.h5"), "--scene",
                                str(tmp_path / "scene.h5"), "-o", str(tmp_path / "run.h5"),
                                "--posterior", "deaf", "--prior-halfwidth", "5",
                                "--max-steps", "4", "--seed", "1"])
        assert r.exit_code == 0, r.output
        assert "infogain/deaf" in r.output and "final error" in r.output
        art = read_artifact(tmp_path / "run.h5", "run")
    assert art.config["adapt"]["robot"]["posterior"] == {"name": "deaf"}
    # the deaf posterior never moves: the entropy stays that of the flat prior
    n = 2 * 10 + 1  # +-5 px at 0.5 px
    assert np.allclose(art.data["entropy"], math.log(n * n))
