"""The command line of oapo-lite: train one run, reproduce a budget's runs and notebooks, or
build the notebooks as a static site.

examples:
    python -m oapo_lite train --algo oappo --env black_red --seed 0 --steps 200000 --sigma 0.1 --reuse-lambda 0.7 --out runs/
    python -m oapo_lite train --algo oappo --env smax:3m --n-envs 64 --max-steps 100 --steps 300000
    python -m oapo_lite reproduce --budget student --plan

Every TrainConfig field is a flag of train; the run goes to <out>/<algo>-<env>-s<seed>-<config hash>/
(the name the run cache uses), so runs that differ in any setting never share a folder.

Errors in what you asked for (a bad value, a damaged checkpoint, a folder that cannot be
written, a run that diverged) are one line on stderr, exit status 2. --debug (anywhere on
the line) or OAPO_DEBUG=1 shows the Python traceback instead.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import sys
import time
from pathlib import Path

from oapo_lite import cli


def _none_or(kind):
    return lambda text: None if text.lower() == "none" else kind(text)


def _mask_or_scheme(text: str):
    """``--allowed``: a scheme's name, or a mask as JSON (``[[1, 0], [0, 1]]``)."""
    if not text.lstrip().startswith("["):
        return text
    import json

    try:
        return json.loads(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is no JSON list; allowed: a scheme or a mask such as "
                                         "[[1, 0], [0, 1]]") from None


def _bool(text: str) -> bool:
    if text.lower() not in ("true", "false", "1", "0"):
        raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")
    return text.lower() in ("true", "1")


class _Renamed(argparse.Action):
    """A flag whose field was renamed: an error naming the new flag."""

    def __init__(self, option_strings, dest, new: str, **kwargs):
        super().__init__(option_strings, dest, **kwargs)
        self.new = new

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(f"{option_string} was renamed --{self.new.replace('_', '-')}")


