"""Bad input and damaged files, as a user meets them: every command-line error is one line with
exit status 2 and no traceback; no damaged file is loaded or loses a result; killed and
concurrent writers leave nothing behind and train nothing twice."""
import argparse
import dataclasses
import errno
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

import fakes

from oapo_lite import __main__ as cli, store
from oapo_lite.algorithms import ALGOS
from oapo_lite.neural.config import TrainConfig, readers
from oapo_lite.neural.losses import Diverged
from oapo_lite.neural.results import learning
from oapo_lite.neural.runstate import RunState, load_checkpoint
from oapo_lite.neural.train import _diverged_at, train
from oapo_lite.study.catalogue import figures
from oapo_lite.study.runs import experiments
from oapo_lite.study.catalogue.metrics import FRAC_OPT, WIN_RATE
from oapo_lite.study.catalogue.tests import Claim
from oapo_lite.study.judge import evidence, statistics, verdicts
from oapo_lite.study.report import words
from oapo_lite.study.studies import tables
from oapo_lite.study.report import plotting
from oapo_lite.study.runs.executors import train_job

QUICK = ["--n-envs", "8", "--rollout-len", "25", "--steps", "400", "--eval-episodes", "4", "--no-progress"]
SMALL = dict(env="black_red", n_envs=8, rollout_len=25, steps=400, eval_every=1, eval_episodes=4)


def quick_but(argv) -> list[str]:
    """QUICK less the flags ``argv`` gives (a flag given twice is an error) and, for SEAC / SePS,
    less --rollout-len (their rollout is n_step long)."""
    drop = {a for a in argv if a.startswith("--")} | ({"--rollout-len"} if {"seac", "seps"} & set(argv) else set())
    out, skip = [], False
    for a in QUICK:
        if skip:
            skip = False
        elif a in drop:
            skip = a != "--no-progress"
        else:
            out.append(a)
    return out


def _cli_error(capsys, *argv) -> str:
    """Run the CLI, expect exit status 2 and one line on stderr, no traceback; return the line."""
    try:
        code = cli.main(list(argv))
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize("argv, words", [
    (["--algo", "seac", "--networks", "one"], ["networks = 'one'", "None with algo 'seac'"]),
    (["--algo", "seac", "--bootstrap-truncation", "true"], ["bootstrap_truncation = True", "None or False"]),
    (["--algo", "seps", "--env", "black_blue_red", "--seps-clusters", "5", "--seps-pretrain-steps", "200"],
     ["seps_clusters = 5", "3 agents", "1..3"]),
    (["--env", "mamujoco:Hopper-3x1", "--algo", "oappo"], ["needs equal spaces", "allowed"]),
    (["--env", "mamujoco:Hopper-3x1", "--algo", "mappo"], ["needs equal spaces", "happo"]),
    (["--lr", "inf"], ["lr = inf", "a number > 0 and below 3.4e38"]),
    (["--lr", "1e300"], ["lr = 1e+300", "below 3.4e38 (float32's largest)"]),
    (["--clip", "1e300"], ["clip = 1e+300", "below 3.4e38"]),
    (["--env", ""], ["--env '' is empty"]),
    (["--allowed", "[[1, 0], [0, 1]"], ["is no JSON list"]),
    (["--lr", "1e30"], ["not finite", "learner 0 (seats ['red'])", "no checkpoint had been written"]),
    (["--sigma", "-1"], ["sigma = -1.0", ">= 0"]),
    (["--steps", "200.0"], ["--steps", "200.0"]),
    (["--n-envs", "0"], ["n_envs = 0", "integer >= 1"]),
    (["--algo", "ppo"], ["ppo", "oappo"]),
    (["--lam", "0.4"], ["--lam was renamed --reuse-lambda"]),
    (["--algo", "mappo", "--allowed", "NR"], ["--allowed does not apply to --algo mappo", "'oappo', 'oatrpo'"]),
    (["--algo", "happo", "--sigma", "0.5"], ["--sigma does not apply to --algo happo"]),
    (["--algo", "oappo", "--cg-iters", "3"], ["--cg-iters does not apply", "'hatrpo', 'oatrpo'"]),
    (["--algo", "seac", "--lr", "0.1"], ["--lr does not apply to --algo seac"]),
    (["--lr-ann", "true"], ["unrecognized arguments: --lr-ann"]),  # an abbreviation could name another flag
    (["--seed", "1", "--seed", "2"], ["--seed is given 2 times; give it once"]),
    (["--steps", "599"], ["--steps 599 is not a whole number of iterations", "a multiple of 200, e.g. 400 or 600"]),
    (["--tensorboard", ""], ["--tensorboard '' is empty; allowed: a folder path"]),
    (["--tensorboard", "/"], ["--tensorboard '/' is the filesystem root"]),
    (["--seed", "4294967296"], ["seed = 4294967296 is invalid; allowed: an integer in [0, 4294967295]"]),
    (["--env", "maps/no_such_map.txt"], ["no such map file"]),
    (["--algo", "seps", "--seps-clusters", "5", "--seps-pretrain-steps", "200"], ["seps_clusters = 5", "2 agents"]),
    (["--eval-episodes", "10000000000"], ["out of memory", "--eval-episodes"]),
    (["--hidden", "2000000", "2000000"], ["out of memory", "--hidden"]),
])
def test_a_bad_training_option_is_one_line_naming_it(tmp_path, capsys, argv, words):
    err = _cli_error(capsys, "train", *quick_but(argv), "--out", str(tmp_path), *argv)
    for word in words:
        assert word in err


def test_a_diverging_oatrpo_run_is_one_line(tmp_path, capsys):
    err = _cli_error(capsys, "train", "--algo", "oatrpo", "--lr", "1e6", "--critic-lr", "1e6", "--n-envs", "8",
                     "--rollout-len", "25", "--steps", "6000", "--eval-every", "100", "--no-progress",
                     "--out", str(tmp_path))
    assert "of oatrpo seed 0" in err and "is not finite" in err


@pytest.mark.parametrize("out", ["a_file", "a_file/below", "/proc/no_such/folder"])
def test_an_output_folder_that_cannot_be_made_is_named(tmp_path, capsys, out):
    (tmp_path / "a_file").write_text("x")
    target = out if out.startswith("/") else str(tmp_path / out)
    err = _cli_error(capsys, "train", *QUICK, "--out", target)
    assert (f"cannot create the run folder {target}/" in err and "another output folder (--out" in err
            or f"--out {target!r} is a file; allowed: a folder" in err
            or f"--out {target!r} lies below {str(tmp_path / 'a_file')!r}, which is a file; allowed: a folder" in err)


