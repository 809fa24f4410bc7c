"""``--model-class auto`` (issue 27): the class chosen by its own cross-validated score."""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.core.model.classes import check_choice, ranked
from kbcli.core.model.classifiers import ForestModel
from kbcli.core.model.explore import Exploration, ExploreConfig
from kbcli.core.model.select import (
    RESELECT,
    SWITCH_Z,
    Selection,
    choose,
    explore_choice,
    explore_class,
    paired_z,
    prefer,
)
from kbcli.errors import ConfigError

#: the classes ``auto`` chooses between and the one it starts exploring with, as the classes declare
CANDIDATES, EXPLORE_CLASS = ranked("auto"), ranked("explores")[0]
AREA = (150.0, 200.0, 650.0, 500.0)
G = np.stack(np.meshgrid(np.arange(160.0, 650.0, 12.0), np.arange(210.0, 500.0, 12.0)),
             -1).reshape(-1, 2)


def _two_discs() -> np.ndarray:
    heard = np.full((len(G), 2), np.nan)
    heard[np.hypot(G[:, 0] - 300, G[:, 1] - 350) < 70] = [10.0, 10.0]
    heard[np.hypot(G[:, 0] - 500, G[:, 1] - 350) < 70] = [20.0, 20.0]
    return heard


def test_round_keys_choose_a_class_that_bends():
    """Two round pads in silence: straight lines cannot follow the circles, the trees bend
    roughly, the SVMs' circle machines follow them: the SVMs replace the forest."""
    sel = choose(G, _two_discs(), match_threshold=1.5, area=AREA, rng=np.random.default_rng(0))
    assert sel.chosen == "svc" and sel.explored_with == EXPLORE_CLASS and sel.folds == 5
    assert set(sel.cv_error) == set(CANDIDATES)
    assert sel.cv_error["lines"] > 3 * sel.cv_error["forest"] > 3 * sel.cv_error["svc"]
    assert sel.summary().startswith("model class: svc, chosen by 5-fold cross-validation")


def test_a_slanted_straight_edge_chooses_an_exact_class():
    """A straight slanted edge: the SVMs (a linear machine) and lines are exact, the trees' and the
    neighbours' boundaries are ragged: the SVMs replace the forest, lines only ties them."""
    heard = np.where((G[:, 0] + 0.5 * G[:, 1] < 560)[:, None], [[10.0, 10.0]], [[20.0, 20.0]])
    sel = choose(G, heard, match_threshold=1.5, area=AREA, rng=np.random.default_rng(0))
    assert sel.chosen == "svc" and sel.cv_error["svc"] == sel.cv_error["lines"] == 0.0
    assert sel.cv_error["forest"] > 0 and sel.cv_error["knn"] > 0
    same = choose(G, heard, match_threshold=1.5, area=AREA, rng=np.random.default_rng(0))
    assert same == sel  # same folds, same scores
    assert Selection(**sel.to_dict()) == sel


def _piano(x: np.ndarray) -> np.ndarray:
    """Five white keys (79 px wide, L-shaped where black keys cut into them) and four black keys
    (34 px wide, on every inner white edge, the upper two thirds): every key edge is horizontal
    or vertical; silence around."""
    heard = np.full((len(x), 2), np.nan)
    inside = (x[:, 0] >= 203) & (x[:, 0] < 597) & (x[:, 1] >= 253) & (x[:, 1] < 447)
    white = np.floor((x[:, 0] - 203) / 79).astype(int)
    for i in range(5):
        heard[inside & (white == i)] = [10.0 + 10 * i, 10.0]
    for j in range(1, 5):
        black = (abs(x[:, 0] - (203 + 79 * j)) < 17) & (x[:, 1] >= 253) & (x[:, 1] < 383)
        heard[black] = [10.0 + 10 * j, 50.0]
    return heard


