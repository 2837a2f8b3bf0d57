"""What Ray adds to a run: start-up of a private cluster on this machine (127.0.0.1), the first
task (a worker process starting with the package shipped as its runtime env), the round trip of
an empty task, and the extra wall time of one smoke training run as a Ray task over the same
run in this process. Prints the figures; nothing is asserted.

    .venv/bin/python benchmarks/ray_overhead.py [--cpus 2] [--tasks 200] [--repeats 3]
"""
import argparse
import os
import statistics
import tempfile
import time

from oapo_lite.study.catalogue import figures
from oapo_lite.study.runs import executors

parser = argparse.ArgumentParser()
parser.add_argument("--cpus", type=int, default=2)
parser.add_argument("--tasks", type=int, default=200, help="empty tasks for the round-trip figures")
parser.add_argument("--repeats", type=int, default=3, help="smoke runs timed each way")
args = parser.parse_args()


def noop(x):
    return x


def seconds(fn) -> float:
    tic = time.perf_counter()
    fn()
    return time.perf_counter() - tic


print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start")
with tempfile.TemporaryDirectory(prefix="oapo-ray-") as temp:
    tic = time.perf_counter()
    ray, _ = executors.connect(None, num_cpus=args.cpus, _temp_dir=temp, object_store_memory=100 * 2**20,
                              runtime_env=executors.runtime_env())
    print(f"private cluster start-up ({args.cpus} CPUs):          {time.perf_counter() - tic:7.2f} s")
    try:
        task = ray.remote(noop).options(num_cpus=1)
        first = seconds(lambda: ray.get(task.remote(0)))
        print(f"first empty task (worker start, runtime env):   {first:7.2f} s")
        serial = seconds(lambda: [ray.get(task.remote(i)) for i in range(args.tasks)])
        print(f"empty task round trip, one at a time:           {1e3 * serial / args.tasks:7.2f} ms")
        batch = seconds(lambda: ray.get([task.remote(i) for i in range(args.tasks)]))
        print(f"empty tasks, {args.tasks} submitted at once:             {1e3 * batch / args.tasks:7.2f} ms each")

        (run,) = figures.runs_of("fig1", "smoke")
        job = ray.remote(executors._ray_job).options(num_cpus=1)
        local, remote = [], []
        for k in range(args.repeats + 1):  # the first of each is a cold start (a fresh worker imports torch)
            with tempfile.TemporaryDirectory() as ck:  # no checkpoint to resume from: a full run each time
                local.append(seconds(lambda: executors.train_job(run.cfg, f"{ck}/local")))
                remote.append(seconds(lambda: ray.get(job.remote(run.cfg, f"{ck}/ray"))))
        print(f"first smoke run, cold: {local[0]:.2f} s in this process, {remote[0]:.2f} s as a Ray task")
        local, remote = local[1:], remote[1:]
        print(f"smoke run ({run.cfg.steps} env steps) in this process: median {statistics.median(local):6.2f} s "
              f"of {[round(t, 2) for t in local]}")
        print(f"the same run as a Ray task:                   median {statistics.median(remote):6.2f} s "
              f"of {[round(t, 2) for t in remote]}")
        print(f"Ray overhead per run (warm): {statistics.median(remote) - statistics.median(local):+.2f} s "
              f"(median difference)")
    finally:
        ray.shutdown()
print(f"load average {os.getloadavg()[0]:.1f} at the end")
