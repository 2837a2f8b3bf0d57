"""The command line under bad input, damage and signals: every error is one line with exit status 2
and no traceback; an interrupt stops every process a command started at once."""
import argparse
import errno
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bad_input import QUICK, SMALL, STOP_LIMIT_S, children, cli_error, fifo, kill, not_zombie, outliving, quick_but
from oapo_lite import __main__ as cli, store
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures
from oapo_lite.study.runs import experiments
from oapo_lite.study.judge import evidence
from oapo_lite.study.report import plotting


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
    err = cli_error(capsys, "train", *quick_but(argv), "--out", str(tmp_path), *argv)
    for word in words:
        assert word in err


def test_a_diverging_oatrpo_run_is_one_line(tmp_path, capsys):
    err = cli_error(capsys, "train", "--algo", "oatrpo", "--lr", "1e6", "--critic-lr", "1e6", "--n-envs", "8",
                     "--rollout-len", "25", "--steps", "6000", "--eval-every", "100", "--no-progress",
                     "--out", str(tmp_path))
    assert "of oatrpo seed 0" in err and "is not finite" in err


@pytest.mark.parametrize("out", ["a_file", "a_file/below", "/proc/no_such/folder"])
def test_an_output_folder_that_cannot_be_made_is_named(tmp_path, capsys, out):
    (tmp_path / "a_file").write_text("x")
    target = out if out.startswith("/") else str(tmp_path / out)
    err = cli_error(capsys, "train", *QUICK, "--out", target)
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
    err = cli_error(capsys, command, *(QUICK if command == "train" else []), "--out", path)
    assert words.format(tmp=tmp_path) in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "notes.txt"]  # nothing written


def test_a_relative_oapo_figures_is_resolved_once_and_a_moved_tree_without_the_committed_runs_is_refused(
        tmp_path, capsys, monkeypatch):
    from oapo_lite.study.runs import reproduce

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("OAPO_FIGURES", "moved")
    err = cli_error(capsys, "reproduce", "--budget", "smoke", "--figures", "fig1")
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
    (["--workers", "0"], ["--workers", "'0' is invalid", "an integer in [1, 1024]"]),
    (["--workers", "-3"], ["'-3' is invalid"]),
    (["--budget", "huge"], ["unknown budget 'huge'", "smoke"]),
])
def test_a_bad_reproduce_option_is_one_line(capsys, argv, words):
    err = cli_error(capsys, "reproduce", *argv)
    for word in words:
        assert word in err


@pytest.mark.parametrize("target", ["a_file", "/proc/no_such"])
def test_oapo_figures_that_cannot_be_written_is_one_line(tmp_path, capsys, monkeypatch, target):
    (tmp_path / "a_file").write_text("x")
    target = target if target.startswith("/") else str(tmp_path / target)
    monkeypatch.setenv("OAPO_FIGURES", target)
    err = cli_error(capsys, "reproduce", "--skip-notebooks")
    assert f"OAPO_FIGURES='{target}'" in err and "cannot write results" in err \
        or f"OAPO_FIGURES '{target}' is a file; allowed: a folder" in err


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
    while time.time() < deadline and any(os.path.exists(f"/proc/{p}") and not_zombie(p) for p in pids):
        time.sleep(0.2)
    assert not [p for p in pids if os.path.exists(f"/proc/{p}") and not_zombie(p)]


def test_a_bool_flag_reads_false_as_false(tmp_path, capsys):
    assert cli.main(["train", *QUICK, "--out", str(tmp_path), "--lr-anneal", "false", "--value-norm", "false"]) == 0
    rows = pd.read_csv(next(tmp_path.glob("*/results.csv")))
    assert (rows["lr_anneal"] == False).all() and (rows["value_norm"] == False).all()  # noqa: E712


