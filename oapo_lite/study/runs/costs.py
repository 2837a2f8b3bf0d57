"""What a grid costs before it is spent (``python -m oapo_lite reproduce --plan``).

A run's CPU time per env step depends on its engine, its algorithm's reading and its batch and
evaluation shape (``cost_key``), not on its seed or learning rate. Its figure comes from the
records of finished runs with the same key (every results row carries ``cpu_s``; ``neural.cost``),
else from the committed table ``COSTS`` that ``benchmarks/costs.py`` measures (with the CPU it
was measured on); where neither has one, the plan says so instead of guessing. ``plan`` sums a
budget's figures: their runs and env steps, what is on disk and what would train, its CPU hours
and the wall time on some workers.
"""
from __future__ import annotations

import heapq
import os
import sys
from dataclasses import dataclass

import numpy as np
import pandas as pd

from oapo_lite import cli
from oapo_lite.cli import boolean
from oapo_lite.envs import registry as env_registry
from oapo_lite.neural import results
from oapo_lite.neural.config import TrainConfig
from oapo_lite.store import is_file
from oapo_lite.study.runs import experiments, readme
from oapo_lite.study.catalogue.figures import FIGURES, runs_of

COSTS = experiments.ROOT / "figures" / "data" / "costs.csv"  # the committed table, whatever OAPO_FIGURES says
KEY = ("env", "algo", "networks", "update_by", "reuse_mode", "reuse_adapt", "n_envs", "rollout_steps", "hidden",
       "ppo_epochs", "n_minibatch", "feature_norm", "eval_every", "eval_episodes", "max_steps")


def cost_key(cfg: TrainConfig) -> tuple:
    """What a run's cost per env step depends on (``KEY``); a maze given as text counts as one
    map, whatever its cells."""
    engine = env_registry.split(cfg.env)[0] if cfg.env_fn is None else "env_fn"
    env = cfg.env if engine else ("a map text" if "\n" in cfg.env else cfg.env)
    values = dict(env=env, networks=cfg.networks_used, rollout_steps=cfg.rollout_steps, hidden="-".join(map(str, cfg.hidden)))
    return tuple(str(values[k] if k in values else getattr(cfg, k)) for k in KEY)


@dataclass(frozen=True)
class Price:
    cpu_per_kstep: float  # CPU seconds per 1,000 env steps, evaluations included
    source: str  # "records" (finished runs of this key) or "table" (benchmarks/costs.py)


def table(path=None) -> dict[tuple, Price]:
    """The committed table (or the one at ``path``): key -> price."""
    path = COSTS if path is None else path
    if not is_file(path, "cost table"):
        return {}
    df = pd.read_csv(path, dtype=str, keep_default_na=False)  # "None" is a key value, not a missing one
    return {tuple(row[k] for k in KEY): Price(float(row["cpu_per_kstep"]), "table") for _, row in df.iterrows()}


def recorded(runs: list[tuple[TrainConfig, pd.DataFrame]]) -> dict[tuple, Price]:
    """From finished runs (config, results rows): per key, the median over runs of CPU seconds
    per 1,000 env steps (a run without a record, trained before costs were recorded, gives none)."""
    per_key: dict[tuple, list[float]] = {}
    for cfg, df in runs:
        results.check_values(df[[c for c in ("step", "cpu_s", "wall_s") if c in df]])  # a sum that fell prices nothing
        if "cpu_s" in df and df["cpu_s"].notna().all():
            per_key.setdefault(cost_key(cfg), []).append(1000 * float(df["cpu_s"].iloc[-1]) / cfg.steps)
    return {k: Price(float(np.median(v)), "records") for k, v in per_key.items()}


@dataclass
class Line:
    """One figure's (or the total's) row of the plan."""

    figure: str
    runs: int
    steps: int
    cached_runs: int
    todo_runs: int
    todo_steps: int
    cpu_hours: float  # of the runs to train that have a price
    unpriced: int  # runs to train without a price
    sources: str