@pytest.mark.parametrize("command, out, words", [
    ("train", "", "--out '' is empty; allowed: a folder path (. for the working folder)"),
    ("train", "/", "--out '/' is the filesystem root; allowed: a folder below it"),
    ("train", "dangling", "--out '{tmp}/dangling' is a link to '{tmp}/nowhere', which does not exist"),
    ("book", "", "--out '' is empty"),
    ("book", "/", "--out '/' is the filesystem root"),
    ("book", ".", "holds files the book did not write; allowed: an empty or new folder"),
])
def test_an_output_path_that_would_alias_another_folder_is_refused(tmp_path, capsys, monkeypatch, command, out, words):
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    (tmp_path / "notes.txt").write_text("a user's file")
    monkeypatch.chdir(tmp_path)
    path = str(tmp_path / out) if out == "dangling" else out
    err = _cli_error(capsys, command, *(QUICK if command == "train" else []), "--out", path)
    assert words.format(tmp=tmp_path) in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "notes.txt"]  # nothing written


def test_a_relative_oapo_figures_is_resolved_once_and_a_moved_tree_without_the_committed_runs_is_refused(
        tmp_path, capsys, monkeypatch):
    from oapo_lite.study.runs import reproduce

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("OAPO_FIGURES", "moved")
    err = _cli_error(capsys, "reproduce", "--budget", "smoke", "--figures", "fig1")
    assert f"OAPO_FIGURES={str(tmp_path / 'moved')!r} lacks" in err and "the notebooks read" in err
    assert os.environ["OAPO_FIGURES"] == str(tmp_path / "moved")  # what the notebooks and workers are given
    shutil.copytree(experiments.ROOT / "figures", tmp_path / "moved", ignore=shutil.ignore_patterns("checkpoints"))
    monkeypatch.setattr(reproduce, "run_notebooks", lambda *a: [])  # the check passes: training starts
    assert cli.main(["reproduce", "--budget", "smoke", "--figures", "fig1", "--check"]) == 0
    assert experiments.missing_runs("fig1", "smoke") == [] and (tmp_path / "moved" / "smoke" / "data").is_dir()


def test_run_folders_carry_the_config_hash_so_settings_never_collide(tmp_path, capsys):
    for lr in ("5e-4", "1e-3"):
        assert cli.main(["train", *QUICK, "--lr", lr, "--out", str(tmp_path)]) == 0
    folders = sorted(p.name for p in tmp_path.iterdir())
    cfgs = [TrainConfig(algo="oappo", env="black_red", n_envs=8, rollout_len=25, steps=400, eval_episodes=4, lr=lr)
            for lr in (5e-4, 1e-3)]
    assert folders == sorted(c.run_id() for c in cfgs) and len(set(folders)) == 2
    assert f"run folder: {tmp_path / cfgs[0].run_id()}" in capsys.readouterr().out


def test_resuming_past_the_asked_steps_names_no_resume(tmp_path, capsys):
    cfg = TrainConfig(algo="happo", **{**SMALL, "steps": 800})
    train(cfg, tmp_path / "run", progress=False)
    with pytest.raises(ValueError, match="--no-resume"):
        train(TrainConfig(algo="happo", **SMALL), tmp_path / "run", progress=False)
    with pytest.raises(ValueError, match="different config.*--no-resume"):
        train(TrainConfig(algo="happo", **{**SMALL, "steps": 800, "lr": 1e-3}), tmp_path / "run", progress=False)


def test_a_map_file_error_names_the_file(tmp_path, capsys):
    path = tmp_path / "my_maze.txt"
    path.write_text("agents: red black\nstart: 1,1 1,1\n#####\n#..*##\n#####\n")
    assert f"map '{path}' has ragged rows" in _cli_error(capsys, "train", *QUICK, "--env", str(path),
                                                         "--out", str(tmp_path))
    path.write_bytes(b"\xff\xfe\x00garbage")
    assert f"cannot read the map file {path}" in _cli_error(capsys, "train", *QUICK, "--env", str(path),
                                                            "--out", str(tmp_path))


def test_a_bug_says_how_to_see_its_traceback_and_debug_shows_it(tmp_path, capsys, monkeypatch):
    import oapo_lite.neural.train

    def broken(*args, **kwargs):
        raise KeyError("a bug")

    monkeypatch.setattr(oapo_lite.neural.train, "train", broken)
    argv = ["train", *QUICK, "--out", str(tmp_path)]
    assert cli.main(argv) == 1
    err = capsys.readouterr().err
    assert "error: KeyError: 'a bug' (a bug in oapo_lite? rerun with --debug" in err and "Traceback" not in err
    with pytest.raises(KeyError):
        cli.main([*argv, "--debug"])
    monkeypatch.setenv("OAPO_DEBUG", "1")
    with pytest.raises(KeyError):
        cli.main(argv)


@pytest.mark.parametrize("argv, words", [
    (["--workers", "0"], ["--workers", "'0' is invalid", "integer >= 1"]),
    (["--workers", "-3"], ["'-3' is invalid"]),
    (["--budget", "huge"], ["unknown budget 'huge'", "smoke"]),
])
def test_a_bad_reproduce_option_is_one_line(capsys, argv, words):
    err = _cli_error(capsys, "reproduce", *argv)
    for word in words:
        assert word in err


@pytest.mark.parametrize("target", ["a_file", "/proc/no_such"])
def test_oapo_figures_that_cannot_be_written_is_one_line(tmp_path, capsys, monkeypatch, target):
    (tmp_path / "a_file").write_text("x")
    target = target if target.startswith("/") else str(tmp_path / target)
    monkeypatch.setenv("OAPO_FIGURES", target)
    err = _cli_error(capsys, "reproduce", "--skip-notebooks")
    assert f"OAPO_FIGURES='{target}'" in err and "cannot write results" in err \
        or f"OAPO_FIGURES '{target}' is a file; allowed: a folder" in err


@pytest.mark.parametrize("damage", [
    lambda b: b[:100],  # truncated
    lambda b: b"",  # empty
    lambda b: np.random.default_rng(0).bytes(5000),  # random bytes
])
def test_a_damaged_checkpoint_is_named_with_what_to_do(tmp_path, capsys, damage):
    argv = ["train", *QUICK, "--out", str(tmp_path)]
    assert cli.main(argv) == 0
    (run,) = tmp_path.iterdir()
    ck = run / "checkpoint.pt"
    ck.write_bytes(damage(ck.read_bytes()))
    err = _cli_error(capsys, *argv)
    assert f"checkpoint {ck} is damaged" in err and "--no-resume" in err
    assert cli.main([*argv, "--no-resume"]) == 0  # what the message says works
    load_checkpoint(run)