def test_help_exits_0_and_an_unknown_command_names_the_commands(capsys):
    assert cli.main(["--help"]) == 0 and "python -m oapo_lite train" in capsys.readouterr().out
    assert cli.main(["trian"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'trian'" in err and "['train', 'reproduce', 'book']" in err


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
        err = cli_error(capsys, "train", *QUICK, "--out", str(disk), "--hidden", "512", "512")
        assert "no space left on the device" in err and "--out" in err
    finally:
        subprocess.run(["umount", str(disk)], check=True)


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
    workers = children(driver.pid)
    try:
        assert len([p for p, parent in workers.items() if parent == driver.pid]) >= 2, workers
        for i, sig in enumerate(signals):
            (os.killpg if to_group else os.kill)(driver.pid, sig)
            sent = sent if i else time.time()
            time.sleep(0.05)
        _, err = driver.communicate(timeout=4 * STOP_LIMIT_S)
        assert driver.returncode == 130 and time.time() - sent < STOP_LIMIT_S, err
        assert not outliving(workers, sent)  # no worker, nor anything it started
    finally:  # a failed stop leaves nothing running either
        kill(driver.pid, *workers)
    assert "run the same command again to resume" in err and "Traceback" not in err
    assert len(list(started.iterdir())) == 2  # no queued run started


def test_stopping_the_process_pool_kills_what_its_jobs_started_and_starts_no_queued_job(tmp_path):
    """The notebook stage's pool: a job's own children (a kernel) die with it."""
    script = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import signal; "
              "signal.signal(signal.SIGTERM, signal.default_int_handler); "
              f"from bad_input import sleeping_driver; from pathlib import Path; "
              f"sleeping_driver(Path({str(tmp_path / 'finished')!r}))")
    driver = subprocess.Popen([sys.executable, "-c", script], start_new_session=True, stderr=subprocess.PIPE,
                              text=True)
    deadline = time.time() + 120
    while time.time() < deadline and sum(len(children(w)) for w in children(driver.pid)) < 2:
        time.sleep(0.2)  # both workers have started their job's child
    below = children(driver.pid)
    try:
        assert len(below) >= 4, below  # two workers, a child each
        os.kill(driver.pid, signal.SIGTERM)
        sent = time.time()
        _, err = driver.communicate(timeout=4 * STOP_LIMIT_S)
        assert time.time() - sent < STOP_LIMIT_S and "KeyboardInterrupt" in err
        assert not outliving(below, sent) and not (tmp_path / "finished").exists()
    finally:
        kill(driver.pid, *below)


def test_no_command_and_a_folder_as_map_are_one_line(tmp_path, capsys):
    assert cli.main([]) == 2 and "error: no command given" in capsys.readouterr().err
    assert "is a folder" in cli_error(capsys, "train", *QUICK, "--out", str(tmp_path), "--env", str(tmp_path))
    board = tmp_path / "a_file"
    board.write_text("x")
    assert "is a file; allowed: a folder" in cli_error(capsys, "train", *QUICK, "--out", str(tmp_path / "o"),
                                                        "--tensorboard", str(board))


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


def test_the_second_audits_cases_are_refused(tmp_path, capsys, monkeypatch):
    """Found by a second hostile audit after the first fixes."""
    from oapo_lite.study.report import book

    assert "--budget is given 2 times" in cli_error(capsys, "reproduce", "--budget", "smoke", "--budget", "cpu")
    assert "--inplace writes" in cli_error(capsys, "reproduce", "--inplace", "--skip-notebooks")
    afile = tmp_path / "site"
    afile.write_text("x")
    assert "is a file; allowed: a folder" in cli_error(capsys, "book", "--out", str(afile))
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
    assert f"error: the lock file {lock} is a folder, not a file; delete it" in err and "Traceback" not in err
    out = tmp_path / "runs"
    quick = TrainConfig(n_envs=8, rollout_len=25, steps=400, eval_episodes=4)  # QUICK's run
    (out / quick.run_id() / ".lock").mkdir(parents=True)
    assert "is a folder, not a file; delete it" in cli_error(capsys, "train", *QUICK, "--out", str(out))


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


# ---------------------------------------------------------------- issue 53: a run file that is no file


@pytest.mark.parametrize("plan", [True, False], ids=["--plan", "train"])
def test_reproduce_names_a_run_file_that_is_no_file_and_ends(tmp_path, capsys, monkeypatch, plan):
    """Both hung on a FIFO in the run cache, and a Ctrl-C then read it again."""
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    (cfg,) = [c for _, c in figures.figure_runs("fig1", "smoke")]
    path = experiments.run_path(cfg, "smoke")
    path.parent.mkdir(parents=True)
    with fifo(path):
        err = cli_error(capsys, "reproduce", "--budget", "smoke", "--figures", "fig1", "--skip-notebooks",
                        *(["--plan"] if plan else ["--check"]))
    assert f"run file {path} is a FIFO (named pipe), not a file; delete or move it" in err


# ---------------------------------------------------------------- issue 53: a name that names nothing


@pytest.mark.parametrize("budget, figure, runs_at", [
    ("student", "fig4_smax", "['smoke', 'paper', 'cpu']"),
    ("student", "fig5b", "['smoke', 'paper', 'paper20', 'cpu']"),
    ("smoke", "fig_dose_smax", "['cpu']"),
])
@pytest.mark.parametrize("plan", [True, False], ids=["--plan", "train"])
def test_reproduce_refuses_a_named_figure_without_runs_at_the_budget(tmp_path, capsys, monkeypatch, budget, figure,
                                                                    runs_at, plan):
    """It said "0 trained" and "0 of 0 runs" without a word that the figure has none there."""
    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    err = cli_error(capsys, "reproduce", "--budget", budget, "--figures", figure, "--skip-notebooks",
                    *(["--plan"] if plan else []))
    assert f"figure '{figure}' has no runs at budget '{budget}'; it has runs at {runs_at}" in err


# ---------------------------------------------------------------- issue 53: a connection with a deadline


@pytest.mark.parametrize("address, words", [
    ("127.0.0.1:1", "no Ray cluster at '127.0.0.1:1': connection refused (a connection waits at most 10 s)"),
    ("no-such-host.invalid:6379", "Ray address 'no-such-host.invalid:6379': no such host 'no-such-host.invalid'"),
    ("ray://127.0.0.1:1", "no Ray cluster at 'ray://127.0.0.1:1': connection refused"),
    ("localhost:1", "no Ray cluster at 'localhost:1'"),
])
def test_a_plan_on_a_ray_cluster_that_is_not_there_ends_within_its_deadline(capsys, address, words):
    """The plan only counts the cluster's CPUs, yet waited on 127.0.0.1:1 past 580 s."""
    start = time.monotonic()
    err = cli_error(capsys, "reproduce", "--plan", "--executor", "ray", "--address", address)
    assert words in err and time.monotonic() - start < 60


def test_a_head_that_never_answers_is_named_with_the_wait(monkeypatch):
    from oapo_lite.study.runs import executors

    def silent(address, timeout):
        raise TimeoutError("timed out")

    monkeypatch.setattr(executors.socket, "create_connection", silent)
    with pytest.raises(ConnectionError, match=r"no Ray cluster answered at '10.0.0.1:6379' within 2 s; start one"):
        executors.reach("10.0.0.1:6379", deadline=2)


def test_a_port_that_takes_the_connection_and_says_nothing_is_no_ray_head():
    """A proxy or another server may accept TCP and then stay silent: Ray's client retried that for
    30 s and said "ray client connection timeout"; the handshake check names the address."""
    import socket
    import threading

    from oapo_lite.study.runs import executors

    server = socket.create_server(("127.0.0.1", 0))
    accepted = []
    threading.Thread(target=lambda: accepted.append(server.accept()), daemon=True).start()
    address = f"ray://127.0.0.1:{server.getsockname()[1]}"
    start = time.monotonic()
    with pytest.raises(ConnectionError, match=rf"no Ray cluster answered at '{address}' within 2 s: the port takes "
                                              "connections but gives no gRPC handshake"):
        executors.reach(address, deadline=2)
    assert time.monotonic() - start < 10
    server.close()


# ---------------------------------------------------------------- issue 53: a path the system refuses


@pytest.mark.parametrize("command, where, value, words", [
    ("train", "--out", "~nonexistentuser/x", "--out '~nonexistentuser/x' starts with ~nonexistentuser, but there is no "
                                             "user 'nonexistentuser'"),
    ("reproduce", "OAPO_FIGURES", "~nonexistentuser/x", "OAPO_FIGURES '~nonexistentuser/x' starts with ~nonexistentuser, "
                                                        "but there is no user"),
    ("book", "--out", "~nonexistentuser/x", "--out '~nonexistentuser/x' starts with ~nonexistentuser"),
    ("train", "--out", "loopA", "--out 'loopA' cannot be used: it runs through a loop of symbolic links"),
    ("train", "--out", "n" * 300, "cannot be used: a name in it is longer than the file system allows"),
    # neighbours: another flag, the variable, the other commands, a whole path too long, a FIFO
    ("train", "--tensorboard", "loopA/board", "--tensorboard 'loopA/board' cannot be used: it runs through a loop"),
    ("reproduce", "OAPO_FIGURES", "n" * 300, "OAPO_FIGURES 'nnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnnn'... (300 "
                                             "characters) cannot be used: a name in it is longer"),
    ("book", "--out", "loopA", "--out 'loopA' cannot be used: it runs through a loop of symbolic links"),
    ("train", "--out", "/".join(["d" * 200] * 25), "(5024 characters) cannot be used: a name in it is longer"),
    ("train", "--out", "pipe", "--out 'pipe' is a FIFO (named pipe); allowed: a folder"),
])
def test_a_path_the_system_refuses_is_named_by_its_cause(tmp_path, capsys, monkeypatch, command, where, value, words):
    """~nonexistentuser ended in "RuntimeError: Could not determine home directory (a bug in
    oapo_lite?)", a loop was called a link to a missing file, a long name a bare [Errno 36]."""
    monkeypatch.chdir(tmp_path)
    Path("loopA").symlink_to("loopB")
    Path("loopB").symlink_to("loopA")
    os.mkfifo("pipe")
    if where == "OAPO_FIGURES":
        monkeypatch.setenv("OAPO_FIGURES", value)
        argv = ["reproduce", "--figures", "fig1", "--skip-notebooks"]
    else:
        argv = [command, *(QUICK if command == "train" else []), *(["--out", "o"] if where != "--out" else []),
                where, value]
    assert words in cli_error(capsys, *argv)


def test_a_full_disk_under_book_is_one_line_naming_the_out_device(tmp_path, capsys, monkeypatch):
    """Sphinx's 52-line crash report came before the one line, and a failed copy named the
    source notebook rather than the --out device."""
    from oapo_lite.study.report import book

    monkeypatch.setattr(book, "check_packages", lambda: None)
    monkeypatch.setattr(book, "mathjax_dir", lambda: tmp_path / "mathjax")
    (tmp_path / "mathjax").mkdir()
    report = "\n".join(["Traceback (most recent call last):", *["  a frame"] * 48,
                        "OSError: [Errno 28] No space left on device",
                        "The full traceback has been saved in /tmp/sphinx-err-x.log, if you want to report the issue."])
    monkeypatch.setattr(book.subprocess, "run", lambda *a, **k: subprocess.CompletedProcess(a, 2, "", report))
    out = tmp_path / "site"
    assert cli_error(capsys, "book", "--out", str(out)) == (f"error: no space left on the device: {out}; free some "
                                                              "space or write elsewhere (--out, OAPO_FIGURES)\n")

    def full(source, target, **kw):
        raise OSError(errno.ENOSPC, "No space left on device", str(source))

    monkeypatch.setattr(book.shutil, "copy2", full)
    assert f"no space left on the device: {out};" in cli_error(capsys, "book", "--out", str(out))


def test_book_without_its_packages_says_how_to_install_them(tmp_path, capsys):
    from oapo_lite.study.report import book

    try:
        book.check_packages()
        pytest.skip("the book's packages are installed here")
    except ImportError:
        pass
    assert "not installed; run `make book-deps`" in cli_error(capsys, "book", "--out", str(tmp_path / "site"))


# ---------------------------------------------------------------- issue 53: counts that mean what they say


@pytest.mark.parametrize("argv, words", [
    (["--plan", "--workers", "1" + "0" * 23], "'100000000000000000000000' is invalid; allowed: an integer in [1, 1024]"),
    (["--workers", "1025"], "'1025' is invalid; allowed: an integer in [1, 1024]"),
])
def test_a_worker_count_beyond_any_machine_is_refused(capsys, argv, words):
    """The plan priced 10^23 workers."""
    assert words in cli_error(capsys, "reproduce", *argv)
    from oapo_lite.study.runs import costs

    for call in (lambda: costs.plan("smoke", ["fig1"], workers=10**23),
                 lambda: experiments.run_all("smoke", ["fig1"], workers=10**23)):
        with pytest.raises(ValueError, match=r"workers = 100000000000000000000000 is invalid; allowed: an integer in "
                                             r"\[1, 1024\]"):
            call()


# ---------------------------------------------------------------- issue 53: first contact


def test_help_gives_a_usage_line_and_the_commands_without_markup(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python -m oapo_lite {train,reproduce,book}") and "``" not in out
    assert all(f"\n  {name} " in out for name in cli.COMMANDS)


@pytest.mark.parametrize("command", ["train", "reproduce", "book"])
def test_a_commands_help_answers_before_the_heavy_imports(command):
    """train --help and reproduce --help took 4-6 s, importing torch before parsing a flag."""
    code = (f"import sys; from oapo_lite.__main__ import main\ntry:\n    main([{command!r}, '--help'])\n"
            "except SystemExit:\n    pass\nprint('torch' in sys.modules, 'pandas' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and f"python -m oapo_lite {command}" in done.stdout, done.stderr
    assert done.stdout.split()[-2:] == ["False", "False"], done.stdout


def test_the_plan_explains_its_columns(capsys, monkeypatch, tmp_path):
    from oapo_lite.study.runs import costs

    monkeypatch.setenv("OAPO_FIGURES", str(tmp_path))
    assert cli.main(["reproduce", "--budget", "smoke", "--figures", "fig1", "--plan"]) == 0
    out = capsys.readouterr().out
    head = out.splitlines()[0].split("  ")
    legend = costs.LEGEND.replace("\n", " ")
    assert [c.strip() for c in head if c.strip()] == ["figure", "runs", "env steps", "on disk", "to train",
                                                       "steps to train", "CPU hours", "from"]
    assert all(f"{word} (" in legend or f"{word}:" in legend for word in ("on disk", "CPU hours", "from", "records",
                                                                          "table", "none"))
    assert "- (nothing to train)" in legend and costs.LEGEND in out


def test_every_apt_install_is_quiet_and_without_recommends():
    """make browser installed 116 packages and printed apt's whole output."""
    makefile = (Path(cli.__file__).parents[1] / "Makefile").read_text().replace("\\\n", " ")  # continued lines
    recipes = re.findall(r"apt-get install[^\n]*", makefile)
    assert len(recipes) == 2 and all("--no-install-recommends" in r and "-qq" in r and "> /dev/null" in r
                                     for r in recipes)
