"""Files that survive a kill: atomic writes, per-run locks, and a clear error for a damaged file.

A writer writes next to the target and renames, so a reader sees the old file or the whole new
one; the temporary files of writers that were killed are removed by the next write. A lock is
an ``flock`` on a file: the kernel releases it when its holder dies, however it dies.
"""
from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
import socket
import stat
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

_HOST = socket.gethostname().replace("-", "_")


class DamagedFile(ValueError):
    """A result or checkpoint file that cannot be read back; the message names it and what to do."""


class NotAFile(ValueError):
    """A path read as a file that names a folder, a FIFO, a socket or a device: refused by its
    kind, never opened (reading a FIFO waits for a writer that never comes, and a device such as
    /dev/zero never ends)."""


# what a path names besides a regular file (os.stat follows links, so a link names its target)
KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket"),
         (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def regular_file(path: Path, what: str, fix: str = "delete or move it") -> os.stat_result:
    """The status of ``path`` if it names a regular file (or a link to one), checked before anything
    opens it: ``FileNotFoundError`` if nothing is there, ``NotAFile`` naming what it is instead
    (``what`` names the file's role, ``fix`` what to do), and a path the system cannot follow
    (a loop of links, a name too long) as ``NotAFile`` naming that cause (``cause``)."""
    try:
        status = os.stat(path)
    except FileNotFoundError:
        raise
    except OSError as err:
        raise NotAFile(f"{what} {path} cannot be read: {cause(err)}; {fix}") from None
    if not stat.S_ISREG(status.st_mode):
        kind = next((name for test, name in KINDS if test(status.st_mode)), "not a regular file")
        raise NotAFile(f"{what} {path} is {kind}, not a file; {fix}")
    return status


def is_file(path: Path, what: str, fix: str = "delete or move it") -> bool:
    """Whether a regular file is at ``path`` (False: nothing there); ``regular_file``'s errors otherwise."""
    try:
        regular_file(path, what, fix)
    except FileNotFoundError:
        return False
    return True


# the causes the system gives for a path it cannot follow, in words that say what to change
CAUSES = {
    errno.ENOENT: "no such file or folder",
    errno.ELOOP: "it runs through a loop of symbolic links (a link that points, at last, back to itself)",
    errno.ENAMETOOLONG: "a name in it is longer than the file system allows (255 bytes a name, 4096 a path)",
    errno.ENOTDIR: "a part of it before the last is a file, not a folder",
    errno.EACCES: "permission denied",
    errno.EROFS: "the file system is read-only",
    errno.ENOSPC: "no space left on the device",
}


def cause(err: OSError) -> str:
    """Why the system refused a path, in words (``CAUSES``), else its own."""
    return CAUSES.get(err.errno, err.strerror or str(err))


def _tmp_name(path: Path, pid: int) -> Path:
    return path.with_name(f".{path.name}.tmp-{_HOST}-{pid}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def remove_stale_tmp(path: Path) -> None:
    """Remove the temporary files that killed writers of ``path`` on this host left behind."""
    prefix = f".{path.name}.tmp"
    for tmp in path.parent.glob(f"{prefix}*"):
        rest = tmp.name[len(prefix):]
        host, _, pid = rest.rpartition("-")
        if rest.isdigit():  # written before the host was part of the name
            host, pid = f"-{_HOST}", rest
        if host == f"-{_HOST}" and pid.isdigit() and not _alive(int(pid)):
            tmp.unlink(missing_ok=True)


def atomic_write(write: Callable[[str], None], path: Path) -> None:
    """``write(tmp)`` next to ``path``, then rename: a reader sees the old file or the whole new one."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder where a file is to be written; delete or move it")
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_tmp(path)
    tmp = _tmp_name(path, os.getpid())
    try:
        try:
            write(str(tmp))
        except RuntimeError as err:
            # torch.save reports a failed write (a full disk: "unexpected pos") as a RuntimeError
            raise OSError(_write_errno(path), f"cannot write {path}: {err}", str(path)) from err
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def cannot_write(folder: Path) -> str | None:
    """Why ``folder`` cannot be made or written to (the system's words), or None if it can: a
    command checks its output folders at the start, not after its first run."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as err:
        return cause(err)
    return None


def _write_errno(path: Path) -> int:
    """ENOSPC when the device holding ``path`` is (nearly) full, else EIO."""
    return errno.ENOSPC if shutil.disk_usage(path.parent).free < 2**20 else errno.EIO


def write_frame(df: pd.DataFrame, path: Path) -> None:
    """``df`` as CSV, written atomically; a cell that holds an array (a per-iteration matrix
    such as Eq. 9's K or M) is written as its JSON text (``read_arrays`` reads it back)."""
    def text(x):
        return json.dumps(x.tolist()) if isinstance(x, np.ndarray) else x

    arrays = [c for c in df.columns if df[c].dtype == object and df[c].map(lambda x: isinstance(x, np.ndarray)).any()]
    df = df.assign(**{c: df[c].map(text) for c in arrays})
    atomic_write(lambda p: df.to_csv(p, index=False), path)


def read_arrays(df: pd.DataFrame, columns) -> pd.DataFrame:
    """``df`` with the JSON text of ``columns`` (those it has) turned back into arrays; a cell
    that is not JSON raises ``ValueError`` naming its column and row."""
    def arrays(column: str) -> list:
        out = []
        for i, x in enumerate(df[column]):
            try:
                out.append(np.array(json.loads(x)) if isinstance(x, str) else x)
            except ValueError as err:
                raise ValueError(f"its {column} column at row {i + 1} holds {x[:40]!r}, which is not JSON ({err})") from None
        return out

    return df.assign(**{c: arrays(c) for c in columns if c in df.columns})


class Lock:
    """An exclusive lock on ``path`` (created if missing), held until ``release`` or until the
    holder dies. ``acquire(wait=False)`` returns whether it got the lock."""

    def __init__(self, path: Path):
        self.path, self._fd = Path(path), None

    def acquire(self, wait: bool = True) -> bool:
        is_file(self.path, "the lock file", "delete it (a lock holds nothing: it keeps two processes from writing one "
                                            "run at once)")
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            os.close(fd)
            return False
        self._fd = fd
        return True

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor releases the flock
            self._fd = None
