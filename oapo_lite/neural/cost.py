"""What a run costs: CPU seconds (this process with all its threads, and the processes in which
an engine steps its copies), wall seconds, and the machine they were measured on. A run keeps
both sums across resumes in its checkpoint; every results row and history entry carries them
so far (``results.COLUMNS``).
"""
from __future__ import annotations

import functools
import os
import time
from pathlib import Path

from oapo_lite.envs.vec import HasWorkers

CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


@functools.cache
def machine() -> dict:
    """The CPU's model name (Linux's /proc/cpuinfo; else the platform's word) and its logical cores."""
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    if not model:
        import platform

        model = platform.processor() or platform.machine() or "unknown"
    return {"cpu_model": model, "cpu_count": os.cpu_count() or 1}


def _process_seconds(pid: int) -> float:
    """CPU seconds of process ``pid`` and its waited-for children, from /proc (0 where unreadable)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return 0.0
    return sum(int(x) for x in fields[11:15]) / CLOCK_TICKS  # utime, stime, cutime, cstime


def cpu_seconds(envs) -> float:
    """CPU seconds of this process and of the worker processes of ``envs`` (``worker_pids()``,
    where an engine steps its copies elsewhere: GRF)."""
    pids = [pid for env in envs if isinstance(env, HasWorkers) for pid in env.worker_pids()]
    return time.process_time() + sum(_process_seconds(pid) for pid in pids)


def clocks() -> tuple[float, float]:
    """(CPU seconds of this process, wall seconds) now: where a ``Meter`` starts counting."""
    return time.process_time(), time.perf_counter()


class Meter:
    """Adds the time since its last reading (first: since ``start``, from ``clocks``) to
    ``spent`` ({"cpu_s", "wall_s"}), a run's sums; the CPU time of ``envs``' workers counts
    from their start."""

    def __init__(self, spent: dict, envs, start: tuple[float, float]):
        self.spent, self.envs, self._last = spent, envs, start

    def _now(self) -> tuple[float, float]:
        return cpu_seconds(self.envs), time.perf_counter()

    def read(self) -> dict:
        """The run's sums so far: {"cpu_s", "wall_s"}."""
        now = self._now()
        self.spent["cpu_s"] += now[0] - self._last[0]
        self.spent["wall_s"] += now[1] - self._last[1]
        self._last = now
        return dict(self.spent)
