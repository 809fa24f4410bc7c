"""The report's figures: file names, titles and captions (drawn by :mod:`kbcli.viz.report`)."""

from __future__ import annotations

from kbcli.stages.artifact import Artifact
from kbcli.stages.report.source import Figure, exact_mode, upgrade


def figures(art: Artifact) -> list[Figure]:
    """The figures of the report (file names and captions)."""
    art = upgrade(art)
    modes = art.attrs["modes"]
    first = exact_mode(modes) or modes[0]
    figs = []
    ex = art.data.get("examples", {}).get(first, {})
    if any(any("snapshots" in e for e in by_s.values()) for by_s in ex.values()):
        figs.append(Figure("fig5_posterior.png", "Fig. 5: evolution of the posterior",
                           f"Posterior over the displacement (dx, dy) in px after 1, 2, 3, ... "
                           f"observations of one example run per method and strategy ({first} "
                           f"mode, first {art.config.get('example', '')} displacement; the same "
                           "displacement for every row), each panel scaled to its own maximum "
                           "(colour bar) and zoomed on the cells above 1e-3 of it and the truth "
                           "(axes in px differ between panels); the circle outlines the true "
                           "displacement, so a posterior collapsed onto one cell stays visible."))
    figs.append(Figure("fig6_entropy.png", "Fig. 6: entropy reduction",
                       "Posterior entropy (nats) against observations from t = 0 (the uniform "
                       "prior over the method's hypothesis grid), mean over the experiments of "
                       "each method and strategy, with the interquartile range shaded; one "
                       "panel per mode and size category. Entropies of different posteriors (KDE, likelihood) are "
                       "on the same grid but not of the same model: compare strategies within "
                       "a method."))
    for m in modes:
        figs.append(Figure(f"fig7_error_{m}.png", f"Fig. 7: error against observations ({m} mode)",
                           "RMSE of the displacement estimate (px) over the experiments of each "
                           "category against the number of observations, log scale, one row per "
                           "method; shaded: the interquartile range of the per-experiment error."))
    return figs


