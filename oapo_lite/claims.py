"""Section 6.1's claim table at several seed budgets, read from the runs on disk.

A budget enters the table only when every run of the asked figures is on disk; nothing is
trained here (``make reproduce BUDGET=paper20`` trains the 20-seed runs).
"""
from __future__ import annotations

import pandas as pd

from oapo_lite import experiments, grid, verdicts

SEED_BUDGETS = ("paper", "paper20")  # 5 and 20 seeds per curve, otherwise identical


def on_disk(figure: str, budget: str) -> bool:
    """Every run of ``figure`` at ``budget`` has finished and been written."""
    return all(experiments.on_disk(cfg, budget) for _, cfg in grid.figure_runs(figure, budget))


def table(figures: tuple[str, ...], budgets: tuple[str, ...] = SEED_BUDGETS) -> pd.DataFrame:
    """The claims of ``figures`` at every budget in ``budgets`` whose runs are all on disk."""
    by_budget = {}
    for budget in budgets:
        if all(on_disk(f, budget) for f in figures):
            name = f"{budget} ({len(grid.get_budget(budget).seeds)} seeds)"
            by_budget[name] = [v for f in figures
                               for v in verdicts.claims(f, experiments.load_figure(f, budget))]
    if not by_budget:
        raise FileNotFoundError(f"no budget in {budgets} has every run of {figures} on disk")
    return verdicts.claim_table(by_budget)
