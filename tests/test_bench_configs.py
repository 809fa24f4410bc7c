"""The benchmarks' configs (pydantic, frozen, unknown keys refused): a bad value is one line naming
the benchmark, the key and what is allowed; on the command line, exit 1 and nothing run."""

from __future__ import annotations

import pytest
from helpers import one_line_error

from kbcli.bench import adapt as adapt_bench
from kbcli.bench import animate as animate_bench
from kbcli.bench import detect as detect_bench
from kbcli.bench import learn as learn_bench
from kbcli.bench.layouts import LayoutsConfig
from kbcli.cli import app
from kbcli.errors import ConfigError

BAD = [
    (adapt_bench.BenchConfig, {"experiments": 1}, ("bench adapt.experiments", "2", "got 1")),
    (adapt_bench.BenchConfig, {"max_steps": 0}, ("bench adapt.max_steps", "1")),
    (adapt_bench.BenchConfig, {"sections": ("exact", "fast")}, ("unknown section 'fast'",
                                                                 "exact", "learned-rigid")),
    (adapt_bench.BenchConfig, {"categories": ("huge",)}, ("unknown category 'huge'", "small")),
    (adapt_bench.BenchConfig, {"strategies": ("greedy",)}, ("greedy", "infogain")),
    (adapt_bench.BenchConfig, {"noise": -1.0}, ("bench adapt.noise", "-1.0")),
    (adapt_bench.BenchConfig, {"layout": "circle"}, ("unknown layout 'circle'", "grid")),
    (adapt_bench.BenchConfig, {"experimnets": 3}, ("unknown bench adapt option 'experimnets'",
                                                   "experiments")),
    (detect_bench.BenchConfig, {"p_pre": 1.0}, ("bench detect.p_pre", "1.0")),
    (detect_bench.BenchConfig, {"p_post": (0.2, 1.5)}, ("bench detect.p_post", "1.5")),
    (detect_bench.BenchConfig, {"change_min": 500, "change_max": 400}, ("change_max",)),
    (detect_bench.BenchConfig, {"detectors": ("kswin",)}, ("unknown detector 'kswin'", "adwin")),
    (detect_bench.BenchConfig, {"streams": 2.5}, ("bench detect.streams", "whole number")),
    (detect_bench.BenchConfig, {"n_lt": 10, "n_st": 10}, ("n_st must be smaller",)),
    (learn_bench.BenchConfig, {"seeds": 0}, ("bench learn.seeds", "got 0")),
    (learn_bench.BenchConfig, {"budgets": (100, 0)}, ("bench learn.budgets", "got 0")),
    (learn_bench.BenchConfig, {"strategies": ("exact",)}, ("unknown strategy 'exact'", "active")),
    (learn_bench.BenchConfig, {"model_classes": ("tree",)}, ("unknown model class 'tree'",
                                                             "lines")),
    (learn_bench.BenchConfig, {"mode": "fast"}, ("fast", "dynamics")),
    (learn_bench.BenchConfig, {"eval_step": 0.0}, ("bench learn.eval_step", "0")),
    (animate_bench.BenchConfig, {"repeats": 0}, ("bench animate.repeats", "got 0")),
    (animate_bench.BenchConfig, {"loop": "yes"}, ("bench animate.loop", "true or false")),
    (LayoutsConfig, {"layouts": ("grid", "circle")}, ("unknown layout 'circle'",)),
    (LayoutsConfig, {"adapt_class": "tree"}, ("layouts.adapt_class", "tree")),
    (LayoutsConfig, {"experiments": 1}, ("experiments", "2")),
    (LayoutsConfig, {"budgets": ()}, ("layouts.budgets",)),
]


@pytest.mark.parametrize(("cls", "kwargs", "fragments"), BAD,
                         ids=[f"{c.__module__.rsplit('.', 1)[-1]}-{next(iter(k))}"
                              for c, k, _ in BAD])
def test_a_bad_value_is_one_line_naming_the_key(cls, kwargs, fragments):
    with pytest.raises(ConfigError) as info:
        cls(**kwargs)
    msg = str(info.value)
    assert "\n" not in msg, msg
    for f in fragments:
        assert f in msg, (f, msg)


@pytest.mark.parametrize("cls", [adapt_bench.BenchConfig, detect_bench.BenchConfig,
                                 learn_bench.BenchConfig, animate_bench.BenchConfig,
                                 LayoutsConfig])
def test_configs_are_frozen_and_round_trip(cls):
    cfg = cls()
    with pytest.raises(Exception):  # noqa: B017 (pydantic's frozen-instance error)
        cfg.seed = 3
    assert cls.from_dict(cfg.to_dict()) == cfg


def test_learn_budgets_are_sorted_once_each():
    assert learn_bench.BenchConfig(budgets=(800, 200, 200)).budgets == (200, 800)


def test_layouts_toml_unknown_keys_are_named(tmp_path):
    f = tmp_path / "layouts.toml"
    f.write_text("[layouts]\nlayouts = ['grid']\n[layouts.adapt]\nexperiment = 3\n")
    with pytest.raises(ConfigError, match=r"unknown \[layouts.adapt\] option\(s\) experiment"):
        LayoutsConfig.from_toml(f)
    f.write_text("[layouts]\nlayouts = ['grid']\n[layouts.learn]\nseeds = 2\n")
    cfg = LayoutsConfig.from_toml(f)
    assert (cfg.layouts, cfg.seeds, cfg.source) == (("grid",), 2, str(f))


@pytest.mark.parametrize(("args", "fragments"), [
    (["bench", "adapt", "--experiments", "1", "--section", "exact"],
     ("bench adapt.experiments", "2")),
    (["bench", "adapt", "--section", "fast"], ("unknown section 'fast'", "exact")),
    (["bench", "adapt", "--category", "huge", "--section", "exact"],
     ("unknown category 'huge'",)),
    (["bench", "detect", "--detectors", "binomial,kswin"], ("unknown detector 'kswin'",)),
    (["bench", "detect", "--p-pre", "1.5"], ("bench detect.p_pre",)),
    (["bench", "learn", "--model-class", "tree"], ("unknown model class 'tree'",)),
])
def test_bench_commands_refuse_bad_values_in_one_line(runner, args, fragments):
    one_line_error(runner.invoke(app, args), *fragments)
