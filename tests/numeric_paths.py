"""The numeric paths ``make test`` runs under, and what moved on each.

Another CPU runs other floating-point kernels: MKL picks its code path by CPU family (AVX-512 on
an Intel Xeon, AVX2 on this AMD EPYC and on most laptops), ATen its vectorised kernels by the
instruction sets it finds, numpy its SIMD loops likewise. The last digits of float32 work move
with them. Each path below picks other kernels on this very machine, in more than one layer at
once, as another CPU would:

- ``default``: what this machine picks;
- ``avx2``: an AVX2-only machine (MKL's AVX2 kernels, ATen's AVX2 kernels, numpy's SIMD loops up
  to AVX2);
- ``scalar``: ATen's scalar kernels, MKL's compatible (SSE2) code path, numpy's baseline loops.

Notebook outputs that nbval compares must not move on any of them (ASSUMPTIONS.md, "Across
machines"); the unit tests whose outcome can depend on the kernels (marked ``numeric`` by
``tests/conftest.py``) must pass on each; the others run once, on the default path.

    python tests/numeric_paths.py unit [PATH ...]    # the numeric unit tests (every path but the default)
    python tests/numeric_paths.py nbval [PATH ...]   # nbval of every notebook (every path), a report

``nbval`` prints, per notebook, how many cells nbval compares and how many of them moved under
each path. Either exits 1 if a run under any path failed.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parent.parent
NBVAL = ["-m", "pytest", "-q", "-p", "no:cacheprovider", "--nbval", "--nbval-current-env",
         "--nbval-sanitize-with", "notebooks/sanitize.cfg"]
IGNORED = ("NBVAL_IGNORE_OUTPUT", "NBVAL_SKIP")  # as comments in a cell, or as tags in lower case


def numpy_targets(keep) -> str:
    """numpy's SIMD targets that ``keep`` rejects, spelled for ``NPY_DISABLE_CPU_FEATURES``: from
    the targets it was built with, not those it runs now (a process on a path has turned some
    off), and numpy accepts a target this CPU lacks."""
    from numpy._core._multiarray_umath import __cpu_dispatch__
    return " ".join(t for t in __cpu_dispatch__ if not keep(t))


def paths() -> dict[str, dict[str, str]]:
    """Every path's environment variables (the default sets none)."""
    above_avx2 = lambda target: target.startswith(("AVX512", "X86_V4"))
    return {
        "default": {},
        "avx2": {"MKL_ENABLE_INSTRUCTIONS": "AVX2", "ATEN_CPU_CAPABILITY": "avx2",
                 "NPY_DISABLE_CPU_FEATURES": numpy_targets(lambda t: not above_avx2(t))},
        "scalar": {"ATEN_CPU_CAPABILITY": "default", "MKL_CBWR": "COMPATIBLE",
                   "NPY_DISABLE_CPU_FEATURES": numpy_targets(lambda t: False)},
    }


def environment(path: str) -> dict[str, str]:
    """This process's environment with ``path``'s variables, and none of another path's."""
    # numpy refuses to start with both NPY_ENABLE_CPU_FEATURES and NPY_DISABLE_CPU_FEATURES set
    every = {name for extra in paths().values() for name in extra} | {"NPY_ENABLE_CPU_FEATURES"}
    return {**{k: v for k, v in os.environ.items() if k not in every}, **paths()[path]}


def compared_cells(notebook: Path) -> int:
    """The code cells of ``notebook`` whose committed outputs nbval compares."""
    cells = nbformat.read(notebook, as_version=4).cells
    tags = lambda c: set(c.metadata.get("tags", ()))
    return sum(c.cell_type == "code" and bool(c.outputs) and not any(
        marker in c.source or marker.lower().replace("_", "-") in tags(c) for marker in IGNORED) for c in cells)


def moved_cells(junit: Path) -> Counter:
    """Failed nbval items per notebook file name, from pytest's JUnit report."""
    moved = Counter()
    for case in ET.parse(junit).iter("testcase"):
        if case.find("failure") is not None or case.find("error") is not None:
            moved[case.get("classname", "").split(".", 1)[-1]] += 1  # "notebooks.<file name>"
    return moved


def run_unit(names: list[str]) -> int:
    failed = False
    for name in names:
        print(f"unit tests, numeric path {name}: {paths()[name] or 'as this machine picks'}", flush=True)
        failed |= subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "numeric",
                                  "tests"], cwd=ROOT, env=environment(name)).returncode != 0
    return int(failed)


def run_nbval(names: list[str]) -> int:
    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    moved, failed = {}, False
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            print(f"nbval, numeric path {name}: {paths()[name] or 'as this machine picks'}", flush=True)
            junit = Path(tmp) / f"{name}.xml"
            failed |= subprocess.run([sys.executable, *NBVAL, f"--junitxml={junit}", "notebooks"], cwd=ROOT,
                                     env=environment(name)).returncode != 0
            moved[name] = moved_cells(junit) if junit.exists() else None
    width = max(len(nb.stem) for nb in notebooks)
    print(f"\ncompared notebook cells that moved, per numeric path\n{'notebook':<{width}}  compared  "
          + "  ".join(f"{n:>7}" for n in names))
    for nb in notebooks:
        counts = ("    n/a" if moved[n] is None else f"{moved[n][nb.name]:>7}" for n in names)
        print(f"{nb.stem:<{width}}  {compared_cells(nb):>8}  " + "  ".join(counts))
    return int(failed)


def main(argv: list[str]) -> int:
    known = list(paths())
    if not argv or argv[0] not in ("unit", "nbval") or any(n not in known for n in argv[1:]):
        print(f"usage: numeric_paths.py unit|nbval [PATH ...], PATH one of {known}", file=sys.stderr)
        return 2
    if argv[0] == "unit":
        return run_unit(argv[1:] or known[1:])
    return run_nbval(argv[1:] or known)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
