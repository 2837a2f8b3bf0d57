"""Wall time of the whole maze reproduction at a budget (default: paper), from nothing.

Runs `python -m oapo_lite reproduce` with every result written to a fresh temporary folder
(OAPO_FIGURES), so nothing is cached and the committed figures are not touched. Prints the
reproduction's own summary, the total wall time and the CPU time of all its processes (on a
machine shared with other jobs the wall time grows, the CPU time much less).

    .venv/bin/python benchmarks/reproduce_time.py [--budget paper] [--workers 2]
"""
import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

parser = argparse.ArgumentParser()
parser.add_argument("--budget", default="paper")
parser.add_argument("--workers", type=int, default=2)
args = parser.parse_args()

with tempfile.TemporaryDirectory() as tmp:
    env = {**os.environ, "OAPO_FIGURES": tmp}
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "oapo_lite", "reproduce", "--budget", args.budget,
                    "--workers", str(args.workers), "--check"], env=env, check=True)
    total = time.perf_counter() - start
usage = resource.getrusage(resource.RUSAGE_CHILDREN)  # every finished descendant, kernels included
print(f"\nwhole {args.budget}-budget reproduction from nothing: {total / 60:.1f} min wall time "
      f"({total:.0f} s) on {os.cpu_count()} cores with {args.workers} workers; "
      f"CPU time {usage.ru_utime + usage.ru_stime:.0f} s")
