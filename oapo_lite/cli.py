"""What every command line of the package shares: an error is one line naming the bad value or
file and what to do, with exit status 2; a bug (any other exception) says how to see its
traceback (``--debug`` or ``OAPO_DEBUG=1``), with exit status 1."""
from __future__ import annotations

import argparse
import os
import sys


class Parser(argparse.ArgumentParser):
    """argparse, but a bad argument is one line (argparse prints its whole usage first)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def debug_requested(argv: list[str]) -> bool:
    return "--debug" in argv or os.environ.get("OAPO_DEBUG", "") not in ("", "0")


def report(err: Exception) -> int:
    """Print ``err`` as one line on stderr; the exit status."""
    from oapo_lite.losses import Diverged

    # bad values, damaged or unwritable files, a missing engine, a run that diverged: the message
    # says what and what to do; anything else is a bug
    known = isinstance(err, (ValueError, OSError, ImportError, Diverged))
    text = " ".join(str(err).split()) or type(err).__name__
    print(f"error: {text}" if known else f"error: {type(err).__name__}: {text} (a bug in oapo_lite? rerun with "
          "--debug for the traceback)", file=sys.stderr)
    return 2 if known else 1
