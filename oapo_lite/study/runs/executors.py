"""Where the runs of a grid are trained: this machine's processes ("local") or a Ray cluster ("ray").

An executor takes (run, checkpoint folder) jobs and yields ``(run, rows, error, trained)`` as
runs finish, in any order: the evaluation rows and None, or None and a traceback; ``trained``
says whether the job trained any iteration (``train_job``). Both train a run
with the same function, ``train_job``; the driver (``experiments.run_all``) writes the results,
so an executor never touches the run cache.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import re
import signal
import socket
import sys
import tempfile
import threading
import time
import traceback
import warnings
from multiprocessing.connection import wait
from pathlib import Path

from oapo_lite.cli import KNOWN, resource_error
from oapo_lite.neural.runstate import git_revision
from oapo_lite.neural.train import train
from oapo_lite.store import DamagedFile

PACKAGE = Path(__file__).resolve().parents[2]


def train_job(cfg, checkpoints: str):
    """Train one run; (rows, None, trained), or (None, why, False) when it raises. ``trained`` is
    False where another process wrote the run's checkpoint while this job waited for its lock and
    left nothing to train (two ``reproduce`` on one cache: the first trains). A failed run is reported by
    the driver while the others go on, with one line where the error says what to do
    (``cli.KNOWN``: a bad value, a file in the way), else its traceback (a bug). A damaged
    checkpoint is named and the run trained again from the start (the cache's runs are
    deterministic). Memory, disk or permissions running out is (None, ``RESOURCE`` + one line):
    the driver then stops."""
    iterations, checkpoint = [], Path(checkpoints) / "checkpoint.pt"
    before = _written(checkpoint)
    try:
        try:
            rows = train(cfg, checkpoints, progress=False, callback=iterations.append)
        except DamagedFile as err:
            print(f"warning: {err}; training the run again from the start", file=sys.stderr, flush=True)
            rows = train(cfg, checkpoints, resume=False, progress=False, callback=iterations.append)
    except Exception as err:
        resource = resource_error(err)  # the machine's, not the run's: the driver stops every run
        if resource:
            return None, RESOURCE + resource, False
        why = f"error: {' '.join(str(err).split())}" if isinstance(err, KNOWN) else traceback.format_exc()
        return None, why, False
    return rows, None, bool(iterations) or _written(checkpoint) == before


def _written(path: Path) -> int | None:
    """When ``path`` was last written (None: absent)."""
    try:
        return os.stat(path).st_mtime_ns
    except OSError:
        return None


RESOURCE = "resource: "  # how a job's error says that memory, disk or permissions ran out


def local(jobs, workers: int = 2, address: str | None = None):
    """``workers`` processes of this machine (1: in this process)."""
    if address is not None:
        raise ValueError(f"address {address!r} is for the ray executor; the local executor takes none")
    if workers <= 1 or len(jobs) <= 1:
        for run, checkpoints in jobs:
            yield (run, *train_job(run.cfg, checkpoints))
        return
    for run, outcome, died in in_processes(train_job, [(run, (run.cfg, ck)) for run, ck in jobs], workers):
        yield (run, *outcome) if died is None else (run, None, died, False)


def in_processes(fn, jobs, workers: int):
    """``fn(*args)`` for every ``(key, args)`` of ``jobs``, in up to ``workers`` spawned processes
    that take one job at a time; yields ``(key, value, died)`` as jobs finish: the value and None,
    or None and why the worker process died (killed, out of memory). What ``fn`` raises is raised
    here.

    The queue stays in this process and a worker is sent a job only when it is idle, so a job
    that has not started never starts once the caller stops. However the caller stops (Ctrl-C,
    SIGTERM made one, a raise, the generator closed), every worker and its children (a notebook's
    kernel, an engine's processes) are killed at once: a run resumes from its last checkpoint,
    so there is nothing to wait for.
    """
    # spawned, not forked: a parent that has imported JAX (SMAX) or started torch's threads
    # cannot fork safely (JAX warns of deadlocks; a forked pool hung the test suite)
    context = mp.get_context("spawn")
    queue, busy, idle = list(jobs)[::-1], {}, []  # busy: connection -> (process, key)
    try:
        while queue or busy:
            while queue and len(busy) < workers:
                process, conn = idle.pop() if idle else _start_worker(context)
                key, args = queue.pop()
                conn.send((fn, args))
                busy[conn] = process, key
            for conn in wait(list(busy)):
                process, key = busy.pop(conn)
                try:
                    value, error = conn.recv()
                except (EOFError, OSError):  # the worker died mid-job
                    process.join(timeout=5)
                    yield key, None, f"its worker process died (exit code {process.exitcode})"
                    continue
                if error is not None:
                    raise error
                idle.append((process, conn))
                yield key, value, None
    finally:
        kill_workers([p for p, _ in busy.values()] + [p for p, _ in idle])


def _start_worker(context):
    """A worker process and this end of its pipe. The worker is born with Ctrl-C blocked (a
    blocked signal stays blocked across the spawn), so that Ctrl-C at a terminal cannot break it
    while it imports, before it leaves the terminal's process group; a Ctrl-C meanwhile reaches
    this process once the block is lifted."""
    ours, theirs = context.Pipe()
    process = context.Process(target=_serve, args=(theirs, os.getpid()), name="oapo-worker")
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        process.start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    theirs.close()  # only the worker holds its end: its death is then an end of file here
    return process, ours


def _serve(conn, parent: int) -> None:
    """A worker: run the jobs ``conn`` sends, send back ``(value, None)`` or ``(None, error)``.

    It takes its own process group, so that Ctrl-C at a terminal reaches only the driver (a worker
    that took it could start its next job before the driver stops it) and the driver can kill the
    worker with everything it started; and it dies with the driver."""
    os.setpgid(0, 0)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked since its birth (``_start_worker``)
    die_with_parent(parent)
    from tqdm import tqdm

    # tqdm's default lock is a named semaphore; a killed worker would leave it to the driver's
    # resource tracker, which warns of it. A worker's bars never cross processes.
    tqdm.set_lock(threading.RLock())
    while True:
        try:
            fn, args = conn.recv()
        except EOFError:  # the driver is gone
            return
        try:
            reply = fn(*args), None
        except Exception as err:
            try:
                pickle.dumps(err)
            except Exception:  # not every exception survives the trip back
                err = RuntimeError(traceback.format_exc())
            reply = None, err
        conn.send(reply)


def kill_workers(processes) -> None:
    """Kill worker processes and their process groups now. A second Ctrl-C or SIGTERM waits until
    this is done, then interrupts as usual: it never leaves a worker behind."""
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        for process in processes:
            for kill in (os.killpg, os.kill):  # the group; the worker alone if it has none yet
                try:
                    kill(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        for process in processes:
            process.join()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def die_with_parent(parent: int) -> None:
    """End this worker, with its process group, once its parent is gone. A driver killed with
    SIGKILL cannot stop its workers, which would otherwise finish their runs (minutes, ~400 MB
    each) for nobody."""
    def watch():
        while os.getppid() == parent:
            time.sleep(0.5)
        os.killpg(0, signal.SIGKILL)

    threading.Thread(target=watch, daemon=True, name="die-with-parent").start()


def check_address(address: str | None) -> None:
    """A Ray address: auto, HOST:PORT or ray://HOST:PORT, with a port in 1..65535 and, for a
    numeric host, four numbers in 0..255 (Ray retries an impossible address for minutes)."""
    if address is None or address == "auto":
        return
    match = re.fullmatch(r"(?:ray://)?([\w.\-]+):(\d+)", address)
    numeric = match and re.fullmatch(r"[\d.]+", match.group(1))
    if match and 1 <= int(match.group(2)) <= 65535 and (not numeric or (
            len(parts := match.group(1).split(".")) == 4 and all(p and int(p) <= 255 for p in parts))):
        return
    raise ValueError(f"Ray address {address!r} is invalid; allowed: auto, HOST:PORT or ray://HOST:PORT (port 1-65535, "
                     "a numeric host as four numbers 0-255)")


CONNECT_S = 10  # how long a driver waits for a cluster's head to answer before it says so


def reach(address: str, deadline: float = CONNECT_S) -> None:
    """Refuse a cluster address whose head does not answer within ``deadline`` seconds, naming
    the address, the wait and the cause (no such host, refused, no answer): Ray itself retries an
    address that nothing answers at for many minutes (seen: 580 s and counting)."""
    host, port = address.removeprefix("ray://").rsplit(":", 1)
    start = time.monotonic()
    try:
        socket.create_connection((host, int(port)), timeout=deadline).close()
    except socket.gaierror as err:
        raise ConnectionError(f"Ray address {address!r}: no such host {host!r} ({err.strerror}); check the address "
                              "(--address)") from None
    except TimeoutError:
        raise ConnectionError(f"no Ray cluster answered at {address!r} within {deadline:g} s; start one there "
                              "(ray start --head) or check the address (--address)") from None
    except OSError as err:
        raise ConnectionError(f"no Ray cluster at {address!r}: {str(err.strerror or err).lower()} (a connection waits "
                              f"at most {deadline:g} s); start one there (ray start --head) or check the address "
                              "(--address)") from None
    # A port can take the connection and then say nothing (a proxy, another kind of server): a Ray
    # head (its GCS, or its client server for ray://) answers gRPC's handshake, and Ray's client
    # would retry the silence for 30 s and then name no address
    import grpc

    channel = grpc.insecure_channel(f"{host}:{port}")
    try:
        grpc.channel_ready_future(channel).result(timeout=max(0.1, deadline - (time.monotonic() - start)))
    except grpc.FutureTimeoutError:
        raise ConnectionError(f"no Ray cluster answered at {address!r} within {deadline:g} s: the port takes connections "
                              "but gives no gRPC handshake; start one there (ray start --head) or check the address "
                              "(--address)") from None
    finally:
        channel.close()


def connect(address: str | None, attempts: int = 3, **init_kwargs):
    """The ``ray`` module, connected to the cluster at ``address`` ("auto": the one running on
    this machine), or to a new one on this machine when None; and whether we connected (and so
    must disconnect; a new cluster stops with its driver). ``init_kwargs`` go to ``ray.init``
    (runtime_env, and for a new cluster e.g. num_cpus). A driver already connected is used as
    it is: its runtime env must then provide the package."""
    check_address(address)
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    host = None if address in (None, "auto") else address.removeprefix("ray://").rsplit(":", 1)[0]
    if host in (None, "localhost") or host.startswith("127."):
        # A cluster on this machine listens on loopback: without this Ray "resolves" 127.0.0.1
        # to the machine's outward address, where nothing answers. Read when ray is imported.
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    token = os.environ.get("RAY_AUTH_TOKEN") or (Path.home() / ".ray" / "auth_token").exists()
    if address is not None and token:
        # a cluster started by ray.init checks a token by default (Ray 2.60), but a driver
        # that connects only sends one in token mode. Read when ray is imported.
        os.environ.setdefault("RAY_AUTH_MODE", "token")
    try:
        import ray
    except ImportError:
        raise ImportError("the ray executor needs Ray: pip install ray==2.60.0 (pinned in environment.txt)") from None
    if ray.is_initialized():
        return ray, False
    if address is not None:
        if address != "auto":
            reach(address)
        # a head that answers but is no Ray GCS: Ray's own connect loop, bounded by the same wait (for
        # this connection only: a private cluster's start reads the variable too)
        given = os.environ.get("RAY_gcs_server_port_wait_time_s")
        os.environ["RAY_gcs_server_port_wait_time_s"] = given or str(CONNECT_S)
        start = time.monotonic()
        try:
            with warnings.catch_warnings():  # the client's timeout warning: the error below says it in one line
                warnings.simplefilter("ignore", UserWarning)
                ray.init(address=address, **init_kwargs)
        except ConnectionError as err:  # Ray's own words name no address ("ray client connection timeout")
            raise ConnectionError(f"no Ray cluster answered at {address!r}: {err} after {time.monotonic() - start:.0f} s "
                                  "(the port answers, but not as a Ray head); check the address (--address)") from None
        finally:
            if given is None:
                del os.environ["RAY_gcs_server_port_wait_time_s"]
        return ray, True
    # A private cluster listens on loopback only (Ray binds its servers to the node's address) and
    # without a dashboard, so no other machine can reach it; ``init_kwargs`` may ask otherwise
    private = {"include_dashboard": False, "_node_ip_address": "127.0.0.1", **init_kwargs}
    for attempt in range(1, attempts + 1):
        try:
            ray.init(**private)
            return ray, True
        except Exception as err:
            # Ray 2.60's raylet gives its Python agent a fixed 15 s to start and aborts after;
            # on a busy machine the agent can take longer (seen here at a load of 11 on 2 cores)
            if "timed out during startup" not in str(err) or attempt == attempts:
                raise
            print(f"Ray did not start ({err}); attempt {attempt + 1} of {attempts}", file=sys.stderr)


def _ray_job(cfg, checkpoints: str):
    """``train_job`` on a Ray worker. A worker that does not share the driver's file system
    (the driver made the checkpoint folder's parent) keeps checkpoints in its own temp folder:
    a retried run then resumes on the same node, otherwise it restarts."""
    if not Path(checkpoints).parent.is_dir():
        checkpoints = str(Path(tempfile.gettempdir()) / "oapo_checkpoints" / Path(checkpoints).name)
    return train_job(cfg, checkpoints)


def runtime_env() -> dict:
    """What a Ray worker gets: this copy of the package and this checkout's git revision."""
    return {"py_modules": [str(PACKAGE)], "env_vars": {"OAPO_GIT_REV": git_revision(), "RAY_USAGE_STATS_ENABLED": "0"}}


def on_ray(jobs, workers: int | None = None, address: str | None = None):
    """One Ray task per run, asking for the run's CPUs, GPUs and memory. Workers run the
    driver's copy of the package (shipped as the job's ``py_modules`` runtime env) and record
    the driver's git revision; ``workers`` is not used (the cluster's resources decide)."""
    if not jobs:
        return
    ray, connected = connect(address, runtime_env=runtime_env())
    try:
        task = ray.remote(_ray_job)
        pending = {}
        for run, checkpoints in jobs:
            need = dict(num_cpus=run.cpus, num_gpus=run.gpus)
            if run.memory_gb:
                need["memory"] = int(run.memory_gb * 2**30)
            pending[task.options(**need).remote(run.cfg, checkpoints)] = run
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            run = pending.pop(ref)
            try:
                rows, error, trained = ray.get(ref)
            except ray.exceptions.RayError as err:  # the task never returned: worker or node lost
                rows, error, trained = None, f"{type(err).__name__}: {err}", False
            yield run, rows, error, trained
    finally:
        if connected:
            ray.shutdown()


EXECUTORS = {"local": local, "ray": on_ray}
