"""What every command line of the package shares: an error is one line naming the bad value or
file and what to do, with exit status 2; a bug (any other exception) says how to see its
traceback (``--debug`` or ``OAPO_DEBUG=1``), with exit status 1. And the checks of values that
the command lines, the library and the notebooks' parameters share (``boolean``, ``names``,
``output_folder``), so that one value is refused alike wherever it enters."""
from __future__ import annotations

import argparse
import contextlib
import errno
import os
import re
import signal
import stat
import sys
from pathlib import Path

import numpy as np


class Parser(argparse.ArgumentParser):
    """argparse, but a bad argument is one line (argparse prints its whole usage first), and a
    flag must be spelled in full (an abbreviation could silently name another flag)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_args(self, args=None, namespace=None):
        """argparse's, refusing a flag given twice: argparse keeps the last value and drops the
        first without a word."""
        args = sys.argv[1:] if args is None else list(args)
        for action in self._actions:
            given = times_given(action, args)
            if given > 1:
                self.error(f"{action.option_strings[0]} is given {given} times; give it once")
        return super().parse_args(args, namespace)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def flag_help(meaning: str, default, allowed: str | None = None) -> str:
    """A flag's line of ``--help``: what it means, its default and (for a flag with a value) what
    it allows. (argparse formats help with %, so a literal % is doubled.)"""
    text = f"{meaning} (default: {default}" + (f"; allowed: {allowed})" if allowed else ")")
    return text.replace("%", "%%")


def times_given(action: argparse.Action, args: list[str]) -> int:
    """How often ``args`` give the flag of ``action`` (as ``--flag value`` or ``--flag=value``)."""
    return sum(a == opt or a.startswith(opt + "=") for opt in action.option_strings for a in args)


def boolean(value, what: str) -> bool:
    """``value`` if it is True or False (numpy's too); anything else is refused, naming ``what``:
    read as truthy, the string "no" or "false" would mean yes."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{what} must be True or False, got {value!r}")
    return bool(value)


# the most processes a command starts at once: beyond any machine's cores here, each holding a
# run (hundreds of MB); a larger count is a slip of the keyboard (10^23 was priced as workers)
MAX_WORKERS = 1024


def workers(value, what: str) -> int:
    """A count of worker processes: an integer in [1, ``MAX_WORKERS``], else refused naming ``what``."""
    if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)) or not 1 <= value <= MAX_WORKERS:
        raise ValueError(f"{what} = {value!r} is invalid; allowed: an integer in [1, {MAX_WORKERS}]")
    return int(value)


def names(value, what: str) -> tuple:
    """A sequence of names as a tuple; one name given as a string is refused, not split into letters."""
    if isinstance(value, str):
        raise TypeError(f"{what} must be a sequence of names, got the string {value!r}; write ({value!r},)")
    try:
        return tuple(value)
    except TypeError:
        raise TypeError(f"{what} must be a sequence of names, got {type(value).__name__} {value!r}") from None


def output_folder(text: str, what: str) -> Path:
    """An output folder given on the command line or in the environment (``what`` names where),
    resolved to an absolute path once, at the start of a command, so that every process and
    notebook it starts writes to the same place; an empty path (which would name the working
    folder), the filesystem root, a file and a link to a missing folder are refused, and a path
    the system cannot follow is named by its cause (no such user, a loop of links, a name too
    long: ``store.cause``)."""
    from oapo_lite.store import KINDS, cause

    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"{what} {text!r} is empty; allowed: a folder path (. for the working folder)")
    try:
        path = Path(text).expanduser()
    except RuntimeError:  # pathlib's words for a ~user that does not exist, or ~ without a HOME
        user = text[1:].split("/", 1)[0]
        raise ValueError(f"{what} {text!r} starts with ~{user}, but " + (f"there is no user {user!r}" if user else
                         "HOME is not set") + "; allowed: a folder path") from None
    try:
        status = os.stat(path)
    except FileNotFoundError:  # a new folder, or a link to one that does not exist
        status = None
        if path.is_symlink():
            raise ValueError(f"{what} {text!r} is a link to {os.readlink(path)!r}, which does not exist; allowed: a "
                             "folder or a link to one") from None
    except NotADirectoryError:  # a file on the way: named below
        status = None
    except OSError as err:
        shown = repr(text) if len(text) <= 80 else f"{text[:40]!r}... ({len(text)} characters)"
        raise ValueError(f"{what} {shown} cannot be used: {cause(err)}; allowed: a folder path") from None
    path = path.resolve()
    if path == path.parent:
        raise ValueError(f"{what} {text!r} is the filesystem root; allowed: a folder below it")
    if status is not None and not stat.S_ISDIR(status.st_mode):
        kind = next((name for test, name in KINDS if test(status.st_mode)), "a file")
        raise ValueError(f"{what} {text!r} is {kind}; allowed: a folder")
    above = next(p for p in path.parents if p.exists())
    if not above.is_dir():
        raise ValueError(f"{what} {text!r} lies below {str(above)!r}, which is a file; allowed: a folder")
    return path