def test_reproduce_trains_a_run_with_a_damaged_checkpoint_again(tmp_path, capfd):
    cfg = TrainConfig(algo="oappo", **SMALL)
    rows, error = train_job(cfg, str(tmp_path / "fresh"))
    (tmp_path / "damaged").mkdir()
    (tmp_path / "damaged" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    again, error_again = train_job(cfg, str(tmp_path / "damaged"))
    assert error is None and error_again is None
    pd.testing.assert_frame_equal(learning(rows), learning(again))
    assert f"checkpoint {tmp_path / 'damaged' / 'checkpoint.pt'} is damaged" in capfd.readouterr().err


@pytest.mark.parametrize("damage", ["truncate", "garbage", "delete"])
def test_a_finished_run_with_a_damaged_results_csv_rewrites_it_from_its_checkpoint(tmp_path, damage):
    cfg = TrainConfig(algo="happo", **SMALL)
    train(cfg, tmp_path, progress=False)
    path = tmp_path / "results.csv"
    good = path.read_bytes()
    {"truncate": lambda: path.write_bytes(good[:200]), "garbage": lambda: path.write_bytes(b"\x00\xff" * 50),
     "delete": path.unlink}[damage]()
    train(cfg, tmp_path, progress=False)
    assert path.read_bytes() == good


def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    (cfg,) = [c for _, c in figures.figure_runs("fig1", "smoke")]
    assert experiments.run_all("smoke", figures=("fig1",), workers=1, progress=False).done == 1
    return cfg, experiments.run_path(cfg, "smoke")


@pytest.mark.parametrize("damage, words", [
    (lambda df, p: p.write_bytes(b"\x89PNG\x00\xff" * 40), "damaged"),
    (lambda df, p: p.write_bytes(b""), "damaged"),
    (lambda df, p: df.iloc[:1].to_csv(p, index=False), "it has 1 rows where the config has 3 evaluations"),
    (lambda df, p: df.assign(step=df["step"].where(df.index != 1)).to_csv(p, index=False), "evaluation steps"),
    (lambda df, p: df.drop(columns="eval_return").to_csv(p, index=False), r"lacks the columns \['eval_return'\]"),
    (lambda df, p: df.assign(seed=7).to_csv(p, index=False), "another run's rows"),
])
def test_the_run_cache_is_checked_when_read_and_a_damaged_run_is_trained_again(tmp_path, monkeypatch, capsys,
                                                                              damage, words):
    cfg, path = _cache(tmp_path, monkeypatch)
    good = learning(pd.read_csv(path))
    damage(pd.read_csv(path), path)
    with pytest.raises(store.DamagedFile, match=f"run file {re.escape(str(path))} .*{words}"):
        experiments.load_figure("fig1", "smoke")
    assert experiments.missing_runs("fig1", "smoke")[0].cfg == cfg
    assert f"warning: run file {path}" in capsys.readouterr().err
    count = experiments.run_all("smoke", figures=("fig1",), workers=1, progress=False)
    assert (count.done, count.cached) == (1, 0)
    pd.testing.assert_frame_equal(learning(pd.read_csv(path)), good)
    assert experiments.load_figure("fig1", "smoke")["step"].is_monotonic_increasing


def test_a_second_trainer_of_a_run_waits_and_then_trains_nothing_again(tmp_path, capfd):
    """Two ``reproduce`` on one cache train a run in the same checkpoint folder: the second
    waits for the first's lock, then resumes from its finished checkpoint."""
    cfg = TrainConfig(algo="oappo", **SMALL)
    first = train(cfg, tmp_path, progress=False)
    held = store.Lock(tmp_path / ".lock")
    assert held.acquire(wait=False)
    iterations, result = [], {}
    second = threading.Thread(target=lambda: result.update(rows=train(cfg, tmp_path, progress=False,
                                                                      callback=iterations.append)))
    second.start()
    time.sleep(1.0)
    assert second.is_alive() and "waiting for another process that is training" in capfd.readouterr().err
    held.release()
    second.join(30)
    assert not second.is_alive() and iterations == []
    pd.testing.assert_frame_equal(first, result["rows"])


def test_a_killed_writers_temporary_files_are_removed_by_the_next_write(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    target = tmp_path / "results.csv"
    stale = [tmp_path / f".results.csv.tmp{pid}", store._tmp_name(target, pid)]
    alive = store._tmp_name(target, os.getppid())  # a writer still at work keeps its file
    for path in (*stale, alive):
        path.write_text("half a file")
    store.atomic_write(lambda p: open(p, "w").write("whole"), target)
    assert target.read_text() == "whole" and alive.exists() and not any(p.exists() for p in stale)


def test_a_killed_reproduce_driver_takes_its_workers_with_it(tmp_path):
    env = {**os.environ, "OAPO_FIGURES": str(tmp_path)}
    driver = subprocess.Popen([sys.executable, "-c", "from oapo_lite.study.runs import experiments; "
                               "experiments.run_all('paper', figures=('fig3b',), workers=2, progress=False)"],
                              env=env, stderr=subprocess.DEVNULL)
    def children() -> list[int]:
        return [int(p) for task in os.listdir(f"/proc/{driver.pid}/task")
                for p in open(f"/proc/{driver.pid}/task/{task}/children").read().split()]

    deadline = time.time() + 120
    while time.time() < deadline and len(children()) < 3:  # resource tracker + 2 workers
        time.sleep(0.2)
    pids = children()
    assert len(pids) >= 3
    time.sleep(3)  # the workers are training
    driver.send_signal(signal.SIGKILL)
    driver.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(os.path.exists(f"/proc/{p}") and _not_zombie(p) for p in pids):
        time.sleep(0.2)
    assert not [p for p in pids if os.path.exists(f"/proc/{p}") and _not_zombie(p)]


def _not_zombie(pid: int) -> bool:
    try:
        return open(f"/proc/{pid}/stat").read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_checkpoint_errors_name_the_seats_of_a_numpy_integer_learner(tmp_path):
    state = RunState.start(TrainConfig(algo="happo", **SMALL))
    err = _diverged_at(Diverged("the PPO loss (Eq. 8)", np.int64(1)), state, tmp_path)
    assert "learner 1 (seats ['black'])" in str(err) and "iteration 1 of happo" in str(err)


@pytest.mark.parametrize("bad, words", [
    (dict(n_envs=4.0), ["n_envs = 4.0", "an integer >= 1"]),
    (dict(steps=200.0), ["steps = 200.0", "an integer >= 1"]),
    (dict(hidden=(64.0,)), ["hidden = (64.0,)", "positive integers"]),
    (dict(hidden=64), ["hidden = 64", "sequence"]),
    (dict(steps="abc"), ["steps = 'abc'", "an integer"]),
    (dict(steps=None), ["steps = None", "an integer"]),
    (dict(reuse_lambda=None), ["reuse_lambda = None", "[0, 1]"]),
    (dict(sigma="0.1"), ["sigma = '0.1'", ">= 0"]),
    (dict(lr=float("nan")), ["lr = nan", "a number > 0 and below 3.4e38"]),
    (dict(seed=True), ["seed = True", "an integer in [0, 4294967295]"]),
    (dict(seed=2**32), ["seed = 4294967296", "an integer in [0, 4294967295]", "would replay seed 0"]),
    (dict(seed=-1), ["seed = -1", "an integer in [0, 4294967295]"]),
    (dict(networks=0), ["networks = 0", "None or one of ['agent', 'type', 'one']"]),
    (dict(networks="team"), ["networks = 'team'", "None or one of ['agent', 'type', 'one']"]),
    (dict(algo="mappo", update_by="seat"), ["update_by = 'seat'", "'net' with algo 'mappo'"]),
    (dict(entropy_by_weight=1), ["entropy_by_weight = 1", "True or False"]),
    (dict(algo="oatrpo", entropy_by_weight=True), ["entropy_by_weight = True", "False with algo 'oatrpo'"]),
    (dict(entropy_coef=0.0, entropy_by_weight=True), ["entropy_by_weight = True", "entropy_coef 0.0"]),
    (dict(algo="seac", feature_norm=True), ["feature_norm = True", "False with algo 'seac'"]),
    (dict(env=None), ["env = None", "map"]),
    (dict(env=""), ["env = ''", "map"]),
    (dict(env_fn=5), ["env_fn = 5", "callable"]),
    (dict(allowed=[[True, False], [True]]), ["allowed", "(n, n) bool mask"]),
    (dict(allowed=[[1, 0, 1], [0, 1, 1]]), ["allowed", "(n, n) bool mask"]),
    (dict(reuse_adapt=["gradient"]), ["reuse_adapt", "gradient_test"]),
])
def test_a_config_value_of_the_wrong_type_is_named(bad, words):
    with pytest.raises(ValueError) as err:
        TrainConfig(**bad)
    for word in words:
        assert word in str(err.value)


def test_numpy_scalars_are_valid_config_values():
    cfg = TrainConfig(steps=np.int64(3200), seed=np.int32(1), reuse_lambda=np.float64(0.5), hidden=(np.int64(32),))
    assert cfg.hidden == (32,) and cfg.n_iterations == 2


# ---------------------------------------------------------------- issue 34: values a run cannot honour


def test_a_bool_flag_reads_false_as_false(tmp_path, capsys):
    assert cli.main(["train", *QUICK, "--out", str(tmp_path), "--lr-anneal", "false", "--value-norm", "false"]) == 0
    rows = pd.read_csv(next(tmp_path.glob("*/results.csv")))
    assert (rows["lr_anneal"] == False).all() and (rows["value_norm"] == False).all()  # noqa: E712


def test_help_exits_0_and_an_unknown_command_names_the_commands(capsys):
    assert cli.main(["--help"]) == 0 and "python -m oapo_lite train" in capsys.readouterr().out
    assert cli.main(["trian"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'trian'" in err and "['train', 'reproduce', 'book']" in err


@pytest.mark.parametrize("algo", sorted(ALGOS))
def test_a_config_refuses_a_value_in_a_field_its_algorithm_does_not_read(algo):
    """Every field of the algorithm-specific groups: a non-default value is refused exactly
    when ``readers`` does not list the algorithm (on the maze with 2 seats: a 2 x 2 mask)."""
    changed = dict(sigma=0.5, reuse_lambda=0.4, kl_reduce="mean", reuse_mode="sample", allowed="UR",
                   reuse_warmup=2, kl_threshold=0.02, cg_iters=3, cg_damping=0.2, line_search_steps=4,
                   backtrack=0.5, accept_ratio=0.3, n_step=10, a2c_lr=1e-3, a2c_adam_eps=1e-4,
                   a2c_max_grad_norm=1.0, seac_lambda=0.5, seps_clusters=1, seps_pretrain_steps=30_000)
    for name, value in changed.items():
        extra = dict(steps=100_000) if name == "seps_pretrain_steps" else {}
        if algo in readers(name):
            TrainConfig(algo=algo, **{name: value}, **extra)
        else:
            with pytest.raises(ValueError, match=f"{name} = .* with algo '{algo}'; only .* read it"):
                TrainConfig(algo=algo, **{name: value}, **extra)


@pytest.mark.parametrize("route, max_steps, words", [
    (100, 50, ["max_steps = 50", "longest shortest route is 100 moves", "max_steps >= 100"]),
    (150, 200, ["best team return is -0.5", "routes shorter than 100 moves"]),
])
def test_a_maze_beyond_the_time_limit_or_without_a_positive_optimum_is_refused(tmp_path, capsys, route, max_steps,
                                                                                words):
    row = "#R" + "." * (route - 1) + "*#"
    path = tmp_path / "corridor.txt"
    path.write_text(f"agents: red\nstart: 1,1\n{'#' * len(row)}\n{row}\n{'#' * len(row)}\n")
    err = _cli_error(capsys, "train", *QUICK, "--out", str(tmp_path / "out"), "--env", str(path),
                     "--max-steps", str(max_steps))
    assert all(w in err for w in words) and not (tmp_path / "out").exists()  # refused before a run folder


# ---------------------------------------------------------------- issue 34: resources


def test_resource_errors_name_what_ran_out_and_what_to_do(tmp_path, monkeypatch):
    from oapo_lite.cli import resource_error

    assert "no space left on the device: /x/y" in resource_error(OSError(errno.ENOSPC, "full", "/x/y"))
    assert "out of memory" in resource_error(MemoryError("Unable to allocate 5 TiB"))
    assert "permission denied" in resource_error(PermissionError(errno.EACCES, "no", "/x"))
    assert resource_error(ValueError("a bad value")) is None
    # torch.save on a full disk raises RuntimeError("... unexpected pos ..."): the write names the device
    monkeypatch.setattr(store.shutil, "disk_usage", lambda p: shutil._ntuple_diskusage(1, 1, 0))

    def torch_on_a_full_disk(tmp):
        raise RuntimeError("[enforce fail at inline_container.cc:626] . unexpected pos 64 vs 0")

    with pytest.raises(OSError) as caught:
        store.atomic_write(torch_on_a_full_disk, tmp_path / "checkpoint.pt")
    assert caught.value.errno == errno.ENOSPC and "no space left" in resource_error(caught.value)
    assert not list(tmp_path.iterdir())  # no temporary file left behind


def test_a_full_disk_is_one_line(tmp_path, capsys):
    """A real full disk: a 256 KiB tmpfs as the output folder (needs root to mount)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here (not root)")
    try:
        err = _cli_error(capsys, "train", *QUICK, "--out", str(disk), "--hidden", "512", "512")
        assert "no space left on the device" in err and "--out" in err
    finally:
        subprocess.run(["umount", str(disk)], check=True)


# ---------------------------------------------------------------- issue 34: an interrupt stops the work


def _children(pid: int) -> dict[int, int]:
    """Every live process under ``pid`` (children, grandchildren, ...) and its parent, from /proc."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended while we looked
            continue
        if fields[0] != "Z":
            parents[int(stat.parent.name)] = int(fields[1])
    found, frontier = {}, [pid]
    while frontier:
        parent = frontier.pop()
        for child, its_parent in parents.items():
            if its_parent == parent and child not in found:
                found[child] = parent
                frontier.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _outliving(pids, sent: float) -> list[int]:
    """The processes of ``pids`` still alive ``STOP_LIMIT_S`` after the signal was sent."""
    while time.time() < sent + STOP_LIMIT_S and [pid for pid in pids if _alive(pid)]:
        time.sleep(0.1)
    return [pid for pid in pids if _alive(pid)]


def _kill(*pids: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


# Runs of 1M MuJoCo steps (App. A at the cpu budget, minutes each): a driver that waited for its
# runs, or let a queued one start, would be caught. A healthy stop kills the workers at once; the
# limits below leave a slow, loaded machine ten times what that needs.
STOP_LIMIT_S = 15


@pytest.mark.parametrize("signals, to_group", [((signal.SIGINT,), True), ((signal.SIGTERM,), False),
                                               ((signal.SIGINT, signal.SIGINT), True)],
                         ids=["ctrl-c to the process group", "sigterm to the driver", "ctrl-c twice"])
def test_an_interrupted_reproduce_kills_its_workers_at_once_and_starts_no_queued_run(tmp_path, signals, to_group):
    env = {**os.environ, "OAPO_FIGURES": str(tmp_path)}
    driver = subprocess.Popen([sys.executable, "-m", "oapo_lite", "reproduce", "--budget", "cpu", "--figures",
                               "figA_mamujoco", "--skip-notebooks", "--workers", "2", "--check"],
                              env=env, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    started = tmp_path / "data" / "checkpoints"
    deadline = time.time() + 300
    while time.time() < deadline and not (started.exists() and len(list(started.iterdir())) >= 2):
        time.sleep(0.2)
    time.sleep(2)  # both workers are training
    workers = _children(driver.pid)
    try:
        assert len([p for p, parent in workers.items() if parent == driver.pid]) >= 2, workers
        for i, sig in enumerate(signals):
            (os.killpg if to_group else os.kill)(driver.pid, sig)
            sent = sent if i else time.time()
            time.sleep(0.05)
        _, err = driver.communicate(timeout=4 * STOP_LIMIT_S)
        assert driver.returncode == 130 and time.time() - sent < STOP_LIMIT_S, err
        assert not _outliving(workers, sent)  # no worker, nor anything it started
    finally:  # a failed stop leaves nothing running either
        _kill(driver.pid, *workers)
    assert "run the same command again to resume" in err and "Traceback" not in err
    assert len(list(started.iterdir())) == 2  # no queued run started


def _sleep_with_a_child(seconds: float) -> None:
    """A job that runs ``seconds`` in a child process it starts, as a notebook runs in its kernel."""
    subprocess.run([sys.executable, "-c", f"import time; time.sleep({seconds})"], check=True)


def _sleeping_driver(out: Path) -> None:
    from oapo_lite.study.runs.executors import in_processes

    jobs = [(k, (60.0,)) for k in range(5)]
    for _ in in_processes(_sleep_with_a_child, jobs, workers=2):
        out.write_text("a job finished")


def test_stopping_the_process_pool_kills_what_its_jobs_started_and_starts_no_queued_job(tmp_path):
    """The notebook stage's pool: a job's own children (a kernel) die with it."""
    script = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import signal; "
              "signal.signal(signal.SIGTERM, signal.default_int_handler); "
              f"from test_bad_input_and_damage import _sleeping_driver; from pathlib import Path; "
              f"_sleeping_driver(Path({str(tmp_path / 'finished')!r}))")
    driver = subprocess.Popen([sys.executable, "-c", script], start_new_session=True, stderr=subprocess.PIPE,
                              text=True)
    deadline = time.time() + 120
    while time.time() < deadline and sum(len(_children(w)) for w in _children(driver.pid)) < 2:
        time.sleep(0.2)  # both workers have started their job's child
    below = _children(driver.pid)
    try:
        assert len(below) >= 4, below  # two workers, a child each
        os.kill(driver.pid, signal.SIGTERM)
        sent = time.time()
        _, err = driver.communicate(timeout=4 * STOP_LIMIT_S)
        assert time.time() - sent < STOP_LIMIT_S and "KeyboardInterrupt" in err
        assert not _outliving(below, sent) and not (tmp_path / "finished").exists()
    finally:
        _kill(driver.pid, *below)


# ---------------------------------------------------------------- issue 34: notebooks and the library


def test_a_misspelled_notebook_parameter_stops_the_first_cell_naming_it(tmp_path):
    from oapo_lite.study.runs.reproduce import NOTEBOOKS, NotebookFailed, run_notebook

    with pytest.raises(NotebookFailed, match=r"cell 4 .*unknown notebook parameter\(s\) \['budgte'\]; this "
                                             r"notebook takes \['budget'\]"):
        run_notebook(NOTEBOOKS / "10_mazes_fig3a_5a.ipynb", tmp_path / "out.ipynb", {"budgte": "smoke"})


def test_every_notebook_checks_its_parameters_right_after_them():
    import nbformat

    from oapo_lite.study.runs.reproduce import NOTEBOOKS

    for path in sorted(NOTEBOOKS.glob("[0-9]*.ipynb")):
        cells = nbformat.read(path, as_version=4).cells
        for i, cell in enumerate(cells):
            if "parameters" in cell.metadata.get("tags", []):
                names = re.findall(r"^(\w+)\s*=", cell.source, re.M)
                call = f"check_parameters({', '.join(map(repr, names))})"
                assert call in cells[i + 1].source.split("\n", 3)[2], (path.name, call)


def test_the_run_cache_refuses_another_configs_rows_and_text_in_a_number_column(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    ten, one = (TrainConfig(algo="oappo", sigma=s, **SMALL) for s in (10.0, 1.0))
    fakes.write_run(ten, "smoke", lambda s: s / 400)
    experiments.read_run(ten, "smoke")  # whole and its own
    shutil.copy(experiments.run_path(ten, "smoke"), experiments.run_path(one, "smoke"))
    with pytest.raises(store.DamagedFile, match=r"another run's rows: its sigma column does not say 1.0"):
        experiments.read_run(one, "smoke")
    path = experiments.run_path(ten, "smoke")
    pd.read_csv(path).assign(eval_return="lots").to_csv(path, index=False)
    with pytest.raises(store.DamagedFile, match=r"its eval_return column at row 1 \(step 0\) holds 'lots'; allowed: "
                                                r"a number \(finite\); empty only where no evaluation episode ended"):
        experiments.read_run(ten, "smoke")


M_JSON = "[[0.7, 0.3], [0.3, 0.7]]"


@pytest.mark.parametrize("column, damage, words", [
    ("frac_opt", lambda v: v.where(v.index < len(v) - 4, np.nan), r"frac_opt column at row 8 \(step 1400\) is empty; allowed: a "
                                                                   r"number \(a maze's evaluation episodes always end\)"),
    ("frac_opt", lambda v: v.where(v.index != 3, np.inf), r"frac_opt column at row 4 \(step 600\) holds inf; "
                                                          r"allowed: a number <= 1.00001"),
    ("frac_opt", lambda v: v * 10, r"frac_opt column at row 3 \(step 400\) holds 2.0; allowed: a number <= 1"),
    ("frac_opt", lambda v: v * 0.5, r"frac_opt column at row 2 .* allowed: eval_return / the maze's optimum = 0.1"),
    ("eval_success", lambda v: v - 1, r"eval_success column at row 1 \(step 0\) holds -1.0; allowed: a number in "
                                      r"\[0, 1\]"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[1]"), r"reuse_matrix column at row 3 .* allowed: a square matrix"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, '"text"'), r"reuse_matrix column at row 3 \(step 400\) holds "
                                                               r"'text'; allowed: a square matrix"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[[0.7, 0.4], [0.3, 0.7]]"), r"rows summing to 1"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]"),
     r"the same number of seats in every matrix \(\[2, 3\] here\)"),
    ("reuse_matrix", lambda v: v.where(v.index != 2, "[[0.7, 0.3]"), r"its reuse_matrix column at row 3 holds "
                                                                    r"'\[\[0.7, 0.3\]', which is not JSON"),
    ("iteration", lambda v: v + 1, r"iteration column at row 1 \(step 0\) holds 1; allowed: step / .* = 0"),
    ("peer_share", lambda v: v.where(v.index == 0, 1.5), r"peer_share column at row 2 .* holds 1.5; allowed: a "
                                                        r"number in \[0, 1.00001\]"),
    ("value_loss", lambda v: v.where(v.index != 3, np.nan), r"value_loss column at row 4 .* empty only at the "
                                                           r"evaluation before the first iteration"),
    ("extra", lambda v: 1.0, r"columns no results row holds: \['extra'\]"),
])
def test_a_run_file_with_a_value_out_of_its_columns_range_is_refused_naming_file_column_and_row(
        tmp_path, monkeypatch, column, damage, words):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    cfg = TrainConfig(algo="oappo", **dict(SMALL, steps=2000))
    n = len(cfg.eval_steps)
    fakes.write_run(cfg, "smoke", lambda s: s / 2000, grid=1, value_loss=[np.nan] + [0.5] * (n - 1),
                    peer_share=[np.nan] + [0.3] * (n - 1), reuse_matrix=[np.nan] + [M_JSON] * (n - 1))
    experiments.read_run(cfg, "smoke")  # whole
    path = experiments.run_path(cfg, "smoke")
    df = pd.read_csv(path)
    df[column] = damage(df[column]) if column in df else damage(None)
    df.to_csv(path, index=False)
    with pytest.raises(store.DamagedFile, match=f"run file {re.escape(str(path))} .*{words}"):
        experiments.read_run(cfg, "smoke")
    assert not experiments.on_disk(cfg, "smoke")  # so reproduce trains it again


def test_an_engine_evaluation_may_be_empty_and_every_verdict_says_so():
    runs = pd.DataFrame({"label": ["a"] * 8 + ["b"] * 8, "seed": ([0] * 4 + [1] * 4) * 2,
                         "step": list(range(4)) * 4,
                         "eval_success": [0, .5, .9, np.nan, 0, .5, .9, 1, 0, .1, .1, .1, 0, .1, .2, .1]})
    rows = evidence.per_run(runs, dataclasses.replace(WIN_RATE, tail=0.5))
    # the window: 3 evaluations at least, of those that hold a value
    assert rows["gaps"].tolist() == [1, 0, 0, 0] and rows["final"].iloc[0] == pytest.approx(np.mean([0, 0.5, 0.9]))
    v = verdicts.check(evidence.Evidence(runs, WIN_RATE), Claim("a ends above b", "higher", ("a", "b")))
    assert v.empty == (("a", 1),)
    assert words.reason(v).endswith("1 of a's evaluations hold no value (no evaluation episode ended) and are left out")
    with pytest.raises(ValueError, match=r"curve 'a' has two rows for seed 0 at step 1"):
        evidence.per_run(pd.concat([runs, runs.iloc[[1]]]), WIN_RATE)


def test_a_checkpoint_whose_record_contradicts_itself_is_named_as_damaged(tmp_path):
    cfg = TrainConfig(algo="happo", **SMALL)
    train(cfg, tmp_path, progress=False)
    ck = load_checkpoint(tmp_path)
    for broken, words in (({**ck, "rows": []}, "evaluation rows are missing"),
                          ({**ck, "history": ck["history"][:-1]}, "at iteration 2 but holds 1 history entries"),
                          ({**ck, "rows": ck["rows"][::-1]}, r"rows are at iterations \[2, 1, 0\]")):
        torch.save(broken, tmp_path / "checkpoint.pt")
        with pytest.raises(store.DamagedFile, match=f"checkpoint {tmp_path}/checkpoint.pt is damaged: .*{words}"):
            train(cfg, tmp_path, progress=False)


def test_reading_results_never_writes(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    for label, cfg in figures.figure_runs("fig1", "smoke"):
        fakes.write_run(cfg, "smoke", lambda s: s / 400)
    written = []
    monkeypatch.setattr(store, "atomic_write", lambda *a: written.append(a))
    assert len(experiments.load_figure("fig1", "smoke")) and written == []
    monkeypatch.undo()
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    assert experiments.export_figure("fig1", "smoke") == experiments.data_dir("smoke") / "fig1.csv"
    assert experiments.export_figure("fig1", "smoke") is None  # unchanged: left alone


def test_the_statistics_take_a_frame_with_no_run(tmp_path):
    empty = pd.DataFrame()
    assert evidence.per_run(empty).empty and list(evidence.per_run(empty).columns) == evidence.PER_RUN_COLUMNS
    assert evidence.summary(empty).empty and evidence.intervals(empty).empty and tables.reuse_summary(empty).empty
    assert plotting.learning_curves(empty).texts[0].get_text() == "no runs on disk"
    assert np.isnan(statistics.probability_of_improvement([np.nan, np.nan], [1, 2]))
    assert statistics.probability_of_improvement([3, 1], [1, 2]) == 0.625  # (1 + 0.5 + 0 + 1) / 4: brute force


@pytest.mark.parametrize("args, words", [
    (("oappo", "runs"), "cfg must be a TrainConfig, got str"),
    ((TrainConfig(), None), "out_dir must be a folder path (a non-empty str or a Path), got NoneType"),
])
def test_train_names_an_argument_of_the_wrong_kind(args, words):
    with pytest.raises(TypeError, match=re.escape(words)):
        train(*args)


def test_what_the_env_cannot_honour_is_refused_before_a_run_folder(tmp_path):
    with pytest.raises(ValueError, match=r"allowed mask has shape \(1, 1\), expected \(2, 2\)"):
        train(TrainConfig(allowed=[[True]], **SMALL), tmp_path / "run")
    with pytest.raises(ValueError, match="seps_clusters = 5"):
        train(TrainConfig(algo="seps", seps_clusters=5, seps_pretrain_steps=200, **{**SMALL, "rollout_len": 50}),
              tmp_path / "run")
    assert not (tmp_path / "run").exists()
    with pytest.raises(TypeError, match="non-empty str"):
        train(TrainConfig(**SMALL), "")


def test_no_command_and_a_folder_as_map_are_one_line(tmp_path, capsys):
    assert cli.main([]) == 2 and "error: no command given" in capsys.readouterr().err
    assert "is a folder" in _cli_error(capsys, "train", *QUICK, "--out", str(tmp_path), "--env", str(tmp_path))
    board = tmp_path / "a_file"
    board.write_text("x")
    assert "is a file; allowed: a folder" in _cli_error(capsys, "train", *QUICK, "--out", str(tmp_path / "o"),
                                                        "--tensorboard", str(board))


def test_an_unreadable_checkpoint_is_not_called_damaged(tmp_path, monkeypatch):
    from oapo_lite.cli import resource_error
    from oapo_lite.neural import runstate

    (tmp_path / "checkpoint.pt").write_bytes(b"x")

    def denied(path, **kw):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(runstate.torch, "load", denied)
    with pytest.raises(PermissionError) as caught:
        load_checkpoint(tmp_path)
    assert resource_error(caught.value).startswith(f"permission denied: {tmp_path / 'checkpoint.pt'}; fix its")


def test_a_full_disk_stops_reproduce_with_one_line(tmp_path):
    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here (not root)")
    try:
        done = subprocess.run([sys.executable, "-m", "oapo_lite", "reproduce", "--budget", "smoke", "--figures",
                               "fig1", "--skip-notebooks", "--workers", "1", "--check"],
                              env={**os.environ, "OAPO_FIGURES": str(disk)}, capture_output=True, text=True, timeout=300)
    finally:
        subprocess.run(["umount", str(disk)], check=True)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.strip().splitlines()[-1].startswith("error: no space left on the device: ")


def test_the_api_names_bad_arguments(tmp_path, monkeypatch):
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    for label, cfg in figures.figure_runs("fig1", "smoke"):
        fakes.write_run(cfg, "smoke", lambda s: s / 400)
    assert experiments.run_all("smoke", figures="fig1", workers=1, progress=False).cached == 1  # one name is a figure
    for workers in (0, -3, "2", True):
        with pytest.raises(ValueError, match=f"workers = {re.escape(repr(workers))} is invalid"):
            experiments.run_all("smoke", figures=["fig1"], workers=workers)
    with pytest.raises(TypeError, match="must be a pandas DataFrame"):
        evidence.summary(None)
    with pytest.raises(ValueError, match=r"square \(n, n\) matrix"):
        plotting.reuse_heatmap(np.array([]))
    assert plotting.final_bars(pd.DataFrame()).texts[0].get_text() == "no runs on disk"


def test_every_notebook_names_its_kernel():
    """papermill without -k reads the kernel from the notebook."""
    import nbformat

    from oapo_lite.study.runs.reproduce import NOTEBOOKS

    for path in sorted(NOTEBOOKS.glob("[0-9]*.ipynb")):
        assert nbformat.read(path, as_version=4).metadata.get("kernelspec", {}).get("name") == "python3", path.name


def test_the_second_audits_cases_are_refused(tmp_path, capsys, monkeypatch):
    """Found by a second hostile audit after the first fixes."""
    from oapo_lite.study.report import book

    assert "--budget is given 2 times" in _cli_error(capsys, "reproduce", "--budget", "smoke", "--budget", "cpu")
    assert "--inplace writes" in _cli_error(capsys, "reproduce", "--inplace", "--skip-notebooks")
    afile = tmp_path / "site"
    afile.write_text("x")
    assert "is a file; allowed: a folder" in _cli_error(capsys, "book", "--out", str(afile))
    mine = tmp_path / "book-src" / "precious.txt"
    mine.parent.mkdir()
    mine.write_text("keep me")
    with pytest.raises(ValueError, match="was not written by the book"):
        book.build(tmp_path / "book")
    assert mine.read_text() == "keep me"
    with pytest.raises(TypeError, match="resume must be True or False, got 'false'"):
        train(TrainConfig(**SMALL), tmp_path / "r", resume="false")
    with pytest.raises(ValueError, match=r"lack the columns \['label', 'seed', 'step', 'frac_opt'\]"):
        evidence.summary(pd.DataFrame({"a": [1]}))
    with pytest.raises(ValueError, match="with NaN or inf"):
        plotting.reuse_heatmap(np.full((2, 2), np.nan))
    monkeypatch.setenv("OAPO_FIGURES", "")
    assert experiments.figures_dir("paper") == experiments.ROOT / "figures"  # empty counts as unset


def test_a_bad_budget_value_stops_the_first_cell(tmp_path):
    from oapo_lite.study.runs.reproduce import NOTEBOOKS, NotebookFailed, run_notebook

    with pytest.raises(NotebookFailed, match=r"cell 4 .*unknown budget 'nope'"):
        run_notebook(NOTEBOOKS / "10_mazes_fig3a_5a.ipynb", tmp_path / "out.ipynb", {"budget": "nope"})


@pytest.mark.parametrize("command", ["train", "reproduce", "book"])
def test_every_flag_says_what_it_means_its_default_and_what_it_allows(command):
    from oapo_lite.neural.config import ALLOWED, MEANING
    from oapo_lite.study.runs import reproduce
    from oapo_lite.study.report import book

    parsers = {"train": cli.train_parser, "reproduce": reproduce.command_line, "book": book.command_line}
    for action in parsers[command]()._actions:
        if action.help == argparse.SUPPRESS or action.dest == "help":  # a renamed flag's error; -h itself
            continue
        assert action.help and re.fullmatch(r"\S.* \(default: [^;]+(; allowed: .+)?\)", action.help), (command, action.dest)
        if action.nargs != 0:  # a flag with a value says what it allows
            assert "; allowed: " in action.help, (command, action.dest)
        if command == "train" and action.dest in MEANING:  # from the field's one home
            assert action.help.startswith(MEANING[action.dest]) and (ALLOWED[action.dest] in action.help
                                                                     or action.dest == "env")


def test_a_lock_that_is_a_folder_is_one_line_in_train_and_in_reproduce(tmp_path, capsys, monkeypatch):
    from oapo_lite.study.runs import reproduce

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path / "figures"))
    (cfg,) = [cfg for _, cfg in figures.figure_runs("fig1", "smoke")]
    lock = experiments.runs_dir("smoke") / "checkpoints" / cfg.run_id() / ".lock"
    lock.mkdir(parents=True)
    assert reproduce.main(["--budget", "smoke", "--figures", "fig1", "--skip-notebooks", "--check"]) == 1
    err = capsys.readouterr().err
    assert f"error: the lock file {lock} is a folder; delete it" in err and "Traceback" not in err
    out = tmp_path / "runs"
    quick = TrainConfig(n_envs=8, rollout_len=25, steps=400, eval_episodes=4)  # QUICK's run
    (out / quick.run_id() / ".lock").mkdir(parents=True)
    assert "is a folder; delete it" in _cli_error(capsys, "train", *QUICK, "--out", str(out))


def test_the_tables_take_no_rows_and_name_what_they_lack():
    from oapo_lite.study.report import claims

    none = pd.DataFrame(columns=claims.GLANCE_COLUMNS + ["n_claims", "one_seed"])
    assert claims.summary(none).empty and claims.summary_lines(none) == []
    assert claims.readme_markdown(none).endswith("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for table in (claims.summary, claims.summary_lines, claims.readme_markdown):
        with pytest.raises(ValueError, match=r"summary counts glance_table\(\)'s rows"):
            table(pd.DataFrame())
    assert tables.reuse_table(pd.DataFrame(), WIN_RATE).empty
    with pytest.raises(ValueError, match=r"no runs labelled \['a', 'b'\] to pair; the runs' labels are \[\]"):
        evidence.Evidence(pd.DataFrame()).pairs("a", "b")
    one = pd.DataFrame({"label": ["a"], "seed": [0], "step": [0], "frac_opt": [1.0]})
    with pytest.raises(ValueError, match=r"no runs of the curves \['nonexistent'\] to draw; the data's curves are "
                                         r"\['a'\]"):
        plotting.learning_curves(one, order=["nonexistent"])


def test_a_map_header_after_its_grid_is_named():
    from oapo_lite.envs.maps import MapError, parse_maze

    with pytest.raises(MapError, match=r"has its 'agents' line after the grid; the header lines .* come first"):
        parse_maze("start: 1,1\n###\n#*#\n###\nagents: red")


def _ck_damage(kind):
    def damage(ck):
        if kind == "no step":
            del ck["step"]
        elif kind == "step None":
            ck["step"] = None
        elif kind == "no learner":
            ck.pop("learner")
        elif kind == "config text":
            ck["config"] = "abc"
        elif kind == "weight shape":
            key = next(iter(ck["actors"]))
            ck["actors"][key] = torch.zeros(3, 3)
        elif kind == "rng garbage":
            ck["torch_rng"] = torch.zeros(3)
        elif kind == "env None":
            ck["env"] = None
        elif kind == "cost garbage":
            ck["cost"] = {"cpu_s": "lots"}
        return ck
    return damage


@pytest.mark.parametrize("kind, words", [
    ("no step", "is damaged: it has no entries ['step']"),
    ("step None", "entries ['step'] are not what a run writes there"),
    ("no learner", "it has no entries ['learner']"),
    ("config text", "entries ['config'] are not what a run writes there"),
    ("weight shape", "does not fit this run (RuntimeError"),
    ("rng garbage", "does not fit this run"),
    ("env None", "entries ['env'] are not what a run writes there"),
    ("cost garbage", "entries ['cost'] are not what a run writes there"),
])
def test_a_checkpoint_missing_or_garbling_an_entry_is_damaged_named_and_trained_again(tmp_path, capfd, kind, words):
    cfg = TrainConfig(algo="oappo", **SMALL)
    first, _ = train_job(cfg, str(tmp_path))
    path = tmp_path / "checkpoint.pt"
    torch.save(_ck_damage(kind)(load_checkpoint(tmp_path)), path)
    with pytest.raises(store.DamagedFile, match=f"checkpoint {re.escape(str(path))} .*{re.escape(words)}"):
        train(cfg, tmp_path, progress=False)
    again, error = train_job(cfg, str(tmp_path))  # reproduce's way: named, then trained again from the start
    assert error is None and words in capfd.readouterr().err
    pd.testing.assert_frame_equal(learning(first), learning(again))


@pytest.mark.parametrize("call, words", [
    (lambda: evidence.per_run(pd.DataFrame({"label": ["a"], "seed": [0], "step": [0], "frac_opt": ["x"]})),
     "'frac_opt' column holds text"),
    (lambda: evidence.per_run(pd.DataFrame(), threshold=float("nan")), "threshold = nan is invalid"),
    (lambda: evidence.per_run(pd.DataFrame(), dataclasses.replace(FRAC_OPT, tail=5)), "tail = 5 is invalid; allowed: a share"),
    (lambda: evidence.per_run(pd.DataFrame(), "frac_opt"), "metric must be a catalogue.metrics.Metric"),
    (lambda: evidence.Evidence(_two_curves().drop(columns="reuse_matrix")).pairs("a", "a"), "a and b are both 'a'"),
    (lambda: evidence.Evidence(_two_curves(b_seed=7).drop(columns="reuse_matrix")).pairs("a", "b"),
     "no seed has runs of both"),
    (lambda: tables.reuse_table(_two_curves().drop(columns="env"), FRAC_OPT), "lack the columns ['env', 'owner']"),
    (lambda: evidence.per_run(_two_curves()), "the runs hold reuse matrices but no owner column"),
    (lambda: claims_module().summary(None), "summary counts glance_table()'s rows"),
    (lambda: claims_module().summary(pd.DataFrame({"section": ["6.1"], "claim": ["c"], "verdict": ["held?"],
                                                   "n_claims": [1], "one_seed": [False]})),
     "verdicts ['held?'] that are no status"),
    (lambda: claims_module().markdown([1]), "markdown takes a DataFrame, got list"),
    (lambda: plotting.learning_curves([1]), "must be a pandas DataFrame"),
    (lambda: plotting.learning_curves(_two_curves().drop(columns="seed")), "lack the columns ['seed']"),
    (lambda: plotting.learning_curves(pd.concat([_two_curves()] * 2)), "has two rows for seed 0 at step 0"),
    (lambda: plotting.learning_curves(_two_curves().assign(frac_opt=np.nan)), "has no value of 'frac_opt' to draw"),
])
def test_a_library_call_with_wrong_input_names_it(call, words):
    with pytest.raises((ValueError, TypeError), match=re.escape(words)):
        call()


def claims_module():
    from oapo_lite.study.report import claims

    return claims


def _two_curves(b_seed: int = 0) -> pd.DataFrame:
    eye = np.eye(2)
    return pd.DataFrame({"label": ["a", "a", "b", "b"], "seed": [0, 0, b_seed, b_seed], "step": [0, 1, 0, 1],
                         "frac_opt": [0.1, 0.9, 0.2, 0.5], "env": "black_red", "reuse_matrix": [eye] * 4})


def test_markdown_keeps_a_cell_with_a_line_break_on_its_row():
    from oapo_lite.study.report import claims

    text = claims.markdown(pd.DataFrame({"a": ["one\ntwo", "x|y"]}))
    assert text.splitlines()[2:] == ["| one two |", "| x\\|y |"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_while_the_command_still_imports_is_one_line_and_130(tmp_path, sig):
    env = {**os.environ, "OAPO_FIGURES": str(tmp_path)}
    checked = 0
    for delay in (0.2, 0.6, 1.2, 2.0, 4.0):  # in the imports, while parsing, at the first run
        driver = subprocess.Popen([sys.executable, "-m", "oapo_lite", "reproduce", "--budget", "smoke", "--figures",
                                   "fig1", "--skip-notebooks", "--check"], env=env, start_new_session=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        os.killpg(driver.pid, sig)
        _, err = driver.communicate(timeout=60)
        if driver.returncode == 0:  # finished before the signal (a fast machine): nothing to show
            continue
        if driver.returncode == -sig and not err:  # a loaded machine: the signal came before the interpreter ran
            continue                               # any of the package, which no Python program can handle
        checked += 1
        assert driver.returncode == 130 and "Traceback" not in err and "run the same command again" in err, \
            (delay, driver.returncode, err)
    assert checked, "every signal came before the package ran or after the run ended: nothing was tested"