def plan(budget: str, figures=FIGURES, workers: int = 2,
         from_nothing: bool = False, envs=None) -> tuple[list[Line], Line, float]:
    """Per figure and in total (every distinct run once): runs, env steps, on disk, to train and
    its CPU hours; and the wall hours of the runs to train on ``workers`` processes, as
    ``run_all`` orders them. ``from_nothing``: as if no run were on disk (what the budget costs);
    ``envs``: only these envs' runs (all: None). Reads only."""
    from_nothing, workers = boolean(from_nothing, "from_nothing"), cli.workers(workers, "workers")
    prices = table()
    on_disk, finished = {}, []
    keep = lambda these: [r for r in these if envs is None or r.cfg.env in envs]  # noqa: E731
    runs = keep(experiments.grid_runs(budget, figures))
    for run in runs:
        try:
            finished.append((run.cfg, experiments.read_run(run.cfg, budget)))
            on_disk[run.cfg.run_id()] = not from_nothing
        except (FileNotFoundError, experiments.DamagedFile):
            on_disk[run.cfg.run_id()] = False
    prices |= recorded(finished)  # a run record beats the table

    def line(name: str, these: list) -> Line:
        todo = [r for r in these if not on_disk[r.cfg.run_id()]]
        priced = [r for r in todo if cost_key(r.cfg) in prices]
        sources = sorted({prices[cost_key(r.cfg)].source for r in priced})
        return Line(name, len(these), sum(r.cfg.steps for r in these), len(these) - len(todo), len(todo),
                    sum(r.cfg.steps for r in todo),
                    sum(run_cpu_seconds(r.cfg, prices) for r in priced) / 3600, len(todo) - len(priced),
                    " + ".join(sources) or ("-" if not todo else "none"))

    lines = [line(f, keep(runs_of(f, budget))) for f in figures]  # a run of two figures is in both
    total = line("total", runs)
    todo = [r for r in runs if not on_disk[r.cfg.run_id()] and cost_key(r.cfg) in prices]
    return lines, total, wall_hours(todo, prices, workers)


def run_cpu_seconds(cfg: TrainConfig, prices: dict) -> float:
    return prices[cost_key(cfg)].cpu_per_kstep * cfg.steps / 1000


def wall_hours(todo: list, prices: dict, workers: int) -> float:
    """The runs ``todo`` on ``workers`` processes, each taking the next run in ``run_all``'s
    order (seed by seed, longest first) as it becomes free; no faster than their CPU time
    spread over this machine's cores."""
    order = sorted(todo, key=lambda r: (r.cfg.seed, -run_cpu_seconds(r.cfg, prices)))
    free = [0.0] * max(1, min(workers, len(order)))
    for run in order:
        heapq.heappush(free, heapq.heappop(free) + run_cpu_seconds(run.cfg, prices))
    spread = sum(run_cpu_seconds(r.cfg, prices) for r in order) / min(workers, os.cpu_count() or 1)
    return max(max(free), spread) / 3600


LEGEND = """\
columns: runs and env steps of each figure at the budget (the total counts a run of two figures once); on
disk: runs already trained and whole in the run cache; to train and steps to train: the others; CPU hours:
of the runs to train, from their price per env step; from: where that price comes from: records (finished
runs of the same engine, algorithm and batch shape), table (figures/data/costs.csv, benchmarks/costs.py),
none (no price: the hours leave those runs out), - (nothing to train)."""


def describe(budget: str, lines: list[Line], total: Line, wall: float, workers: int) -> str:
    """The plan as a table and a closing sentence."""
    head = ["figure", "runs", "env steps", "on disk", "to train", "steps to train", "CPU hours", "from"]
    body = [[x.figure, x.runs, _steps(x.steps), x.cached_runs, x.todo_runs, _steps(x.todo_steps),
             _hours(x.cpu_hours, x.unpriced), x.sources] for x in [*lines, total]]
    widths = [max(len(str(r[k])) for r in [head, *body]) for k in range(len(head))]
    text = "\n".join("  ".join(str(c).ljust(w) for c, w in zip(r, widths)) for r in [head, *body])
    unpriced = (f"; {total.unpriced} run(s) to train have no measured cost (no record, not in {COSTS.name}: "
                "run benchmarks/costs.py), so the hours leave them out" if total.unpriced else "")
    return (f"{text}\n\n{LEGEND}\n\nbudget {budget!r}: {total.todo_runs} of {total.runs} runs to train, {total.cpu_hours:.1f} CPU "
            f"hours, about {_wall(wall)} of wall time on {workers} worker(s){unpriced}. Costs measured on "
            f"{_machines()}; nothing was trained or written.")


