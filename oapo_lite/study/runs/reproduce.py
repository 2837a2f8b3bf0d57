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
from oapo_lite.study.catalogue import grid
from oapo_lite.study.catalogue.figures import FIGURES, required_runs

ROOT = Path(__file__).resolve().parents[3]
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
    only read the finished runs); ``inplace`` overwrites the committed copies. A failed notebook
    or an interrupt stops the others at once (``executors.in_processes``)."""
    from oapo_lite.study.runs.executors import in_processes

    out_dir = NOTEBOOKS if inplace else ROOT / "build" / "notebooks" / budget
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = notebook_paths(budget)
    jobs = [(path, (path, out_dir / path.name, {"budget": budget} if takes_budget(path) else {})) for path in paths]
    timings = {}
    for i, (path, seconds, died) in enumerate(in_processes(_timed_run, jobs, max(1, workers)), 1):
        if died:
            raise NotebookFailed(f"{path.name} failed: {died}; the executed notebook is {out_dir / path.name}")
        timings[path.name] = seconds
        print(f"[{i}/{len(paths)}] {path.name} (budget={budget}) {seconds:.1f} s", flush=True)
    return [(path.name, timings[path.name]) for path in paths]


def _workers(text: str) -> int:
    if not text.lstrip("+").isdigit() or not 1 <= int(text) <= cli.MAX_WORKERS:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid; allowed: an integer in [1, {cli.MAX_WORKERS}]")
    return int(text)


def _check_writable(folder: Path) -> None:
    """Fail at the start, not after the first run, if results cannot be written to ``folder``."""
    from oapo_lite.store import cannot_write

    why = cannot_write(folder)
    if why:
        moved = f" (OAPO_FIGURES={os.environ['OAPO_FIGURES']!r})" if os.environ.get("OAPO_FIGURES") else ""
        raise ValueError(f"cannot write results to {folder}{moved}: {why}; point OAPO_FIGURES at a folder you can write")


def _check_committed_data(moved: Path, budget: str, figures) -> None:
    """Refuse a moved figures tree that lacks committed results this command does not write:
    the notebooks read them whatever the budget (the claims table, the 20-seed and engine runs
    they quote), so they would fail after all the training."""
    from oapo_lite.study.runs import experiments

    committed = ROOT / "figures"
    if moved == committed:
        return
    written = {experiments.run_path(r.cfg, budget).relative_to(moved) for r in experiments.grid_runs(budget, figures)}
    written |= {experiments.data_dir(budget).relative_to(moved) / f"{f}.csv" for f in figures}
    missing = [p.relative_to(committed) for p in sorted((committed / "data").rglob("*"))
               if p.is_file() and "checkpoints" not in p.parts and p.relative_to(committed) not in written
               and not (moved / p.relative_to(committed)).exists()]
    if missing:
        raise ValueError(f"OAPO_FIGURES={str(moved)!r} lacks {len(missing)} of the committed result files the notebooks "
                         f"read (first: {missing[0]}); copy them there (cp -r {committed}/. {moved}/) or train only "
                         "(--skip-notebooks)")


def _counted(experiments, cfg, budget: str) -> bool:
    """Whether a run is on disk, for the line an interrupt prints: a path in the cache that is no
    file (``store.NotAFile``, named when the run was read) counts as not on disk here, so that the
    stop cannot fail."""
    from oapo_lite.store import NotAFile

    try:
        return experiments.on_disk(cfg, budget)
    except NotAFile:
        return False


def _cluster_cpus(address: str | None) -> int:
    """The CPUs of the Ray cluster at ``address``; a private one would have this machine's."""
    if address is None:
        return os.cpu_count() or 1
    from oapo_lite.study.runs.executors import connect

    ray, connected = connect(address)
    try:
        return int(ray.cluster_resources().get("CPU", 1))
    finally:
        if connected:
            ray.shutdown()


