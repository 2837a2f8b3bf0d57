"""Bad training input and damaged run folders: a config value, an argument of ``train`` or a
checkpoint that cannot be used is named with what to do; a damaged checkpoint is trained again
from the start; concurrent and killed writers leave nothing behind and train nothing twice."""
import errno
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from bad_input import NOT_A_FILE, QUICK, SMALL, cli_error, fifo, not_a_file
from oapo_lite import __main__ as cli, store
from oapo_lite.algorithms import ALGOS
from oapo_lite.neural.config import TrainConfig, readers
from oapo_lite.neural.losses import Diverged
from oapo_lite.neural.results import learning
from oapo_lite.neural.runstate import RunState, load_checkpoint
from oapo_lite.neural.train import _diverged_at, train
from oapo_lite.study.runs.executors import train_job


def test_resuming_past_the_asked_steps_names_no_resume(tmp_path, capsys):
    cfg = TrainConfig(algo="happo", **{**SMALL, "steps": 800})
    train(cfg, tmp_path / "run", progress=False)
    with pytest.raises(ValueError, match="--no-resume"):
        train(TrainConfig(algo="happo", **SMALL), tmp_path / "run", progress=False)
    with pytest.raises(ValueError, match="different config.*--no-resume"):
        train(TrainConfig(algo="happo", **{**SMALL, "steps": 800, "lr": 1e-3}), tmp_path / "run", progress=False)


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
    err = cli_error(capsys, *argv)
    assert f"checkpoint {ck} is damaged" in err and "--no-resume" in err
    assert cli.main([*argv, "--no-resume"]) == 0  # what the message says works
    load_checkpoint(run)


