"""Fake finished runs, written as the run cache holds real ones (every evaluation row of the
config, with the config's columns)."""
import json

import numpy as np
import pandas as pd

from oapo_lite import store
from oapo_lite.algorithms import ALGOS
from oapo_lite.envs import registry as env_registry
from oapo_lite.envs.oracle import optimal_return
from oapo_lite.neural.nets import owners
from oapo_lite.study.runs import experiments


def write_run(cfg, budget: str, frac, grid: int = 16_000, **columns) -> pd.DataFrame:
    """Write ``cfg``'s run with ``frac_opt = frac(step)``, where ``step`` is rounded down to a
    multiple of ``grid``: a curve that moves only every ``grid`` env steps, whatever the
    config's evaluation grid. ``columns`` adds or replaces columns."""
    steps = np.array(cfg.eval_steps)
    value = np.asarray(frac(steps // grid * grid), dtype=float)
    config = {k: v for k, v in cfg.flat().items() if v is not None}  # as a real run file holds them
    maze = env_registry.maze_of(cfg.env)  # a maze's return is its fraction of the oracle's optimum
    optimum = optimal_return(maze) if maze is not None else np.nan
    df = pd.DataFrame({**config, "iteration": steps // cfg.iteration_steps, "step": steps,
                       "eval_return": value * optimum if maze is not None else value,
                       "frac_opt": value if maze is not None else np.nan, "eval_success": np.clip(value, 0, 1),
                       "git_rev": "test", **learner_columns(cfg, len(steps)), **structure(cfg, len(steps)), **columns})
    store.write_frame(df, experiments.run_path(cfg, budget))
    return df


def structure(cfg, rows: int) -> dict:
    """What every run records it is: its seats' networks and agent types (``results.STRUCTURE``)."""
    types = env_registry.agent_types(cfg.env, cfg.max_steps)
    return {"owner": [json.dumps(owners(cfg.networks_used, types))] * rows,
            "agent_types": [json.dumps(list(types))] * rows}


def learner_columns(cfg, rows: int) -> dict:
    """What every run of ``cfg``'s family writes after its first iteration (empty at the first
    evaluation): a PPO / TRPO run's objective, critic loss, K and M (no reuse), an A2C run's losses."""
    def later(x):
        return [np.nan] + [x] * (rows - 1)

    if ALGOS[cfg.algo].a2c:
        return {"policy_loss": later(0.0), "value_loss": later(0.1), "entropy": later(1.0)}
    n = len(env_registry.agent_types(cfg.env, cfg.max_steps))
    return {"objective": later(0.0), "value_loss": later(0.1), "kl_matrix": later(json.dumps(np.zeros((n, n)).tolist())),
            "reuse_matrix": later(json.dumps(np.eye(n).tolist()))}


def interrupt(cfg, out, at: int) -> None:
    """Train ``cfg`` into ``out`` and stop it as a Ctrl-C would, right after iteration ``at``
    (what a resumed run must continue from)."""
    import pytest

    from oapo_lite.neural.train import train

    def crash(metrics):
        if metrics["iteration"] == at:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(cfg, out, progress=False, callback=crash)
