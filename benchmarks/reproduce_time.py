"""Wall time of the whole maze reproduction at a budget (default: paper), from nothing.

Runs `python -m oapo_lite reproduce` on the maze figures (`figures.MAZE_FIGURES`; the
real engines' paper runs are a cluster's work) with every result written to a fresh
temporary folder (OAPO_FIGURES) that holds a copy of the committed results less the runs
timed, so those are trained from nothing, the notebooks find the other budgets' runs they
quote, and the committed figures are not touched. Prints the reproduction's own summary, the total wall time and the CPU time of all
its processes (on a machine shared with other jobs the wall time grows, the CPU time much
less). From an empty cache, notebook 16 trains the layout study's 315 runs one at a time;
`--skip-notebooks` times the figures' training runs alone.

    .venv/bin/python benchmarks/reproduce_time.py [--budget paper] [--workers 2] [--executor ray]
        [--address HOST:PORT] [--skip-notebooks] [--figures FIGURE ...]
"""
import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from oapo_lite.study.runs import experiments
from oapo_lite.study.catalogue.figures import MAZE_FIGURES

parser = argparse.ArgumentParser()
parser.add_argument("--budget", default="paper")
parser.add_argument("--workers", type=int, default=2)
parser.add_argument("--executor", default="local", choices=["local", "ray"])
parser.add_argument("--address", default=None, help="Ray cluster (default: a private one on this machine)")
parser.add_argument("--skip-notebooks", action="store_true", help="time the training runs only")
parser.add_argument("--figures", nargs="+", default=list(MAZE_FIGURES), help="the figures whose runs are trained")
args = parser.parse_args()
extra = ["--figures", *args.figures, "--executor", args.executor] + (["--address", args.address] if args.address else []) \
    + (["--skip-notebooks"] if args.skip_notebooks else [])

with tempfile.TemporaryDirectory() as name:
    tmp = Path(name)
    shutil.copytree(experiments.ROOT / "figures", tmp, dirs_exist_ok=True,
                    ignore=shutil.ignore_patterns("checkpoints"))
    env = {**os.environ, "OAPO_FIGURES": name}
    for run in experiments.grid_runs(args.budget, args.figures):  # the runs timed start from nothing
        (tmp / experiments.run_path(run.cfg, args.budget).relative_to(experiments.ROOT / "figures")).unlink(missing_ok=True)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "oapo_lite", "reproduce", "--budget", args.budget,
                    "--workers", str(args.workers), "--check", *extra], env=env, check=True)
    total = time.perf_counter() - start
usage = resource.getrusage(resource.RUSAGE_CHILDREN)  # every finished descendant, kernels included
what = "training runs" if args.skip_notebooks else "reproduction"
print(f"\nwhole {args.budget}-budget {what} from nothing: {total:.1f} s wall time on {os.cpu_count()} cores, "
      f"executor {args.executor}" + (f" with {args.workers} workers" if args.executor == "local" else "")
      + f"; CPU time {usage.ru_utime + usage.ru_stime:.0f} s (locally; Ray workers are not counted); "
      f"load average {os.getloadavg()[0]:.1f} at the end")