def test_reproduce_trains_a_run_with_a_damaged_checkpoint_again(tmp_path, capfd):
    cfg = TrainConfig(algo="oappo", **SMALL)
    rows, error, _ = train_job(cfg, str(tmp_path / "fresh"))
    (tmp_path / "damaged").mkdir()
    (tmp_path / "damaged" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    again, error_again, _ = train_job(cfg, str(tmp_path / "damaged"))
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
    first, _, _ = train_job(cfg, str(tmp_path))
    path = tmp_path / "checkpoint.pt"
    torch.save(_ck_damage(kind)(load_checkpoint(tmp_path)), path)
    with pytest.raises(store.DamagedFile, match=f"checkpoint {re.escape(str(path))} .*{re.escape(words)}"):
        train(cfg, tmp_path, progress=False)
    again, error, _ = train_job(cfg, str(tmp_path))  # reproduce's way: named, then trained again from the start
    assert error is None and words in capfd.readouterr().err
    pd.testing.assert_frame_equal(learning(first), learning(again))


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


# ---------------------------------------------------------------- issue 53: a checkpoint that is no file


@pytest.mark.parametrize("kind", ["FIFO", "socket", "folder"])
def test_a_checkpoint_that_is_no_regular_file_is_named_and_never_opened(tmp_path, kind):
    """torch.load on a FIFO blocked for ever, and so did the rerun its error advised."""
    cfg = TrainConfig(algo="oappo", **SMALL)
    what = NOT_A_FILE[kind]
    with not_a_file(tmp_path / "checkpoint.pt", kind) as path:
        with pytest.raises(store.NotAFile, match=re.escape(f"checkpoint {path} is {what}, not a file; delete or move it")):
            train(cfg, tmp_path, progress=False)
        with pytest.raises(store.NotAFile, match=re.escape(f"checkpoint {path} is {what}")):
            load_checkpoint(tmp_path)
    if kind != "FIFO":  # what the message says works
        shutil.rmtree(path) if path.is_dir() else path.unlink()
        assert len(train(cfg, tmp_path, progress=False)) == len(cfg.eval_steps)


def test_a_fifo_checkpoint_is_one_line_on_the_command_line(tmp_path, capsys):
    assert cli.main(["train", *QUICK, "--out", str(tmp_path)]) == 0
    (run,) = tmp_path.iterdir()
    (run / "checkpoint.pt").unlink()
    with fifo(run / "checkpoint.pt"):
        err = cli_error(capsys, "train", *QUICK, "--out", str(tmp_path))
    assert f"checkpoint {run / 'checkpoint.pt'} is a FIFO (named pipe), not a file; delete or move it" in err


# ---------------------------------------------------------------- issue 53: train's arguments, checked first


@pytest.mark.parametrize("kw, error, words", [
    (dict(callback="x"), TypeError, "train's callback must be None or callable with an iteration's metrics, got 'x'"),
    (dict(callback=5), TypeError, "train's callback must be None or callable"),
    (dict(timing=[]), TypeError, "train's timing must be None or a dict to fill with seconds per phase, got []"),
    (dict(tensorboard="/proc/x"), ValueError, "train's tensorboard '/proc/x' cannot be written (no such file or folder)"),
    (dict(tensorboard="a_file"), ValueError, "train's tensorboard 'a_file' is a file; allowed: a folder"),
    (dict(tensorboard="loop/x"), ValueError, "train's tensorboard 'loop/x' cannot be used: it runs through a loop"),
    (dict(progress="no"), TypeError, "train's progress must be True or False, got 'no'"),
])
def test_every_callback_and_folder_argument_of_train_is_checked_before_the_first_iteration(
        tmp_path, monkeypatch, kw, error, words):
    """Before issue 53 a callback failed after the first iteration and /proc/x raised a bare
    FileNotFoundError; now nothing is made, not even the run folder."""
    monkeypatch.chdir(tmp_path)
    Path("a_file").write_text("x")
    Path("loop").symlink_to("loop")
    with pytest.raises(error, match=re.escape(words)):
        train(TrainConfig(**SMALL), tmp_path / "run", **kw)
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------- issue 53: messages that name the real cause


@pytest.mark.parametrize("kw, words", [
    (dict(algo="seac", n_step=1000, steps=16_000), "steps = 16000 is invalid; allowed: >= n_envs * n_step = 32000"),
    (dict(algo="seps", n_step=1000, steps=16_000), "steps = 16000 is invalid; allowed: >= n_envs * n_step = 32000"),
    (dict(algo="oappo", rollout_len=1000, steps=16_000), "allowed: >= n_envs * rollout_len = 32000"),
    (dict(algo="oappo", n_envs=1, rollout_len=1, steps=4), "n_envs = 1 and rollout_len = 1 give one sample per "
                                                           "iteration; allowed: n_envs * rollout_len >= 2"),
    (dict(algo="happo", n_envs=1, rollout_len=1, steps=4), "give one sample per iteration"),
])
def test_a_config_names_the_field_that_sets_what_it_refuses(kw, words):
    """SEAC's rollout is n_step long: a message naming rollout_len named a flag SEAC refuses; a
    batch of one sample was accepted and then reported as a non-finite Eq. 8 loss."""
    with pytest.raises(ValueError, match=re.escape(words)):
        TrainConfig(**kw)
    TrainConfig(algo="oappo", n_envs=2, rollout_len=1, steps=4)  # two samples have a spread


def test_a_run_that_diverges_says_whether_its_last_checkpoint_already_holds_non_finite_values(tmp_path):
    cfg = TrainConfig(algo="happo", **SMALL)
    train(cfg, tmp_path, progress=False)
    state = RunState.start(cfg)
    good = str(_diverged_at(Diverged("the PPO loss (Eq. 8)", 0), state, tmp_path))
    assert "the last checkpoint" in good and "non-finite" not in good
    ck = load_checkpoint(tmp_path)
    name = next(iter(ck["actors"]))
    ck["actors"][name] = torch.full_like(ck["actors"][name], float("nan"))
    torch.save(ck, tmp_path / "checkpoint.pt")
    bad = str(_diverged_at(Diverged("the PPO loss (Eq. 8)", 0), state, tmp_path))
    assert f"already holds non-finite values (actors/{name})" in bad and "--no-resume" in bad and "good" not in bad


def test_a_checkpoint_whose_cost_is_below_its_last_row_is_damaged(tmp_path):
    """The run's sums go on from the checkpoint's cost: one below what a row already recorded
    would make cpu_s fall in the next rows."""
    cfg = TrainConfig(algo="happo", **SMALL)
    train(cfg, tmp_path, progress=False)
    ck = load_checkpoint(tmp_path)
    ck["cost"] = {"cpu_s": 0.0, "wall_s": ck["cost"]["wall_s"]}
    torch.save(ck, tmp_path / "checkpoint.pt")
    with pytest.raises(store.DamagedFile, match=r"its cost cpu_s = 0.0 is below its last row's .*; a sum so far never"):
        load_checkpoint(tmp_path)


def test_a_job_that_another_process_finished_while_it_waited_says_it_trained_nothing(tmp_path):
    """Two ``reproduce`` on one cache both reported the runs as trained: the second waited for the
    first's lock and then found each run finished. A run written again from its own finished
    checkpoint (its results file was damaged) still counts as done here."""
    cfg = TrainConfig(algo="oappo", **SMALL)
    rows, error, trained = train_job(cfg, str(tmp_path / "other"))
    assert (error, trained) == (None, True) and train_job(cfg, str(tmp_path / "other"))[1:] == (None, True)
    run = tmp_path / "run"
    run.mkdir()
    held = store.Lock(run / ".lock")  # the first process, training
    assert held.acquire(wait=False)
    result = {}
    second = threading.Thread(target=lambda: result.update(outcome=train_job(cfg, str(run))))
    second.start()
    time.sleep(1.0)
    shutil.copy(tmp_path / "other" / "checkpoint.pt", run / "checkpoint.pt")  # the first one's last checkpoint
    held.release()
    second.join(60)
    again, error_again, trained_again = result["outcome"]
    assert (error_again, trained_again) == (None, False)
    pd.testing.assert_frame_equal(learning(rows), learning(again))
