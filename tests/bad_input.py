"""What the tests of bad input share: a quick training command line, a small config, the
command line's one-line error, and the processes a command leaves behind."""
import os
import signal
import subprocess
import sys
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
