"""Command line: ``python -m oapo_lite train ...`` (one run) or ``python -m oapo_lite reproduce ...``.

    python -m oapo_lite train --algo oappo --env black_red --seed 0 --steps 200000 --sigma 0.1 --lam 0.7 --out runs/
    python -m oapo_lite runs fig6b --budget cpu --workers 1

Every ``TrainConfig`` field is a flag; the run goes to ``<out>/<algo>_<env>_s<seed>/``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from oapo_lite.envs.maps import MAPS


def _none_or(kind):
    return lambda text: None if text.lower() == "none" else kind(text)


def _bool(text: str) -> bool:
    if text.lower() not in ("true", "false", "1", "0"):
        raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")
    return text.lower() in ("true", "1")


def train_parser() -> argparse.ArgumentParser:
    from oapo_lite.train import TrainConfig

    parser = argparse.ArgumentParser(prog="python -m oapo_lite train", description="Train one run.")
    special = {
        "hidden": dict(type=int, nargs="+"),
        "allowed": dict(type=_none_or(str), help="none or a scheme: NR, UR, RR, AR"),
        "shared": dict(type=_none_or(_bool), help="none (the algorithm's choice), true or false"),
        "bootstrap_truncation": dict(type=_none_or(_bool), help="none (no on the built-in mazes), true or false"),
        "env": dict(type=str, help=f"a built-in map {sorted(MAPS)} or a path to a map text file"),
    }
    for f in dataclasses.fields(TrainConfig):
        if f.name == "env_fn":
            continue  # a Python callable: use the API
        options = special.get(f.name, dict(type=type(f.default)))
        flags = dict.fromkeys([f"--{f.name.replace('_', '-')}", f"--{f.name}"])  # --n-envs and --n_envs
        parser.add_argument(*flags, dest=f.name, default=f.default, **options)
    parser.add_argument("--out", default="runs", help="parent folder of the run folder")
    parser.add_argument("--no-resume", action="store_true", help="start afresh even if a checkpoint exists")
    parser.add_argument("--no-progress", action="store_true")
    return parser


def train_main(argv: list[str]) -> int:
    from oapo_lite.train import TrainConfig, train

    args = vars(train_parser().parse_args(argv))
    out, resume, progress = Path(args.pop("out")), not args.pop("no_resume"), not args.pop("no_progress")
    name = args["env"]
    if name not in MAPS and Path(name).is_file():
        args["env"], name = Path(name).read_text(), Path(name).stem
    try:
        cfg = TrainConfig(**args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    run_dir = out / f"{cfg.algo}_{name.replace(':', '-')}_s{cfg.seed}"
    start = time.perf_counter()
    try:
        rows = train(cfg, run_dir, resume=resume, progress=progress)
    except ImportError as err:  # an engine that is not installed says how to install it
        print(f"error: {err}", file=sys.stderr)
        return 2
    wall = time.perf_counter() - start
    last = rows.iloc[-1]
    hit = rows.loc[rows["frac_opt"] >= 0.95, "step"]
    print(f"{cfg.algo} on {name}, seed {cfg.seed}: {int(last['step'])} env steps in {wall:.1f} s")
    print(f"  final evaluation: return {last['eval_return']:.3f}, {last['frac_opt']:.1%} of the optimum, "
          f"success {last['eval_success']:.0%}")
    print(f"  95% of the optimum first reached at: {f'{int(hit.iloc[0])} env steps' if len(hit) else 'never'}")
    print(f"  results: {run_dir / 'results.csv'}")
    return 0


def runs_main(argv: list[str]) -> int:
    """Train the missing runs of some figures at a budget (the run cache skips finished ones)."""
    from oapo_lite import experiments

    parser = argparse.ArgumentParser(prog="python -m oapo_lite runs", description=runs_main.__doc__)
    parser.add_argument("figures", nargs="+", help="figure names, e.g. fig6b")
    parser.add_argument("--budget", required=True)
    parser.add_argument("--workers", type=int, default=1, help="runs trained at the same time")
    args = parser.parse_args(argv)
    try:
        for fig in args.figures:
            experiments.figure_runs(fig, args.budget)  # fail fast on a bad name
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        count = experiments.run_all(args.budget, figures=args.figures, workers=args.workers)
    except ImportError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"{count.done} runs trained, {count.cached} already on disk")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    commands = {"train": train_main, "runs": runs_main}
    if argv and argv[0] == "reproduce":
        from oapo_lite.reproduce import main as reproduce_main

        return reproduce_main(argv[1:])
    if not argv or argv[0] not in commands:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    return commands[argv[0]](argv[1:])


if __name__ == "__main__":
    sys.exit(main())