def _steps(n: int) -> str:
    return "0" if n == 0 else f"{n / 1e6:.1f}M" if n >= 1e6 else f"{n / 1e3:.0f}k"


def _hours(h: float, unpriced: int) -> str:
    return f"{h:.2f}" + (f" + {unpriced} unpriced" if unpriced else "")


def _wall(hours: float) -> str:
    minutes = max(1, round(hours * 60))
    return f"{minutes} minute{'s' * (minutes > 1)}" if hours < 2 else f"{hours:.1f} hours"


def _machines() -> str:
    if not is_file(COSTS, "cost table"):
        return "no machine (no table)"
    df = pd.read_csv(COSTS)
    machines = sorted({(m, int(c)) for m, c in zip(df["cpu_model"], df["cpu_count"])})
    return "; ".join(f"{m} ({c} cores)" for m, c in machines)


def main_plan(budget: str, figures, workers: int) -> str:
    lines, total, wall = plan(budget, figures, workers)
    return describe(budget, lines, total, wall, workers)


BEGIN, END = "<!-- costs: generated by python -m oapo_lite.study.runs.costs -->", "<!-- end of costs -->"
README_BUDGETS = ("student", "cpu", "paper")
README_WORKERS = 2


def readme_markdown() -> str:
    """What each budget costs from nothing, per figure (runs, env steps, CPU hours), with each
    budget's total and wall time on two workers: the README's block between its markers."""
    per_budget = {b: plan(b, from_nothing=True, workers=README_WORKERS) for b in README_BUDGETS}
    cells = {b: {x.figure: x for x in lines} for b, (lines, _, _) in per_budget.items()}
    rows = [[f, *(_cell(cells[b][f]) if cells[b][f].runs else "-" for b in README_BUDGETS)]
            for f in FIGURES if any(cells[b][f].runs for b in README_BUDGETS)]
    rows.append(["total (a run of two figures once)", *(_cell(per_budget[b][1]) for b in README_BUDGETS)])
    sentences = []
    for b, (_, total, wall) in per_budget.items():
        rest = f", {total.unpriced} runs without a measured cost left out" if total.unpriced else ""
        sentences.append(f"- `{b}`: {total.runs} runs, {_steps(total.steps)} env steps, about "
                         f"{total.cpu_hours:,.{2 if total.cpu_hours < 10 else 1}f} CPU hours from nothing: {_wall(wall)} "
                         f"on {README_WORKERS} workers of this kind of machine{rest}.")
    table_text = "\n".join(["| figure | " + " | ".join(f"`{b}`: runs, env steps, CPU hours" for b in README_BUDGETS) + " |",
                            "| --- |" + " --- |" * len(README_BUDGETS)]
                           + ["| " + " | ".join(r) + " |" for r in rows])
    return "\n\n".join([f"Measured CPU time per env step (the committed runs' own records where they have one, else "
                         f"`figures/data/costs.csv`, measured on {_machines()} by `benchmarks/costs.py`), times each "
                         "budget's runs:", "\n".join(sentences), table_text])


def _cell(line: Line) -> str:
    return f"{line.runs}, {_steps(line.steps)}, {_hours(line.cpu_hours, line.unpriced)}"


def write_readme() -> None:
    readme.rewrite(BEGIN, END, readme_markdown())


if __name__ == "__main__":
    write_readme()
    print(f"wrote the costs of {list(README_BUDGETS)} into {readme.README}", file=sys.stderr)

