"""The workers of the two phases (run by :mod:`kbcli.io.runner`): setup once, then one task."""

from __future__ import annotations

import numpy as np

from kbcli.core.adaptation.setup import table_key
from kbcli.stages.quality.config import EXACT, QualityConfig, adapt_config
from kbcli.stages.quality.plan import LearnTask, Task


def learn_setup(ctx: dict) -> dict:
    from kbcli.stages.learn import LearnConfig

    return {"keyboard": ctx["keyboard"], "cfg": QualityConfig.from_dict(ctx["quality"]),
            "LearnConfig": LearnConfig}


def learn_one(state: dict, task: LearnTask) -> dict:
    """Learn one model; returns its artifact as ``{"artifact": Artifact}``."""
    from kbcli.sim import SimConfig
    from kbcli.stages import learn as learn_stage

    cfg: QualityConfig = state["cfg"]
    sim = SimConfig(mode=cfg.mode, reach_noise=float(cfg.reach_noise), arm=dict(cfg.arm))
    lc = state["LearnConfig"](strategy=task.exploration, budget=task.budget, sim=sim)
    art = learn_stage.run(lc, state["keyboard"], rng=np.random.default_rng(task.seed),
                          seed=task.seed)
    return {"artifact": art}


def adapt_setup(ctx: dict) -> dict:
    from kbcli.stages import keyboard as keyboard_stage
    from kbcli.stages.models import load_model

    cfg = QualityConfig.from_dict(ctx["quality"])
    models = {name: load_model(art) for name, art in ctx["models"].items()}
    kb = keyboard_stage.load(next(iter(ctx["models"].values())))
    if cfg.ideal:
        from kbcli.stages.learn import exact_artifact

        models[EXACT] = load_model(exact_artifact(ctx["keyboard"]))
    return {"cfg": cfg, "models": models, "keyboard": kb, "tables": {}}


def adapt_one(state: dict, task: Task) -> dict:
    """One adaptation; returns the error (px) after every touch and the wall time per step."""
    from kbcli.stages import adapt as adapt_stage

    cfg: QualityConfig = state["cfg"]
    acfg = adapt_config(cfg, task.method)
    model = state["models"][task.model]
    key = (task.model, table_key(model, acfg.adapter_config()))
    if key not in state["tables"]:
        # keep the current model's tables only: plan() runs a model's tasks together
        if any(m != task.model for m, _ in state["tables"]):
            state["tables"].clear()
        state["tables"][key] = adapt_stage.build_shared_table(acfg, model)
    rng = np.random.default_rng(np.random.SeedSequence(task.entropy, spawn_key=task.spawn_key))
    out = adapt_stage.experiment(acfg, model, state["keyboard"], np.asarray(task.params, float),
                                 rng=rng, table=state["tables"][key])
    return {"errors": np.asarray(out["errors"], float), "step_ms": np.asarray(out["step_ms"])}


