"""Run files written before runs recorded what they are: each gets its seats' networks and agent
types (``results.STRUCTURE``: ``owner``, ``agent_types``) as two columns at the end of every row,
read once from the run's config and its engine, and no other cell changes (the rows are copied
as text). The study then reads them from the run and never from the engines installed where it
is judged, so a verdict is the same on every machine.

    python -m oapo_lite.study.runs.migrate [--budgets cpu paper ...]

Every grid run (``figures.GRID``, the layout study's) at the given budgets whose file lacks the
columns is rewritten atomically; a run whose engine is not installed here is named and left.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path

from oapo_lite.envs import registry as env_registry
from oapo_lite.neural.nets import owners
from oapo_lite.neural.results import STRUCTURE
from oapo_lite.neural.seps import group_labels
from oapo_lite.store import atomic_write, regular_file
from oapo_lite.study.catalogue.figures import FIGURES
from oapo_lite.study.catalogue.figures.layouts import study_runs
from oapo_lite.study.catalogue.grid import SHARED_RUNS
from oapo_lite.study.runs import experiments


def structure_columns(cfg, rows: list[dict]) -> list[tuple[str, str]]:
    """Per row of a run, its ``owner`` and ``agent_types`` cells as the run writes them (JSON)."""
    types = env_registry.agent_types(cfg.env, cfg.max_steps)
    owner = owners(cfg.networks_used, types)
    out = []
    for row in rows:
        seats = owner
        if cfg.algo == "seps":  # one network in pre-training, then the groups each row names
            groups = row.get("seps_groups") or ""
            seats = (group_labels(groups, env_registry.agent_names(cfg.env, cfg.max_steps)) if groups
                     else [0] * len(owner))
        out.append((json.dumps(list(seats)), json.dumps(list(types))))
    return out


def migrate(path, cfg) -> bool:
    """Add the two columns to the run file ``path`` of config ``cfg`` if it lacks them."""
    regular_file(path, "run file")
    text = path.read_text()
    rows = list(csv.reader(io.StringIO(text)))
    if set(STRUCTURE) <= set(rows[0]):
        return False
    records = [dict(zip(rows[0], r)) for r in rows[1:]]
    cells = structure_columns(cfg, records)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(rows[0] + list(STRUCTURE))
    writer.writerows(r + list(c) for r, c in zip(rows[1:], cells))
    atomic_write(lambda p: Path(p).write_text(buffer.getvalue()), path)
    return True


def grid_configs(budgets) -> dict:
    """run id -> (config, budget) of every grid run at ``budgets`` (figures and layout study)."""
    out = {}
    for budget in budgets:
        for run in experiments.grid_runs(budget, FIGURES):
            out.setdefault(run.cfg.run_id(), (run.cfg, budget))
        if budget in SHARED_RUNS:
            for _, _, cfg in study_runs(budget):
                out.setdefault(cfg.run_id(), (cfg, budget))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oapo_lite.study.runs.migrate", description=__doc__.splitlines()[0])
    parser.add_argument("--budgets", nargs="+", default=["cpu", "paper", "paper20"])
    args = parser.parse_args(argv)
    done = left = 0
    for cfg, budget in grid_configs(args.budgets).values():
        path = experiments.run_path(cfg, budget)
        if not path.exists():
            continue
        try:
            done += migrate(path, cfg)
        except ImportError as err:  # the engine is not installed here
            left += 1
            print(f"left {path.name}: {err}", file=sys.stderr)
    print(f"added {', '.join(STRUCTURE)} to {done} run files; {left} left (engine not installed)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
