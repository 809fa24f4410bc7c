"""Model classes own their options (issue 41): each learned class declares the fit's parameters a
user may set, ``model_class`` names the class and carries them (a name, a table, or flat), and a
model learned with the defaults records the config it always did."""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.cli import app
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.classes import MODEL_CLASSES, ModelClass, learned_classes
from kbcli.core.model.classifiers import KNNModel, KNNOptions
from kbcli.core.model.explore import Exploration, ExploreConfig
from kbcli.core.options import Options, options_of
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import load_config
from kbcli.sim import SimConfig, World, make_reacher
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage
from kbcli.stages.models import load_model

SMALL = KeyboardConfig(rows=2, cols=3)


@pytest.mark.parametrize("name", learned_classes())
def test_each_class_declares_options_with_its_own_defaults(name):
    opts = options_of(MODEL_CLASSES, name)(name=name)
    assert type(opts) is not Options and opts.own()
    params = MODEL_CLASSES.get(name).estimator()().get_params()
    assert all(params[k] == v for k, v in opts.own().items())


@pytest.mark.parametrize("table", [
    '[learn]\nmodel_class = {name = "forest", n_estimators = 7}\nbudget = 40\n',
    '[learn]\nbudget = 40\n[learn.model_class]\nname = "forest"\nn_estimators = 7\n',
    '[learn]\nmodel_class = "forest"\nn_estimators = 7\nbudget = 40\n',
])
def test_a_class_option_from_toml_is_recorded_and_fits_the_model(tmp_path, table):
    (tmp_path / "learn.toml").write_text(table)
    cfg = load_config(learn_stage.LearnConfig, tmp_path / "learn.toml")
    assert cfg.model_class.name == "forest" and cfg.model_class.n_estimators == 7
    art = learn_stage.run(cfg, keyboard_stage.run(SMALL), rng=np.random.default_rng(0), seed=0)
    write_artifact(art, tmp_path / "m.h5")
    back = read_artifact(tmp_path / "m.h5", "model")
    assert back.config["model_class"] == "forest" and back.config["n_estimators"] == 7
    assert "n_directions" not in back.config  # only the options set are recorded
    model = load_model(back)
    assert model.n_estimators == 7 and len(model.classifier_.estimators_) == 7
    assert learn_stage.LearnConfig(**{k: back.config[k] for k in ("model_class", "n_estimators")}
                                   ).model_class == cfg.model_class


def test_options_set_reach_the_exploration_refits_over_its_lighter_ones():
    kb = Keyboard(SMALL)

    def explorer(**cfg):
        ex = Exploration(ExploreConfig(budget=20, **cfg), World(kb, make_reacher(SimConfig())).touch,
                         kb.area, kb.config.match_threshold, np.random.default_rng(0))
        for _ in ex:
            pass
        return ex.model

    assert explorer(model_class="forest").n_estimators == 60  # the class's lighter forest
    assert explorer(model_class="forest", n_estimators=9).n_estimators == 9
    assert explorer(model_class={"name": "knn", "n_neighbors": 2}).n_neighbors == 2


@pytest.mark.parametrize("given, words", [
    ({"model_class": "knn", "n_estimators": 5},
     "model class knn takes no option 'n_estimators' (model class forest and forest-xy do); "
     "its options: n_neighbors"),
    ({"n_neighbors": 3}, "model class auto takes no option 'n_neighbors'"),
    ({"model_class": {"name": "auto", "n_estimators": 3}}, "model class auto takes no option"),
    ({"model_class": {"name": "lines", "n_estimators": 3}}, "model class lines takes no option"),
    ({"model_class": "forest", "n_estimators": 0}, "n_estimators must be a whole number in [1, "),
    ({"model_class": "lines", "max_sd": 0.01}, "max_sd must be >= min_sd"),
])
def test_an_option_the_class_does_not_take_is_refused_naming_it(given, words):
    with pytest.raises(ConfigError) as exc:
        learn_stage.LearnConfig(**given)
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_the_cli_sets_a_class_option_and_refuses_a_foreign_one(runner, tmp_path):
    kb, out = tmp_path / "kb.h5", tmp_path / "m.h5"
    write_artifact(keyboard_stage.run(SMALL), kb)
    base = ["learn", "--keyboard", str(kb), "-o", str(out), "--budget", "40"]
    r = runner.invoke(app, [*base, "--model-class", "knn", "--model-option", "n_estimators=5"])
    assert r.exit_code == 1 and not out.exists()
    assert r.output.strip().splitlines() == [
        "kbcli: error: learn.model_class: model class knn takes no option 'n_estimators' (model "
        "class forest and forest-xy do); its options: n_neighbors"]
    r = runner.invoke(app, [*base, "--model-option", "n_neighbors=3"])  # auto takes none
    assert r.exit_code == 1 and "model class auto takes no option 'n_neighbors'" in r.output
    r = runner.invoke(app, [*base, "--model-class", "knn", "--model-option", "n_neighbors=3"])
    assert r.exit_code == 0, r.output
    art = read_artifact(out, "model")
    assert art.config["n_neighbors"] == 3 and load_model(art).n_neighbors == 3


def test_a_model_learned_with_the_defaults_records_the_config_it_always_did():
    stored = read_artifact("data/default-model.h5", "model").config  # (make data: lines, dynamics)
    cfg = learn_stage.LearnConfig(sim=SimConfig(mode="dynamics"), model_class="lines")
    assert learn_stage.model_config(cfg, stored["keyboard"]) == stored
    assert learn_stage.LearnConfig().to_dict()["model_class"] == "auto"
    assert learn_stage.LearnConfig(model_class="forest").to_dict()["model_class"] == "forest"


def test_a_plug_in_class_with_options_of_its_own():
    class ToyOptions(KNNOptions):
        pass

    with MODEL_CLASSES.temporarily("toy-knn", ModelClass(lambda: KNNModel),
                                   traits={"options": ToyOptions}):
        cfg = learn_stage.LearnConfig(model_class="toy-knn", n_neighbors=4)
        assert isinstance(cfg.model_class, ToyOptions) and cfg.model_class.n_neighbors == 4
    with MODEL_CLASSES.temporarily("bare", ModelClass(lambda: KNNModel)):  # declares none
        with pytest.raises(ConfigError, match="model class bare takes no option 'n_neighbors'"):
            learn_stage.LearnConfig(model_class="bare", n_neighbors=4)
