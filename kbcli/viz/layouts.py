"""One figure per layout for ``kbcli bench layouts``: the layout, its learned model's map, the
learning curves and the adaptation curves."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.ticker import FixedLocator, NullFormatter, ScalarFormatter

from kbcli.core.model import accuracy as scoring
from kbcli.core.model.base import grid_points
from kbcli.stages.artifact import Artifact
from kbcli.viz.common import draw_keyboard, draw_layout, save
from kbcli.viz.palette import map_colours

MAP_STEP = 2.0  # px
_STRATEGY_COLOURS = {"random": "tab:grey", "active": "tab:orange", "infogain": "tab:blue"}
_CLASS_COLOURS = {"lines": "tab:green", "svc": "tab:purple"}
_EXPLORATION_STYLES = {"active": "-"}  # any other exploration: dotted


def _layout_panel(ax, res) -> None:
    """Top left: the layout and its working area."""
    kb = res.keyboard
    draw_layout(ax, kb, 5)
    ax.set_title(f"{res.layout}: {kb.describe()}\nlabels: note, tempo (bpm); dashed: working area",
                 fontsize=9)


def _map_panel(ax, kb, model_art: Artifact) -> None:
    """Top right: the adaptation model's map, wrong cells red, where the finger landed."""
    from kbcli.stages.models import load_model

    x0, y0, x1, y1 = kb.area
    model = load_model(model_art)
    _, pts = grid_points(kb.area, MAP_STEP)
    flat = pts.reshape(-1, 2)
    keys = scoring.class_keys(model.class_features_, kb)[model.predict_class(flat)]
    keys = keys.reshape(pts.shape[:2])
    wrong = keys != kb.key_at(flat).reshape(pts.shape[:2])
    colours = map_colours(kb.n_keys)
    ax.imshow(keys + 2, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest",
              cmap=ListedColormap(colours), vmin=-0.5, vmax=len(colours) - 0.5)
    red = np.zeros((*wrong.shape, 4))
    red[wrong] = (0.9, 0.0, 0.0, 0.95)
    ax.imshow(red, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    landed = np.asarray(model_art.data["samples"]["landed"], float)
    ax.plot(landed[:, 0], landed[:, 1], ".", color="black", ms=1.2, alpha=0.6)
    draw_keyboard(ax, kb, labels=False, fill=False, edge="0.3", alpha=0.5)
    a = model_art.attrs
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_title(f"adaptation model: {a.get('model_class')}, {a.get('n_reaches')} active reaches: "
                 f"accuracy {100 * a.get('accuracy', np.nan):.2f} %, boundary error "
                 f"{a.get('boundary_error_px', np.nan):.2f} px\nred: wrong (2 px cells); dots: "
                 "where the finger landed", fontsize=9)


def _learning_panel(ax, res) -> None:
    """Bottom left: the median learning curve per model class and exploration."""
    for mc in dict.fromkeys(r.model_class for r in res.learn_runs):
        for strategy in dict.fromkeys(r.strategy for r in res.learn_runs):
            runs = [r for r in res.learn_runs if (r.model_class, r.strategy) == (mc, strategy)]
            if not runs:
                continue
            n = np.array(runs[0].checkpoints)
            acc = np.array([r.accuracy for r in runs if len(r.accuracy) == len(n)])
            ax.plot(n, 100 * np.median(acc, axis=0), _EXPLORATION_STYLES.get(strategy, ":"),
                    color=_CLASS_COLOURS.get(mc, "black"), lw=1.6,
                    label=f"{mc}, {strategy} ({len(acc)} runs)")
    for level in (97, 99):
        ax.axhline(level, ls="--", color="grey", lw=0.8)
    lows = [line.get_ydata().min() for line in ax.get_lines() if len(line.get_ydata()) > 2]
    ax.set_ylim(max(50.0, min([90.0, *lows]) - 2), 100.3)
    ax.set_xlabel("reaches")
    ax.set_ylabel("median accuracy (%, 1 px grid)")
    ax.set_title("learning curves (dashed: 97 % and 99 %)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")


def _adapt_panel(ax, res) -> None:
    """Bottom right: the median error while adapting with the learned model, per strategy."""
    from kbcli.core.adaptation import stats

    for cell_label in dict.fromkeys(c.label for c in res.cells):
        for section, ls in (("learned", "-"), ("learned-rigid", "--")):
            cells = [c for c in res.cells if c.label == cell_label and c.section == section]
            if not cells:
                continue
            e = np.vstack([np.asarray(c.errors, float) for c in cells])
            med = stats.spread(e)["median"]
            steps = np.arange(1, e.shape[1] + 1)
            ax.plot(steps, np.maximum(med, 1e-2), ls, color=_STRATEGY_COLOURS.get(cell_label, "k"),
                    lw=1.6, label=f"{cell_label}, {'rigid' if section != 'learned' else 'translation'}"
                    f" ({len(e)} runs)")
    ax.axhline(2.0, ls=":", color="grey", lw=0.8)
    ax.set_yscale("log")
    ax.yaxis.set_major_locator(FixedLocator([0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50]))
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("touches")
    ax.set_ylabel("median error (px)")
    ax.set_title("adapting with the learned model (dotted: 2 px); all displacement categories",
                 fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper right")


def plot_layout(res, model_art: Artifact, cfg, path: str | os.PathLike) -> None:
    """Draw one layout's results (a :class:`kbcli.bench.layouts.LayoutResult`) to a PNG."""
    fig, axes = plt.subplots(2, 2, figsize=(13, 9.4))
    _layout_panel(axes[0, 0], res)
    _map_panel(axes[0, 1], res.keyboard, model_art)
    _learning_panel(axes[1, 0], res)
    _adapt_panel(axes[1, 1], res)
    fig.tight_layout()
    save(fig, path)
