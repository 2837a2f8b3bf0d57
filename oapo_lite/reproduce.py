"""The main job: run every experiment of a budget, then execute every notebook with papermill.

Experiment runs are cached on disk (see ``experiments``), so an interrupted reproduction
resumes where it stopped; notebooks then only read results and draw figures.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"


def notebook_paths() -> list[Path]:
    return sorted(NOTEBOOKS.glob("[0-9]*.ipynb"))


def takes_budget(path: Path) -> bool:
    """A notebook takes a budget when its cell tagged ``parameters`` defines one."""
    import nbformat

    nb = nbformat.read(path, as_version=4)
    return any(
        "parameters" in c.metadata.get("tags", []) and "budget" in c.source for c in nb.cells
    )


def run_notebooks(budget: str, inplace: bool) -> list[tuple[str, float]]:
    """Execute every numbered notebook; ``inplace`` overwrites the committed copies."""
    import papermill as pm

    out_dir = NOTEBOOKS if inplace else ROOT / "build" / "notebooks" / budget
    out_dir.mkdir(parents=True, exist_ok=True)
    timings, paths = [], notebook_paths()
    for i, path in enumerate(paths, 1):
        print(f"[{i}/{len(paths)}] {path.name} (budget={budget})", flush=True)
        params = {"budget": budget} if takes_budget(path) else {}
        start = time.perf_counter()
        pm.execute_notebook(
            str(path), str(out_dir / path.name), parameters=params, kernel_name="python3", language="python",
            cwd=str(NOTEBOOKS), progress_bar=False,
        )
        timings.append((path.name, time.perf_counter() - start))
    return timings


def main(argv: list[str] | None = None) -> int:
    from oapo_lite import experiments

    parser = argparse.ArgumentParser(prog="python -m oapo_lite reproduce", description=__doc__)
    parser.add_argument("--budget", default="smoke",
                        help=f"one of {sorted(set(experiments.BUDGETS) | set(experiments.SMAX_BUDGETS))}")
    parser.add_argument("--inplace", action="store_true",
                        help="write executed notebooks over notebooks/*.ipynb (to commit them)")
    parser.add_argument("--check", action="store_true",
                        help="CI mode: no progress bars")
    parser.add_argument("--workers", type=int, default=2, help="parallel training processes")
    args = parser.parse_args(argv)
    if not experiments.figures_for(args.budget):  # fail fast on a bad name
        experiments.get_budget(args.budget)

    start = time.perf_counter()
    runs = experiments.run_all(args.budget, figures=experiments.figures_for(args.budget), workers=args.workers,
                               progress=not args.check)
    timings = run_notebooks(args.budget, args.inplace)
    print("\nSummary")
    print(f"  experiment runs: {runs.done} trained, {runs.cached} already on disk")
    for name, seconds in timings:
        print(f"  {name:<45s} {seconds:6.1f} s")
    print(f"  total wall time: {time.perf_counter() - start:.1f} s")
    print(f"  figures: {experiments.figures_dir(args.budget)}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
