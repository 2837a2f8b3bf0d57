"""``make test``'s stages, each timed, and the times printed at the end (also after a failure).

    python tests/stages.py START    # START: when make began (seconds since the epoch), for the set-up

Stops at the first stage that fails, with its exit status.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STAGES = {
    "unit tests (default numeric path)": ["-m", "pytest", "-q", "tests"],
    "numeric unit tests (the other paths)": ["tests/numeric_paths.py", "unit"],
    "smoke reproduction": ["-m", "oapo_lite", "reproduce", "--budget", "smoke", "--check"],
    "nbval (every path)": ["tests/numeric_paths.py", "nbval"],
}


def main(start: float) -> int:
    times = {"set-up (venv, book, browser, GRF)": time.time() - start}
    status = 0
    for name, args in STAGES.items():
        tic = time.time()
        status = subprocess.run([sys.executable, *args], cwd=ROOT).returncode
        times[name] = time.time() - tic
        if status:
            times[name + ": FAILED"] = times.pop(name)
            break
    print("\nmake test, time per stage")
    for name, seconds in times.items():
        print(f"  {name:<45s} {seconds / 60:6.1f} min")
    print(f"  {'total':<45s} {(time.time() - start) / 60:6.1f} min")
    return status


if __name__ == "__main__":
    sys.exit(main(float(sys.argv[1])))
