"""The catalogue: every figure the project reproduces, one module per engine family (``mazes``,
``smax``, ``mujoco``, ``grf``) and one for what SMAX and MuJoCo share (``readings``). A new
figure is a new entry in its family's ``FIGURES``; ``grid`` holds the types."""
from __future__ import annotations

from oapo_lite.neural.config import TrainConfig
from oapo_lite.study.catalogue.figures import grf, mazes, mujoco, smax
from oapo_lite.study.catalogue.grid import BUDGETS, Figure, Run

GRID = (*mazes.FIGURES, *smax.FIGURES, *mujoco.FIGURES, *grf.FIGURES)
FIGURES = tuple(f.id for f in GRID)
MAZE_FIGURES = tuple(f.id for f in mazes.FIGURES)  # Section 6.1; the others run real engines
# Eq. 9's sigma per (env, reading), by ``selection.gate_sigma``'s rule
SELECTION_SIGMA = smax.SELECTION_SIGMA | mujoco.SELECTION_SIGMA


def get_figure(figure: Figure | str) -> Figure:
    """A figure of the catalogue by its id; a ``Figure`` as it is."""
    if isinstance(figure, Figure):
        return figure
    known = {f.id: f for f in GRID}
    if figure not in known:
        raise ValueError(f"unknown figure {figure!r}; choose from {sorted(known)}")
    return known[figure]


def runs_of(figure: Figure | str, budget: str) -> list[Run]:
    """A figure's runs at a budget (``Figure.runs``), the figure by its id or as it is."""
    return get_figure(figure).runs(budget)


def required_runs(figure: Figure | str, budget: str) -> list[Run]:
    """``runs_of``, refusing a figure that has no runs at ``budget`` (a ``ValueError`` naming the
    budgets it has runs at): where it is named on purpose, an empty answer would read as "nothing
    to do" or "nothing on disk"."""
    runs = runs_of(figure, budget)
    if not runs:
        fig = get_figure(figure)
        raise ValueError(f"figure {fig.id!r} has no runs at budget {budget!r}; it has runs at "
                         f"{[b for b in BUDGETS if fig.runs(b)]}")
    return runs


def figure_runs(figure: Figure | str, budget: str) -> list[tuple[object, TrainConfig]]:
    """(label, config) of every run of a figure."""
    return [(r.label, r.cfg) for r in runs_of(figure, budget)]
