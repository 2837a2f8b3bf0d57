"""The grid on a real Ray cluster: started here on 127.0.0.1 with two CPUs, stopped at the end
with no Ray process left behind. Through Ray the smoke grid gives byte-identical run files to
the local executor; a driver killed mid-grid loses nothing and a rerun completes the grid; a
run that raises is reported while the others complete."""
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from oapo_lite.neural.results import learning
from oapo_lite.study.catalogue import figures
from oapo_lite.study.runs import experiments
from oapo_lite.study.catalogue.grid import Figure

# The head node lives in its own process (so that other drivers, including a killed one, come
# and go); it stops when the test closes its stdin.
HEAD = """
import sys
from oapo_lite.study.runs.executors import connect
ray, _ = connect(None, num_cpus=2, _temp_dir=sys.argv[1], object_store_memory=100 * 2**20)
print(ray.get_runtime_context().gcs_address, flush=True)
sys.stdin.read()
ray.shutdown()
"""
ENV = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}


def processes_of(marker: str) -> list[int]:
    """Processes whose command line names ``marker`` (the cluster's own temp folder)."""
    pids = []
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            if marker.encode() in (proc / "cmdline").read_bytes() and int(proc.name) != os.getpid():
                pids.append(int(proc.name))
        except OSError:  # it ended meanwhile
            pass
    return pids


@pytest.fixture(scope="module")
def cluster():
    temp = tempfile.mkdtemp(prefix="oapo-ray-")
    head = subprocess.Popen([sys.executable, "-c", HEAD, temp], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, env=ENV, start_new_session=True)
    address = head.stdout.readline().strip()
    try:
        assert address.startswith("127.0.0.1:"), f"the Ray head did not start (exit code {head.wait()})"
        yield address
    finally:
        head.stdin.close()
        head.wait(timeout=180)
        time.sleep(2)  # workers exit on their own once the raylet is gone
        leftovers = processes_of(temp)
        for pid in leftovers:
            os.kill(pid, signal.SIGKILL)
        shutil.rmtree(temp, ignore_errors=True)
        assert not leftovers, f"Ray processes {leftovers} outlived the cluster"


@contextmanager
def figures_at(path: Path):
    old = os.environ.get("OAPO_FIGURES")
    os.environ["OAPO_FIGURES"] = str(path)
    try:
        yield experiments.data_dir("smoke") / "runs"
    finally:
        if old is None:
            del os.environ["OAPO_FIGURES"]
        else:
            os.environ["OAPO_FIGURES"] = old


def run_files(runs: Path) -> dict[str, str]:
    """Every run file's rows less what the run cost (which no two trainings share)."""
    return {p.name: learning(pd.read_csv(p)).to_csv(index=False) for p in sorted(runs.glob("*.csv"))}


# the maze figures: the engines' smoke runs are exercised by reproduce in CI and by their own tests
MAZES = figures.MAZE_FIGURES


@pytest.fixture(scope="module")
def local_smoke(tmp_path_factory):
    """The smoke grid trained by the local executor: the reference."""
    with figures_at(tmp_path_factory.mktemp("local")) as runs:
        count = experiments.run_all("smoke", MAZES, executor="local", workers=2, progress=False)
    assert not count.failed and count.done == len(experiments.grid_runs("smoke", MAZES))
    return run_files(runs)


def test_the_smoke_grid_through_ray_equals_the_local_executor(cluster, local_smoke, tmp_path):
    with figures_at(tmp_path) as runs:
        count = experiments.run_all("smoke", MAZES, executor="ray", address=cluster, progress=False)
        assert (count.done, count.cached, count.failed) == (len(local_smoke), 0, [])
        assert run_files(runs) == local_smoke  # same seeds: the same numbers, config and revision
        again = experiments.run_all("smoke", MAZES, executor="ray", address=cluster, progress=False)
    assert (again.done, again.cached) == (0, len(local_smoke))  # what is on disk is never redone


def test_a_driver_killed_mid_grid_loses_nothing_and_a_rerun_completes_it(cluster, local_smoke, tmp_path):
    figures = ["fig3b", "fig3c"]
    total = len(experiments.grid_runs("smoke", figures))
    cmd = [sys.executable, "-m", "oapo_lite", "reproduce", "--budget", "smoke", "--figures", *figures,
           "--skip-notebooks", "--check", "--executor", "ray", "--address", cluster]
    env = {**ENV, "OAPO_FIGURES": str(tmp_path)}
    runs = tmp_path / "smoke" / "data" / "runs"
    driver = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    deadline = time.monotonic() + 600
    while not list(runs.glob("*.csv")) and driver.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    os.killpg(driver.pid, signal.SIGKILL)
    driver.wait()
    before = run_files(runs)
    assert 1 <= len(before) < total, f"kill the driver mid-grid, not at {len(before)} of {total} runs"
    assert all(local_smoke[name] == data for name, data in before.items())  # nothing half-written

    rerun = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert rerun.returncode == 0, rerun.stderr[-3000:]
    assert f"{total - len(before)} trained, {len(before)} already on disk, 0 failed" in rerun.stdout
    after = run_files(runs)
    assert after == {name: local_smoke[name] for name in after} and len(after) == total


def test_a_private_cluster_listens_on_loopback_only_and_has_no_dashboard(cluster):
    """Every socket the cluster's processes listen on (GCS, raylet, object manager, workers,
    agents, the head's driver) is bound to 127.0.0.1, so no other machine can reach it, and
    nothing serves the dashboard (Ray's port 8265)."""
    import psutil  # Ray's own dependency

    bound = []
    for pid in processes_of("oapo-ray-"):
        try:
            sockets = psutil.Process(pid).net_connections("inet")
        except psutil.NoSuchProcess:  # it ended meanwhile
            continue
        bound += [(c.laddr.ip.removeprefix("::ffff:"), c.laddr.port) for c in sockets if c.status == psutil.CONN_LISTEN]
    assert ("127.0.0.1", int(cluster.rsplit(":", 1)[1])) in bound  # the GCS's: these are the cluster's sockets
    assert {ip for ip, _ in bound} == {"127.0.0.1"} and 8265 not in {port for _, port in bound}


@pytest.mark.parametrize("executor", ["local", "ray"])
def test_a_run_that_raises_is_reported_and_the_others_complete(executor, request, tmp_path, capsys):
    address = request.getfixturevalue("cluster") if executor == "ray" else None
    # a 3 x 3 reuse mask passes the config's checks but not the 2-agent maze: train() raises
    broken = Figure("broken", (("bad", dict(algo="oappo", allowed=np.ones((3, 3), bool))),
                               ("good", dict(algo="happo"))), common=dict(env="black_red"))
    with figures_at(tmp_path) as runs:
        count = experiments.run_all("smoke", figures=(broken,), executor=executor, address=address,
                                    progress=False)
        paths = {r.label: experiments.run_path(r.cfg, "smoke") for r in figures.runs_of(broken, "smoke")}
        assert list(runs.glob("*.csv")) == [paths["good"]]
    assert count.done == 1 and [f.run.label for f in count.failed] == ["bad"]
    error = count.failed[0].error
    # a value error says what to do in one line: no traceback (a bug's would show one)
    assert error.startswith("error: ") and "allowed mask has shape (3, 3), expected (2, 2)" in error
    assert "Traceback" not in error
    reported = capsys.readouterr().err
    assert count.failed[0].run.cfg.run_id() in reported and "'allowed': '[[1, 1, 1]" in reported
    assert "allowed mask has shape (3, 3)" in reported
