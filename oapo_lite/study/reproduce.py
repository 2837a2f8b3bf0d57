"""The main job: run every experiment of a budget, then execute every notebook with papermill.

Experiment runs are cached on disk (see ``experiments``), so an interrupted reproduction
resumes where it stopped; notebooks then only read results and draw figures.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

from oapo_lite import cli
from oapo_lite.study import grid

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = ROOT / "notebooks"


def notebook_paths(budget: str | None = None) -> list[Path]:
    """The numbered notebooks, or those a budget runs (``Budget.notebooks``)."""
    paths = sorted(NOTEBOOKS.glob("[0-9]*.ipynb"))
    wanted = None if budget is None else grid.get_budget(budget).notebooks
    return paths if wanted is None else [p for p in paths if p.name.split("_")[0] in wanted]


def takes_budget(path: Path) -> bool:
    """A notebook takes a budget when its cell tagged ``parameters`` defines one."""
    import nbformat

    nb = nbformat.read(path, as_version=4)
    return any(
        "parameters" in c.metadata.get("tags", []) and "budget" in c.source for c in nb.cells
    )


def check_parameters(*names: str) -> None:
    """Stop a notebook run with a parameter it does not take: papermill only warns, and a
    misspelled ``budgte`` would run the committed budget. Called first in the cell after the
    ``parameters`` cell, which is where papermill puts the cell it injects (its source starts
    "# Parameters"); outside papermill there is nothing to check."""
    import ast

    from IPython import get_ipython

    shell = get_ipython()
    injected = [src for src in (shell.user_ns.get("In", []) if shell else []) if src.startswith("# Parameters")]
    if not injected:
        return
    given = {t.id for node in ast.parse(injected[-1]).body if isinstance(node, ast.Assign)
             for t in node.targets if isinstance(t, ast.Name)}
    unknown = sorted(given - set(names))
    if unknown:
        raise ValueError(f"unknown notebook parameter(s) {unknown}; this notebook takes {sorted(names)}")
    if "budget" in given:  # a bad value, named here rather than where the budget is first used
        grid.get_budget(shell.user_ns["budget"])


class NotebookFailed(RuntimeError):
    """A notebook's cell raised, or its kernel died; the message names the notebook and the cell."""


def kernel_manager_class():
    """jupyter_client's kernel manager, with two defaults changed for a local batch run.

    - IPC transport: the kernel is a child process on this machine, so its channels are Unix
      sockets, not TCP ports on localhost (over TCP ipykernel warns, rightly, that anyone on the
      machine could listen in, once per notebook). The sockets get a path of their own in
      Jupyter's runtime folder: jupyter_client's default, ``kernel-ipc-<n>`` in the working
      folder, is shared by kernels started at the same time, which then read each other's
      messages.
    - No SIGINT before the shutdown request: jupyter_client interrupts the kernel before asking
      it to shut down, and a kernel still busy with its last message logs "KeyboardInterrupt
      caught in kernel". nbclient shuts the kernel down only once the last cell has replied (or
      after its own interrupt on a timeout), so there is nothing to interrupt; a kernel that does
      not exit after the request is still killed by jupyter_client.
    """
    import os
    import uuid

    from jupyter_client.manager import AsyncKernelManager
    from jupyter_core.paths import jupyter_runtime_dir
    from traitlets import CaselessStrEnum, default

    class BatchKernelManager(AsyncKernelManager):
        transport = CaselessStrEnum(["tcp", "ipc"], default_value="ipc", config=True)

        @default("ip")
        def _unique_ipc_path(self) -> str:
            os.makedirs(jupyter_runtime_dir(), exist_ok=True)
            return os.path.join(jupyter_runtime_dir(), f"oapo-kernel-{uuid.uuid4().hex}-ipc")

        async def _async_interrupt_kernel(self) -> None:
            if not self.shutting_down:
                await super()._async_interrupt_kernel()

    return BatchKernelManager


def run_notebook(path: Path, out: Path, parameters: dict, cwd: Path = NOTEBOOKS) -> None:
    """Execute ``path`` into ``out`` with papermill; raise ``NotebookFailed`` if a cell fails."""
    import papermill as pm
    from papermill.exceptions import PapermillExecutionError

    try:
        pm.execute_notebook(str(path), str(out), parameters=parameters, kernel_name="python3", language="python",
                            cwd=str(cwd), progress_bar=False, kernel_manager_class=kernel_manager_class())
    except PapermillExecutionError as err:
        trace = "\n".join(err.traceback)
        raise NotebookFailed(f"{path.name} failed in cell {err.cell_index + 1} (In [{err.exec_count}]) with "
                             f"{err.ename}: {err.evalue}\n{trace}\nthe executed notebook is {out}") from None
    except Exception as err:  # the kernel died or timed out: nbclient names no cell then
        raise NotebookFailed(f"{path.name} failed: {type(err).__name__}: {err}\nthe executed notebook is {out}") from err


