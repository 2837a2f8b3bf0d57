"""Command line: ``python -m oapo_lite train ...`` (one run), ``python -m oapo_lite reproduce ...``
or ``python -m oapo_lite book`` (the notebooks as a static site).

    python -m oapo_lite train --algo oappo --env black_red --seed 0 --steps 200000 --sigma 0.1 --lam 0.7 --out runs/
    python -m oapo_lite train --algo oappo --env smax:3m --n-envs 64 --max-steps 100 --steps 300000

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
        "reuse_adapt": dict(type=_none_or(str), help="none (Eq. 9 as written), gradient, gradient_sign or "
                                                     "gradient_test (oapo_lite/adaptive.py)"),
        "seps_clusters": dict(type=_none_or(int), help="none (chosen by the Davies-Bouldin index) or a number"),
        "env": dict(type=str, help=f"a built-in map {sorted(MAPS)}, a path to a map text file, or "
                                   "<engine>:<name> of a real engine, e.g. smax:3m, mamujoco:HalfCheetah-2x3, "
                                   "grf:academy_3_vs_1_with_keeper"),
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
    except ImportError as err:  # an optional engine that is not installed says how to install it
        print(f"error: {err}", file=sys.stderr)
        return 2
    wall = time.perf_counter() - start
    last = rows.iloc[-1]
    hit = rows.loc[rows["frac_opt"] >= 0.95, "step"]
    has_optimum = rows["frac_opt"].notna().any()  # only the mazes have an oracle
    print(f"{cfg.algo} on {name}, seed {cfg.seed}: {int(last['step'])} env steps in {wall:.1f} s")
    print(f"  final evaluation: return {last['eval_return']:.3f}, "
          + (f"{last['frac_opt']:.1%} of the optimum, " if has_optimum else "")
          + f"success {last['eval_success']:.0%}")
    if has_optimum:
        print(f"  95% of the optimum first reached at: {f'{int(hit.iloc[0])} env steps' if len(hit) else 'never'}")
    print(f"  results: {run_dir / 'results.csv'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    commands = {"train": train_main}
    if argv and argv[0] == "reproduce":
        from oapo_lite.reproduce import main as reproduce_main

        return reproduce_main(argv[1:])
    if argv and argv[0] == "book":
        from oapo_lite.book import main as book_main

        return book_main(argv[1:])
    if not argv or argv[0] not in commands:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    return commands[argv[0]](argv[1:])


if __name__ == "__main__":
    sys.exit(main())