def writable_folder(text: str, what: str) -> Path:
    """``output_folder``, made and checked writable now (``store.cannot_write``): a command, or
    ``train``, refuses it at its start rather than where it first writes."""
    from oapo_lite.store import cannot_write

    path = output_folder(text, what)
    why = cannot_write(path)
    if why:
        raise ValueError(f"{what} {text!r} cannot be written ({why}); choose another folder")
    return path


def interrupt(signum, frame):
    """The handler of Ctrl-C and SIGTERM in every command: the first stops the work (a
    KeyboardInterrupt, which the command turns into one line and exit status 130); later ones
    are ignored, so that none can break the stop itself (workers are killed at once, so a stop
    never waits)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    raise KeyboardInterrupt


@contextlib.contextmanager
def uninterrupted():
    """Ctrl-C and SIGTERM held back while the block runs, and delivered after it: torch's import
    runs C++ that calls Python, and a KeyboardInterrupt raised there aborts the process."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def debug_requested(argv: list[str]) -> bool:
    return "--debug" in argv or os.environ.get("OAPO_DEBUG", "") not in ("", "0")


# what ran out, and what to do, for the errors of the machine rather than of the request
OUT_OF_MEMORY = re.compile(r"can't allocate memory|not enough memory|out of memory|unable to allocate", re.I)
RESOURCES = {
    errno.ENOSPC: "no space left on the device{where}; free some space or write elsewhere (--out, OAPO_FIGURES)",
    errno.EDQUOT: "disk quota exceeded{where}; free some space or write elsewhere (--out, OAPO_FIGURES)",
    errno.EACCES: "permission denied{where}; fix its permissions, or write elsewhere (--out, OAPO_FIGURES)",
    errno.EPERM: "operation not permitted{where}; fix its permissions, or write elsewhere (--out, OAPO_FIGURES)",
    errno.EROFS: "read-only file system{where}; write elsewhere (--out, OAPO_FIGURES)",
}


# bad values, damaged or unwritable files, a missing engine, a run that diverged (the neural
# track's Diverged is the only FloatingPointError here: numpy's error state is never "raise"):
# the message says what and what to do; anything else is a bug
KNOWN = (ValueError, OSError, ImportError, FloatingPointError)


def resource_error(err: BaseException) -> str | None:
    """One line naming what ran out and what to do, or None if ``err`` is not such an error."""
    if isinstance(err, MemoryError) or (isinstance(err, RuntimeError) and OUT_OF_MEMORY.search(str(err))):
        detail = " ".join(str(err).split())[:200]
        return (f"out of memory ({detail or 'MemoryError'}); lower the sizes that scale it (--n-envs, "
                "--eval-episodes, --hidden, --workers) or free memory")
    if isinstance(err, OSError) and err.errno in RESOURCES:
        return RESOURCES[err.errno].format(where=f": {err.filename}" if err.filename else "")
    return None


def report(err: Exception) -> int:
    """Print ``err`` as one line on stderr; the exit status."""
    resource = resource_error(err)
    if resource:
        print(f"error: {resource}", file=sys.stderr)
        return 2
    known = isinstance(err, KNOWN)
    text = " ".join(str(err).split()) or type(err).__name__
    print(f"error: {text}" if known else f"error: {type(err).__name__}: {text} (a bug in oapo_lite? rerun with "
          "--debug for the traceback)", file=sys.stderr)
    return 2 if known else 1