def _timed_run(path: Path, out: Path, parameters: dict) -> float:
    start = time.perf_counter()
    run_notebook(path, out, parameters)
    return time.perf_counter() - start


def run_notebooks(budget: str, inplace: bool, workers: int = 2) -> list[tuple[str, float]]:
    """Execute every numbered notebook, ``workers`` at a time (each in its own kernel; they
    only read the finished runs); ``inplace`` overwrites the committed copies."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from oapo_lite.study.executors import pool_worker, stop

    out_dir = NOTEBOOKS if inplace else ROOT / "build" / "notebooks" / budget
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = notebook_paths(budget)
    timings = {}
    # spawned, as the training pool, and no more workers than notebooks: a fork pool starts all
    # of its workers at the first submit, each a copy of this process
    with ProcessPoolExecutor(max_workers=max(1, min(workers, len(paths))), mp_context=mp.get_context("spawn"),
                             initializer=pool_worker, initargs=(os.getpid(),)) as pool:
        futures = {pool.submit(_timed_run, path, out_dir / path.name,
                               {"budget": budget} if takes_budget(path) else {}): path for path in paths}
        try:
            for i, future in enumerate(as_completed(futures), 1):
                path = futures[future]
                timings[path.name] = future.result()
                print(f"[{i}/{len(paths)}] {path.name} (budget={budget}) {timings[path.name]:.1f} s", flush=True)
        except BaseException:  # a failed notebook or an interrupt: the others are not waited for
            stop(pool)
            raise
    return [(path.name, timings[path.name]) for path in paths]


def _positive(text: str) -> int:
    if not text.lstrip("+").isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid; allowed: an integer >= 1")
    return int(text)


def _check_writable(folder: Path) -> None:
    """Fail at the start, not after the first run, if results cannot be written to ``folder``."""
    from oapo_lite.store import cannot_write

    why = cannot_write(folder)
    if why:
        moved = f" (OAPO_FIGURES={os.environ['OAPO_FIGURES']!r})" if os.environ.get("OAPO_FIGURES") else ""
        raise ValueError(f"cannot write results to {folder}{moved}: {why}; point OAPO_FIGURES at a folder you can write")


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    from oapo_lite.study import experiments

    parser = cli.Parser(prog="python -m oapo_lite reproduce", description=__doc__)
    parser.add_argument("--budget", default="smoke", help=f"one of {sorted(grid.BUDGETS)}")
    parser.add_argument("--inplace", action="store_true",
                        help="write executed notebooks over notebooks/*.ipynb (to commit them)")
    parser.add_argument("--check", action="store_true",
                        help="CI mode: no progress bars")
    parser.add_argument("--workers", type=_positive, default=2,
                        help="parallel training processes (local executor), then notebooks")
    parser.add_argument("--executor", default="local", choices=["local", "ray"],
                        help="where runs are trained: this machine's processes, or a Ray cluster")
    parser.add_argument("--address", default=None,
                        help="Ray cluster: auto (the one running on this machine) or HOST:PORT of its head; "
                             "default: start a private one on this machine")
    parser.add_argument("--figures", nargs="+", default=list(grid.FIGURES), metavar="FIGURE",
                        help=f"train only these figures' runs; one or more of {list(grid.FIGURES)}")
    parser.add_argument("--skip-notebooks", action="store_true", help="train the runs only")
    args = parser.parse_args(argv)
    try:  # fail fast, naming what is allowed
        grid.get_budget(args.budget)
        for figure in args.figures:
            grid.get_figure(figure)
        if args.inplace and args.skip_notebooks:
            raise ValueError("--inplace writes the executed notebooks, and --skip-notebooks runs none; give one")
        if args.address is not None and args.executor != "ray":
            raise ValueError(f"--address {args.address!r} needs --executor ray")
        if args.executor == "ray":
            from oapo_lite.study.executors import check_address

            check_address(args.address)
        _check_writable(experiments.data_dir(args.budget))
    except ValueError as err:
        parser.error(str(err))

    start = time.perf_counter()
    signal.signal(signal.SIGTERM, _interrupt)  # a SIGTERM stops the work as Ctrl-C does
    try:
        runs = experiments.run_all(args.budget, figures=args.figures, workers=args.workers,
                                   progress="lines" if args.check else True, executor=args.executor,
                                   address=args.address)
    except KeyboardInterrupt:
        done = sum(experiments.on_disk(r.cfg, args.budget) for r in experiments.grid_runs(args.budget, args.figures))
        print(f"\ninterrupted: {done} runs of {args.figures} at budget {args.budget!r} are on disk, queued runs "
              "were not started, running ones stopped (they resume from their last checkpoint); run the same "
              "command again to resume", file=sys.stderr)
        return 130
    try:
        timings = [] if args.skip_notebooks or runs.failed else run_notebooks(args.budget, args.inplace,
                                                                              args.workers)
    except NotebookFailed as err:
        print(f"\nerror: {err}", file=sys.stderr)
        return 1
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
