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
    parser.add_argument("--budget", default="smoke", help=f"one of {sorted(experiments.BUDGETS)}")
    parser.add_argument("--inplace", action="store_true",
                        help="write executed notebooks over notebooks/*.ipynb (to commit them)")
    parser.add_argument("--check", action="store_true",
                        help="CI mode: no progress bars")
    parser.add_argument("--workers", type=int, default=2, help="parallel training processes (local executor)")
    parser.add_argument("--executor", default="local", choices=["local", "ray"],
                        help="where runs are trained: this machine's processes, or a Ray cluster")
    parser.add_argument("--address", default=None,
                        help="Ray cluster: auto (the one running on this machine) or HOST:PORT of its head; "
                             "default: start a private one on this machine")
    parser.add_argument("--figures", nargs="+", default=list(experiments.FIGURES), metavar="FIGURE",
                        help=f"train only these figures' runs; one or more of {list(experiments.FIGURES)}")
    parser.add_argument("--skip-notebooks", action="store_true", help="train the runs only")
    args = parser.parse_args(argv)
    try:  # fail fast, naming what is allowed
        experiments.get_budget(args.budget)
        for figure in args.figures:
            experiments.get_figure(figure)
        if args.address is not None and args.executor != "ray":
            raise ValueError(f"--address {args.address!r} needs --executor ray")
        if args.executor == "ray":
            from oapo_lite.executors import check_address

            check_address(args.address)
    except ValueError as err:
        parser.error(str(err))

    start = time.perf_counter()
    runs = experiments.run_all(args.budget, figures=args.figures, workers=args.workers,
                               progress="lines" if args.check else True, executor=args.executor,
                               address=args.address)
    timings = [] if args.skip_notebooks or runs.failed else run_notebooks(args.budget, args.inplace)
    print("\nSummary")
    print(f"  experiment runs ({args.executor}): {runs.done} trained, {runs.cached} already on disk, "
          f"{len(runs.failed)} failed")
    for failure in runs.failed:
        print(f"  FAILED {experiments.run_id(failure.run.cfg)} ({failure.run.figure}, curve {failure.run.label!r})")
    if runs.failed:
        print("  notebooks not run: they need every run (failures reported above with config and traceback)")
    for name, seconds in timings:
        print(f"  {name:<45s} {seconds:6.1f} s")
    print(f"  total wall time: {time.perf_counter() - start:.1f} s")
    print(f"  figures: {experiments.figures_dir(args.budget)}/")
    return 1 if runs.failed else 0


if __name__ == "__main__":
    sys.exit(main())