def train_parser() -> argparse.ArgumentParser:
    from oapo_lite.envs.maps import MAPS
    from oapo_lite.neural.config import ALLOWED, MEANING, RENAMED, TrainConfig

    parser = cli.Parser(prog="python -m oapo_lite train", usage="%(prog)s [--algo ALGO] [--env ENV] [--seed SEED] "
                        "[--FIELD VALUE ...] [--out FOLDER] [--no-resume] [--no-progress] [--tensorboard FOLDER]",
                        description="Train one run. Every flag but the last four "
                        "is a field of oapo_lite.neural.config.TrainConfig; none or true / false where a field takes "
                        "None or True / False.")
    special = {
        "hidden": dict(type=int, nargs="+"),
        "allowed": dict(type=_none_or(_mask_or_scheme)),
        "networks": dict(type=_none_or(str)),
        "bootstrap_truncation": dict(type=_none_or(_bool)),
        "reuse_adapt": dict(type=_none_or(str)),
        "seps_clusters": dict(type=_none_or(int)),
        "env": dict(type=str),
    }
    # on the command line, a map file's path too
    allowed = {**ALLOWED, "env": f"a built-in map {sorted(MAPS)}, a path to a map text file, or <engine>:<name> of a "
                                 "real engine, e.g. smax:3m, mamujoco:HalfCheetah-2x3, grf:academy_3_vs_1_with_keeper"}
    for old, new in RENAMED.items():
        parser.add_argument(*dict.fromkeys([f"--{old.replace('_', '-')}", f"--{old}"]), action=_Renamed, new=new,
                            default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    for f in dataclasses.fields(TrainConfig):
        if f.name == "env_fn":
            continue  # a Python callable: use the API
        # type=bool would read "false" as True: a non-empty string
        options = special.get(f.name, dict(type=_bool if isinstance(f.default, bool) else type(f.default)))
        flags = dict.fromkeys([f"--{f.name.replace('_', '-')}", f"--{f.name}"])  # --n-envs and --n_envs
        default = " ".join(map(str, f.default)) if isinstance(f.default, tuple) else f.default
        parser.add_argument(*flags, dest=f.name, default=f.default, **options,
                            help=cli.flag_help(MEANING[f.name], default, allowed[f.name]))
    parser.add_argument("--out", default="runs", help=cli.flag_help("parent folder of the run folder", "runs",
                                                                    "a folder path"))
    parser.add_argument("--no-resume", action="store_true",
                        help=cli.flag_help("start afresh even if the run folder holds a checkpoint", "resume"))
    parser.add_argument("--no-progress", action="store_true",
                        help=cli.flag_help("no progress bar (a line of results at the end still)", "a bar"))
    parser.add_argument("--tensorboard", metavar="FOLDER", default=None,
                        help=cli.flag_help("also write the live diagnostics as TensorBoard scalars there "
                                           "(tensorboard --logdir FOLDER)", "none", "a folder path"))
    return parser


def _refuse_unhonoured(parser: argparse.ArgumentParser, argv: list[str], args: dict) -> None:
    """What the run could not honour is an error, not a silent no-op: a flag for a field the
    algorithm does not read, an unusable TensorBoard folder. (A flag given twice: ``cli.Parser``;
    steps that are not whole iterations: ``_refuse_partial_iteration``.)"""
    from oapo_lite.algorithms import ALGOS
    from oapo_lite.neural.config import readers

    for action in parser._actions:
        if cli.times_given(action, argv) and args["algo"] in ALGOS and args["algo"] not in readers(action.dest):
            parser.error(f"{action.option_strings[0]} does not apply to --algo {args['algo']}; only "
                         f"{readers(action.dest)} read it")
    board = args.get("tensorboard")
    if board is not None:
        try:
            args["tensorboard"] = str(cli.writable_folder(board, "--tensorboard"))
        except ValueError as err:
            parser.error(str(err))


def _refuse_partial_iteration(parser: argparse.ArgumentParser, cfg) -> None:
    """The run trains ``steps // iteration_steps`` whole iterations: other steps would be
    recorded as asked but not trained."""
    per = cfg.iteration_steps
    if cfg.steps % per:
        below, above = cfg.steps // per * per, (cfg.steps // per + 1) * per
        parser.error(f"--steps {cfg.steps} is not a whole number of iterations of n_envs x {cfg.rollout_field} = {per} "
                     f"env steps; allowed: a multiple of {per}, e.g. {below or above} or {above}")


def train_main(argv: list[str]) -> int:
    parser = train_parser()
    args = vars(parser.parse_args(argv))  # first: --help and a bad flag answer before the heavy imports
    import pandas as pd

    from oapo_lite.envs.maps import MAPS, parse_maze
    from oapo_lite.neural.config import TrainConfig
    from oapo_lite.neural.train import train
    from oapo_lite.store import regular_file

    _refuse_unhonoured(parser, argv, args)
    out, resume, progress = cli.output_folder(args.pop("out"), "--out"), not args.pop("no_resume"), \
        not args.pop("no_progress")
    tensorboard = args.pop("tensorboard")
    name, file_name = args["env"], None
    allowed = f"allowed: a built-in map {sorted(MAPS)}, a map file or <engine>:<name>"
    if not name.strip():
        raise ValueError(f"--env {name!r} is empty; {allowed}")
    if name not in MAPS and (os.path.lexists(name) or ":" not in name and ("/" in name or name.endswith(".txt"))):
        path = Path(name)
        try:
            regular_file(path, "--env", allowed)  # a FIFO or a device is named, never opened
            args["env"] = path.read_text()
        except FileNotFoundError:
            raise ValueError(f"--env {name!r}: no such map file; {allowed}") from None
        except (OSError, UnicodeDecodeError) as err:
            raise ValueError(f"cannot read the map file {path}: {err}") from None
        parse_maze(args["env"], name=str(path))  # its errors name the file
        name = file_name = path.stem
    cfg = TrainConfig(**args)
    _refuse_partial_iteration(parser, cfg)
    run_dir = out / cfg.run_id(file_name)
    print(f"run folder: {run_dir}", flush=True)
    start = time.perf_counter()
    rows = train(cfg, run_dir, resume=resume, progress=progress, tensorboard=tensorboard)
    wall = time.perf_counter() - start
    last = rows.iloc[-1]
    hit = rows.loc[rows["frac_opt"] >= 0.95, "step"]
    has_optimum = rows["frac_opt"].notna().any()  # only the mazes have an oracle
    print(f"{cfg.algo} on {name}, seed {cfg.seed}: {int(last['step'])} env steps in {wall:.1f} s")
    parts = [f"return {last['eval_return']:.3f}"]
    if has_optimum:
        parts.append(f"{last['frac_opt']:.1%} of the optimum")
    if pd.notna(last["eval_success"]):  # NaN: the env has no success rule (MaMuJoCo)
        parts.append(f"success {last['eval_success']:.0%}")
    print(f"  final evaluation: {', '.join(parts)}")
    if has_optimum:
        print(f"  95% of the optimum first reached at: {f'{int(hit.iloc[0])} env steps' if len(hit) else 'never'}")
    print(f"  results: {run_dir / 'results.csv'}")
    return 0


def _reproduce(argv: list[str]) -> int:
    from oapo_lite.study.runs.reproduce import main as reproduce_main

    return reproduce_main(argv)


def _book(argv: list[str]) -> int:
    from oapo_lite.study.report.book import main as book_main

    return book_main(argv)


COMMANDS = {"train": train_main, "reproduce": _reproduce, "book": _book}
SUMMARIES = {"train": "train one run (python -m oapo_lite train --help: every flag)",
             "reproduce": "train a budget's runs, then execute every notebook (--plan: what it would cost)",
             "book": "the notebooks with their committed outputs as a static site"}


def usage() -> str:
    """``--help``: the usage line, the commands and what they do, then the module's words."""
    commands = "\n".join(f"  {name:<11}{SUMMARIES[name]}" for name in COMMANDS)
    return (f"usage: python -m oapo_lite {{{','.join(COMMANDS)}}} [--help] [FLAGS ...] [--debug]\n\ncommands:\n"
            f"{commands}\n\n{__doc__.strip()}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = cli.debug_requested(argv)
    argv = [a for a in argv if a != "--debug"]
    if argv and argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    if not argv:
        print(f"error: no command given; the commands are {list(COMMANDS)} (python -m oapo_lite --help)",
              file=sys.stderr)
        return 2
    if argv[0] not in COMMANDS:
        print(f"error: unknown command {argv[0]!r}; the commands are {list(COMMANDS)} (python -m oapo_lite --help)",
              file=sys.stderr)
        return 2
    try:
        if not {"-h", "--help"} & set(argv[1:]):  # a command's help parses its flags, and needs no torch
            with cli.uninterrupted():  # an interrupt during the import waits for its end
                import torch  # noqa: F401
        return COMMANDS[argv[0]](argv[1:])
    except KeyboardInterrupt:
        print("interrupted; run the same command again to resume", file=sys.stderr)
        return 130
    except Exception as err:
        if debug:
            raise
        return cli.report(err)


if __name__ == "__main__":
    # Ctrl-C stops every command, even one started where SIGINT is ignored (a script's `cmd &`
    # inherits SIG_IGN, and Python then keeps it), and SIGTERM as Ctrl-C does; the heavy imports
    # come after, inside main, where an interrupt is one line
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, cli.interrupt)
    status = main()
    for sig in (signal.SIGINT, signal.SIGTERM):  # a late signal cannot turn the exit status into a traceback
        signal.signal(sig, signal.SIG_IGN)
    if status == 130:  # interrupted: the work is stopped and written; the interpreter's shutdown restores the
        sys.stdout.flush()  # default handlers, where a signal still pending would end the process by that
        sys.stderr.flush()  # signal instead of 130 (seen on a loaded machine), so leave without it
        os._exit(status)
    sys.exit(status)
