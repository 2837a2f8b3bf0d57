"""The training runs the speed benchmarks measure (``smax_speed.py``, ``grf_speed.py``,
``mamujoco_speed.py``, ``train_speed.py``): a figure's run cut to a few iterations, the warm-up
before the first measured run, and the top of a run's profile where its loop falls short of its
engine."""
from __future__ import annotations

import cProfile
import dataclasses
import io
import pstats
import tempfile

from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures


def cut_short(figure: str, budget: str, algo: str, env: str, iterations: int) -> TrainConfig:
    """Seed 0's config of curve ``algo`` of ``figure`` at ``budget`` on ``env`` (the figure's
    first env's, moved to ``env``, where the figure has no run there), cut to ``iterations``."""
    runs = [r.cfg for r in figures.runs_of(figure, budget) if r.label == algo and r.cfg.seed == 0]
    cfg = next((c for c in runs if c.env == env), runs[0])
    return dataclasses.replace(cfg, env=env, steps=iterations * cfg.iteration_steps)


def warm_up() -> None:
    """torch's first-call costs (the first Adam imports torch._dynamo, about 1 CPU-s) are the
    process's, not the first measured loop's: a few seconds of maze training pay them."""
    with tempfile.TemporaryDirectory() as out:
        train(TrainConfig(algo="happo", env="black_red", steps=1600, eval_episodes=2), out, progress=False)


def profile(cfg: TrainConfig, top: int = 20) -> str:
    """The ``top`` functions of ``train(cfg)`` by cumulative wall-clock time, in this process."""
    with tempfile.TemporaryDirectory() as out:
        prof = cProfile.Profile()
        prof.runcall(train, cfg, out, resume=False, progress=False)
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(top)
    return text.getvalue()