def command_line() -> cli.Parser:
    """The command line of ``reproduce``."""
    parser = cli.Parser(prog="python -m oapo_lite reproduce", description=__doc__)
    parser.add_argument("--budget", default="smoke", help=cli.flag_help("the runs' budget, and the notebooks'", "smoke",
                                                                        str(sorted(grid.BUDGETS))))
    parser.add_argument("--inplace", action="store_true",
                        help=cli.flag_help("write the executed notebooks over notebooks/*.ipynb (to commit them)",
                                           "into build/notebooks/<budget>/"))
    parser.add_argument("--check", action="store_true",
                        help=cli.flag_help("CI mode: a line per finished run instead of progress bars", "bars"))
    parser.add_argument("--workers", type=_workers, default=2,
                        help=cli.flag_help("parallel training processes (local executor), then notebooks", 2,
                                           f"an integer in [1, {cli.MAX_WORKERS}]"))
    parser.add_argument("--executor", default="local", choices=["local", "ray"],
                        help=cli.flag_help("where runs are trained: this machine's processes, or a Ray cluster",
                                           "local", "local or ray"))
    parser.add_argument("--address", default=None,
                        help=cli.flag_help("the Ray cluster: auto (the one running on this machine) or its head's "
                                           "HOST:PORT", "a private cluster on this machine",
                                           "auto, HOST:PORT or ray://HOST:PORT"))
    parser.add_argument("--figures", nargs="+", default=None, metavar="FIGURE",
                        help=cli.flag_help("train only these figures' runs", "every figure",
                                           f"one or more of {list(FIGURES)}"))
    parser.add_argument("--skip-notebooks", action="store_true",
                        help=cli.flag_help("train the runs only", "then execute every notebook"))
    parser.add_argument("--plan", action="store_true",
                        help=cli.flag_help("print what the command would train and its estimated CPU and wall time "
                                           "(per figure: runs, env steps, on disk, to train); train and write nothing",
                                           "train"))
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = command_line()
    args = parser.parse_args(argv)  # first: --help and a bad flag answer before the heavy imports
    from oapo_lite.study.runs import experiments

    try:  # fail fast, naming what is allowed
        grid.get_budget(args.budget)
        every = args.figures is None
        if every:  # every figure: those without runs at the budget have nothing to do
            args.figures = list(FIGURES)
        else:  # a figure named on purpose that has no runs at the budget would read as "nothing to do"
            for figure in args.figures:
                required_runs(figure, args.budget)
        if args.inplace and args.skip_notebooks:
            raise ValueError("--inplace writes the executed notebooks, and --skip-notebooks runs none; give one")
        if args.address is not None and args.executor != "ray":
            raise ValueError(f"--address {args.address!r} needs --executor ray")
        if args.executor == "ray":
            from oapo_lite.study.runs.executors import check_address

            check_address(args.address)
        if args.plan:
            from oapo_lite.study.runs import costs

            workers = args.workers if args.executor == "local" else _cluster_cpus(args.address)
            print(costs.main_plan(args.budget, args.figures, workers))
            return 0
        if os.environ.get("OAPO_FIGURES"):  # resolved once: the notebooks run in notebooks/, the workers anywhere
            os.environ["OAPO_FIGURES"] = str(cli.output_folder(os.environ["OAPO_FIGURES"], "OAPO_FIGURES"))
            if not args.skip_notebooks:
                _check_committed_data(experiments.figures_dir(grid.COMMITTED[0]), args.budget, args.figures)
        _check_writable(experiments.data_dir(args.budget))
    except ValueError as err:
        parser.error(str(err))

    start = time.perf_counter()
    signal.signal(signal.SIGTERM, cli.interrupt)  # a SIGTERM stops the work as Ctrl-C does
    try:
        runs = experiments.run_all(args.budget, figures=None if every else args.figures, workers=args.workers,
                                   progress="lines" if args.check else True, executor=args.executor,
                                   address=args.address)
    except KeyboardInterrupt:
        done = sum(_counted(experiments, r.cfg, args.budget) for r in experiments.grid_runs(args.budget, args.figures))
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
    except KeyboardInterrupt:
        print("\ninterrupted while executing the notebooks: every run is on disk and the notebooks stopped; run "
              "the same command again to resume (the notebooks are executed again)", file=sys.stderr)
        return 130
    print("\nSummary")
    print(f"  experiment runs ({args.executor}): {runs.done} trained, {runs.cached} already on disk, "
          f"{len(runs.failed)} failed")
    for failure in runs.failed:
        print(f"  FAILED {failure.run.cfg.run_id()} ({failure.run.figure}, curve {failure.run.label!r})")
    if runs.failed:
        print("  notebooks not run: they need every run (failures reported above with config and traceback)")
    for name, seconds in timings:
        print(f"  {name:<45s} {seconds:6.1f} s")
    print(f"  total wall time: {time.perf_counter() - start:.1f} s")
    print(f"  figures: {experiments.figures_dir(args.budget)}/")
    return 1 if runs.failed else 0


if __name__ == "__main__":
    sys.exit(main())