def test_axis_aligned_keys_choose_the_forest_on_the_coordinates():
    """Piano-like keys, 2000 uniform touches: the trees splitting on x and y only place every edge
    between the two nearest samples across it; oblique projections slant some of them: forest-xy
    mislabels fewer held-out touches by more than 2 standard errors and replaces the forest; the
    SVMs (straight lines per pair, no L-shaped key) and lines do worse still."""
    x = np.random.default_rng(12).uniform((160.0, 210.0), (640.0, 490.0), size=(2000, 2))
    sel = choose(x, _piano(x), match_threshold=1.5, area=AREA, rng=np.random.default_rng(2))
    assert sel.chosen == "forest-xy"
    err = sel.cv_error
    assert err["forest-xy"] < err["forest"] < min(err["svc"], err["lines"], err["knn"])
    # a slanted edge, the other way: the coordinates alone staircase it
    slant = np.where((x[:, 0] + 0.5 * x[:, 1] < 560)[:, None], [[10.0, 10.0]], [[20.0, 20.0]])
    sel = choose(x, slant, match_threshold=1.5, area=AREA, rng=np.random.default_rng(2),
                 candidates=("forest", "forest-xy"))
    assert sel.chosen == "forest" and sel.cv_error["forest-xy"] > sel.cv_error["forest"]


def test_a_class_replaces_the_kept_one_only_on_significant_evidence():
    """Paired test: 20 of 100 touches the forest gets wrong and the SVMs right is a mean
    difference of 0.2 with a standard error of 0.04, z = 5 (switch); 2 of 100 is z = 0.02 / 0.014
    = 1.43 (stay)."""
    w = np.ones(100)
    forest = np.zeros(100)
    forest[:20] = 1
    svc = np.zeros(100)
    assert paired_z(forest, svc, w) == pytest.approx(5.0)
    assert prefer(("forest", "svc"), {"forest": forest, "svc": svc}, w) == "svc"
    few = np.zeros(100)
    few[:2] = 1
    assert paired_z(few, svc, w) == pytest.approx(1 / 0.7) and 1 / 0.7 < SWITCH_Z
    assert prefer(("forest", "svc"), {"forest": few, "svc": svc}, w) == "forest"
    assert paired_z(svc, svc, w) == 0.0 and paired_z(forest, svc, np.zeros(100)) == 0.0


def test_candidates_must_be_learned_classes_and_auto_is_a_valid_choice():
    with pytest.raises(ConfigError, match="'exact' is not learned"):
        choose(G, _two_discs(), match_threshold=1.5, area=AREA, rng=np.random.default_rng(0),
               candidates=("lines", "exact"))
    assert check_choice("auto") == "auto" and check_choice("svc") == "svc"
    with pytest.raises(ConfigError, match="unknown model class 'tree'; valid: auto, lines, svc"):
        check_choice("tree")


def test_auto_explores_with_the_explore_class():
    assert explore_class("auto") == EXPLORE_CLASS and explore_class("svc") == "svc"
    from kbcli.bench.learn import bench_keyboard
    from kbcli.sim import SimConfig, World, make_reacher

    kb = bench_keyboard("grid")
    ex = Exploration(ExploreConfig(budget=30, model_class="auto"),
                     World(kb, make_reacher(SimConfig())).touch, kb.area,
                     kb.config.match_threshold, np.random.default_rng(0))
    for _ in ex:
        pass
    assert isinstance(ex.model, ForestModel)


def test_explore_choice_keeps_the_forest_unless_another_class_is_clearly_better():
    heard = np.where((G[:, 0] + 0.5 * G[:, 1] < 560)[:, None], [[10.0, 10.0]], [[20.0, 20.0]])
    assert explore_choice(G, heard, match_threshold=1.5, area=AREA) == "svc"
    assert explore_choice(G, _two_discs(), match_threshold=1.5, area=AREA) == "svc"
    # an axis-aligned rectangle: the trees' splits are exact along its sides, the SVMs' only
    # round its corners a little better: not by 2 standard errors, the forest stays
    rect = np.full((len(G), 2), np.nan)
    rect[(abs(G[:, 0] - 400) < 120) & (abs(G[:, 1] - 350) < 40)] = [10.0, 10.0]
    assert explore_choice(G, rect, match_threshold=1.5, area=AREA) == "forest"


