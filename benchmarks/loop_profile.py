"""The top of a profile of one training run, for the speed benchmarks whose loop falls short of
its engine (``smax_speed.py``, ``grf_speed.py``)."""
from __future__ import annotations

import cProfile
import io
import pstats
import tempfile

from oapo_lite.config import TrainConfig
from oapo_lite.train import train


def profile(cfg: TrainConfig, top: int = 20) -> str:
    """The ``top`` functions of ``train(cfg)`` by cumulative wall-clock time, in this process."""
    with tempfile.TemporaryDirectory() as out:
        prof = cProfile.Profile()
        prof.runcall(train, cfg, out, resume=False, progress=False)
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(top)
    return text.getvalue()
