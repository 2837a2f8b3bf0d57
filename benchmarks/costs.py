"""The committed cost table (``figures/data/costs.csv``) that ``reproduce --plan`` prices a run
by where no finished run of its type has a record: for every distinct cost key
(``study.costs.cost_key``) among the runs of the given budgets, one run of that key trained for
one evaluation period (at most ``CAP`` env steps) and an evaluation, and its CPU and wall
seconds per 1,000 env steps from its own record (``cpu_s``, ``wall_s``): training per step, and
the evaluation spread over the key's evaluation period; building the envs and the evaluation
before training are left out. Written atomically after every key, with
the CPU it was measured on and the git revision, so an interrupted measurement resumes.

    .venv/bin/python benchmarks/costs.py [--budgets cpu paper] [--again]

``--again`` measures every key anew; otherwise keys already in the table are kept. Prints one
line per key measured.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time

import pandas as pd

from oapo_lite.envs import registry
from oapo_lite.neural.cost import machine
from oapo_lite.neural.runstate import git_revision, load_history
from oapo_lite.neural.train import train
from oapo_lite.store import write_frame
from oapo_lite.study.runs import experiments
from oapo_lite.study.runs.costs import COSTS, KEY, cost_key

from loops import warm_up


CAP = 16_000  # env steps measured at most: a paper budget's evaluation period can be hundreds of thousands


def measure(cfg) -> dict:
    """``cfg`` from seed 0's start for one evaluation period, or as many iterations as fit in
    ``CAP`` steps, closed by an evaluation: CPU and wall seconds per 1,000 env steps, as its
    training per step plus one evaluation's cost spread over the period (``cfg.eval_every``)."""
    k = max(1, min(cfg.eval_every, CAP // cfg.iteration_steps))
    short = dataclasses.replace(cfg, steps=k * cfg.iteration_steps, eval_every=k,
                                **({"seps_pretrain_steps": min(cfg.seps_pretrain_steps, cfg.iteration_steps)}
                                   if cfg.algo == "seps" else {}))
    with tempfile.TemporaryDirectory() as out:
        rows = train(short, out, progress=False)
        trained = load_history(out)[-1]  # the sums after the last iteration, before its evaluation
    first, last = rows.iloc[0], rows.iloc[-1]
    period = cfg.eval_every * cfg.iteration_steps
    return {f"{clock}_per_kstep": 1000 * ((trained[f"{clock}_s"] - first[f"{clock}_s"]) / short.steps
                                          + (last[f"{clock}_s"] - trained[f"{clock}_s"]) / period)
            for clock in ("cpu", "wall")} | {"measured_steps": short.steps}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budgets", nargs="+", default=["cpu", "paper"])
    parser.add_argument("--again", action="store_true", help="measure every key anew")
    args = parser.parse_args()
    old = pd.read_csv(COSTS, dtype=str, keep_default_na=False) if COSTS.exists() and not args.again else pd.DataFrame(columns=list(KEY))
    done = {tuple(r[k] for k in KEY) for _, r in old.iterrows()}
    todo = {}
    for budget in args.budgets:
        for run in experiments.grid_runs(budget):
            key = cost_key(run.cfg)
            engine = registry.split(run.cfg.env)[0]
            if key not in done and key not in todo and not (engine and registry.missing_engine(engine)):
                todo[key] = run.cfg
    warm_up()
    rows = [old]
    for k, (key, cfg) in enumerate(todo.items(), 1):
        tic = time.perf_counter()
        price = measure(cfg)
        rows.append(pd.DataFrame([{**dict(zip(KEY, key)), **price, **machine(), "git_rev": git_revision()[:12]}], dtype=str))
        write_frame(pd.concat(rows, ignore_index=True), COSTS)
        print(f"[{k}/{len(todo)}] {' '.join(key[:4])} {key[6]}x{key[7]}: {price['cpu_per_kstep']:.3f} CPU-s per "
              f"1,000 steps ({time.perf_counter() - tic:.0f} s)", flush=True)
    print(f"{COSTS}: {sum(len(r) for r in rows)} keys")
    return 0


if __name__ == "__main__":
    sys.exit(main())