def _grid_exploration(model_class: str, budget: int) -> Exploration:
    from kbcli.bench.learn import bench_keyboard
    from kbcli.sim import SimConfig, World, make_reacher

    kb = bench_keyboard("grid")
    return Exploration(ExploreConfig(budget=budget, model_class=model_class),
                       World(kb, make_reacher(SimConfig(mode="ideal"))).touch, kb.area,
                       kb.config.match_threshold, np.random.default_rng(0))


def test_auto_rechooses_its_explorer_every_reselect_reaches(monkeypatch):
    """Under auto the class refitted is re-chosen after the batch reaching each multiple of
    RESELECT (here the choice is made to say svc), recorded with the reach count; the choice draws
    nothing from the exploration's generator (the reaches before it are a forest run's), and a
    named class is never re-chosen."""
    from kbcli.core.model.explore import loop as explore
    from kbcli.core.model.svc import SVCModel

    asked = []
    monkeypatch.setattr(explore, "explore_choice", lambda x, *a, **k: asked.append(len(x)) or "svc")
    auto = _grid_exploration("auto", RESELECT + 20)
    steps = list(auto)
    assert asked == [RESELECT] and auto.explorer == "svc"
    assert auto.explorers == [(0, "forest"), (RESELECT, "svc")]
    assert auto.explored_with == f"forest, svc from {RESELECT} reaches"
    assert isinstance(steps[-1].model, SVCModel)
    forest = _grid_exploration("forest", RESELECT + 20)
    list(forest)
    assert asked == [RESELECT] and forest.explored_with == "forest"
    np.testing.assert_array_equal(auto.targets[:RESELECT], forest.targets[:RESELECT])
    assert not np.array_equal(auto.targets[RESELECT:], forest.targets[RESELECT:])


def test_balanced_exploration_covers_early_and_then_seeks_boundaries():
    """The balanced strategy's first reaches are a coarse cover (many sounds heard in 30 reaches),
    the next ones fill the widest holes."""
    from kbcli.bench.learn import bench_keyboard
    from kbcli.sim import SimConfig, World, make_reacher

    kb = bench_keyboard("grid")
    ex = Exploration(ExploreConfig(strategy="balanced", budget=150, model_class="forest"),
                     World(kb, make_reacher(SimConfig())).touch, kb.area,
                     kb.config.match_threshold, np.random.default_rng(0))
    steps = list(ex)
    assert steps[-1].n_reaches == 150
    heard = ex.model.classify(ex.perceived[:30])
    assert len(set(heard.tolist())) >= 12  # 32 keys of 50 px: a coarse cover hears many
    from scipy.spatial import cKDTree

    first = cKDTree(ex.landed[:40]).query(ex.targets[40:60])[0]
    assert first.min() > 30.0  # the next picks fill the widest holes
    d = cKDTree(ex.landed).query(np.stack(np.meshgrid(np.arange(155.0, 650.0, 5.0),
                                                      np.arange(205.0, 500.0, 5.0)), -1)
                                 .reshape(-1, 2))[0]
    assert d.max() < 40.0  # 150 reaches leave no hole wider than a key


def test_auto_reads_its_candidates_from_what_the_classes_declare():
    """A class joins ``auto``'s candidates by declaring its place (``ModelClass.auto``), a
    plug-in's included; none is named in the selection code."""
    from kbcli.core.model.classes import MODEL_CLASSES, ModelClass
    from kbcli.core.model.classifiers import KNNModel

    assert ranked("auto") == ("forest", "forest-xy", "svc", "lines", "knn")
    with MODEL_CLASSES.temporarily("knn-late", ModelClass(lambda: KNNModel, auto=9, explores=9)):
        assert ranked("auto")[-1] == "knn-late" and ranked("explores")[-1] == "knn-late"
    assert "knn-late" not in ranked("auto")
