"""What the tests of bad input share: a quick training command line, a small config, the
command line's one-line error, the processes a command leaves behind, and a FIFO that cannot hang
a test, and a Unix socket."""
import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from oapo_lite import __main__ as cli

QUICK = ["--n-envs", "8", "--rollout-len", "25", "--steps", "400", "--eval-episodes", "4", "--no-progress"]


SMALL = dict(env="black_red", n_envs=8, rollout_len=25, steps=400, eval_every=1, eval_episodes=4)


def quick_but(argv) -> list[str]:
    """QUICK less the flags ``argv`` gives (a flag given twice is an error) and, for SEAC / SePS,
    less --rollout-len (their rollout is n_step long)."""
    drop = {a for a in argv if a.startswith("--")} | ({"--rollout-len"} if {"seac", "seps"} & set(argv) else set())
    out, skip = [], False
    for a in QUICK:
        if skip:
            skip = False
        elif a in drop:
            skip = a != "--no-progress"
        else:
            out.append(a)
    return out


def cli_error(capsys, *argv) -> str:
    """Run the CLI, expect exit status 2 and one line on stderr, no traceback; return the line."""
    try:
        code = cli.main(list(argv))
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


def children(pid: int) -> dict[int, int]:
    """Every live process under ``pid`` (children, grandchildren, ...) and its parent, from /proc."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended while we looked
            continue
        if fields[0] != "Z":
            parents[int(stat.parent.name)] = int(fields[1])
    found, frontier = {}, [pid]
    while frontier:
        parent = frontier.pop()
        for child, its_parent in parents.items():
            if its_parent == parent and child not in found:
                found[child] = parent
                frontier.append(child)
    return found


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def outliving(pids, sent: float) -> list[int]:
    """The processes of ``pids`` still alive ``STOP_LIMIT_S`` after the signal was sent."""
    while time.time() < sent + STOP_LIMIT_S and [pid for pid in pids if alive(pid)]:
        time.sleep(0.1)
    return [pid for pid in pids if alive(pid)]


def kill(*pids: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


# Runs of 1M MuJoCo steps (App. A at the cpu budget, minutes each): a driver that waited for its
# runs, or let a queued one start, would be caught. A healthy stop kills the workers at once; the
# limits below leave a slow, loaded machine ten times what that needs.
STOP_LIMIT_S = 15


def not_zombie(pid: int) -> bool:
    try:
        return open(f"/proc/{pid}/stat").read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def sleep_with_a_child(seconds: float) -> None:
    """A job that runs ``seconds`` in a child process it starts, as a notebook runs in its kernel."""
    subprocess.run([sys.executable, "-c", f"import time; time.sleep({seconds})"], check=True)


def sleeping_driver(out: Path) -> None:
    from oapo_lite.study.runs.executors import in_processes

    jobs = [(k, (60.0,)) for k in range(5)]
    for _ in in_processes(sleep_with_a_child, jobs, workers=2):
        out.write_text("a job finished")


@contextlib.contextmanager
def fifo(path: Path, after: float = 20.0):
    """A FIFO at ``path`` for the block; a reader that opens it anyway is let go after ``after``
    seconds (a thread opens the other end and closes it: the reader sees an empty file), so that
    a regression fails its test instead of hanging the suite."""
    os.mkfifo(path)
    done = threading.Event()

    def release():
        done.wait(after)
        while not done.is_set():
            try:
                os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))  # ENXIO: no reader has it open
            except OSError:
                pass
            done.wait(0.5)

    thread = threading.Thread(target=release, daemon=True)
    thread.start()
    try:
        yield path
    finally:
        done.set()
        thread.join()


@contextlib.contextmanager
def unix_socket(path: Path):
    """A Unix socket at ``path`` for the block: bound at a short path (a socket's address is at
    most 108 bytes) and moved there."""
    with tempfile.TemporaryDirectory(dir="/tmp") as short, socket.socket(socket.AF_UNIX) as sock:
        sock.bind(f"{short}/s")
        os.replace(f"{short}/s", path)
        yield path


# how the package names each kind of path that is no regular file (``store.NotAFile``)
NOT_A_FILE = {"FIFO": "a FIFO (named pipe)", "socket": "a socket", "folder": "a folder", "device": "a character device",
              "link to a device": "a character device"}


@contextlib.contextmanager
def not_a_file(path: Path, kind: str):
    """For the block, ``path`` made into a ``kind`` of ``NOT_A_FILE`` (a device: /dev/zero itself,
    which is yielded in place of ``path``)."""
    if kind == "FIFO":
        with fifo(path):
            yield path
        return
    if kind == "socket":
        with unix_socket(path):
            yield path
        return
    if kind == "folder":
        path.mkdir()
    elif kind == "link to a device":
        path.symlink_to("/dev/zero")
    yield Path("/dev/zero") if kind == "device" else path

