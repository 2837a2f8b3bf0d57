"""The layout study's runs: on every generated layout of ``envs.layouts.LAYOUTS``, OAPPO (sigma
0.1, lambda 0.7) against HAPPO, MAPPO, OAPPO at lambda in {0.2, 0.4, 0.7, 1} and the adaptive
reuse rule with its one setting for all layouts; one figure entry per layout, not in ``GRID``
(the study is run on request; ``studies.layout_study`` reads it)."""
from __future__ import annotations

from oapo_lite.envs.layouts import LAYOUTS
from oapo_lite.neural.config import TrainConfig
from oapo_lite.study.catalogue import grid
from oapo_lite.study.catalogue.figures import figure_runs, mazes

LAMBDAS = mazes.LAMBDAS
ADAPTIVE = mazes.ADAPTIVE_CURVES[0][0]  # gradient_test at the default sigma and lambda: one setting
# curve label -> the TrainConfig fields that make it; OAPPO's lambda = 0.7 is the "oappo" curve
CURVES = {"oappo": dict(algo="oappo"), "happo": dict(algo="happo"), "mappo": dict(algo="mappo")} | {
    f"oappo lambda={lam:g}": dict(algo="oappo", reuse_lambda=lam) for lam in LAMBDAS if lam != TrainConfig.reuse_lambda} | {
    ADAPTIVE: dict(mazes.ADAPTIVE_CURVES[0][1])}


def layout_figures(layouts=None) -> list[grid.Figure]:
    """One grid entry per layout (not in ``figures.GRID``: the study is run on request)."""
    layouts = sorted(LAYOUTS) if layouts is None else list(layouts)
    unknown = sorted(set(layouts) - set(LAYOUTS))
    if unknown:
        raise ValueError(f"unknown layouts {unknown}; the study's layouts are {sorted(LAYOUTS)}")
    return [grid.Figure(f"layout_{name}", tuple(CURVES.items()), common=dict(env=f"layout:{name}"))
            for name in layouts]


def study_runs(budget: str, layouts=None) -> list[tuple[str, str, TrainConfig]]:
    """(layout, curve label, config) for every run of the study at ``budget``."""
    return [(fig.common["env"].removeprefix("layout:"), label, cfg)
            for fig in layout_figures(layouts) for label, cfg in figure_runs(fig, budget)]
