"""Checkpoints are data (issue 54). What a run writes holds nothing beyond ``runstate.DATA``; a
checkpoint holding any other type is refused as damaged, naming the file and the type, and
nothing in it runs, wherever a run is read: ``load_checkpoint``, ``load_history``,
``train(resume=True)``, the command line's ``train`` and ``reproduce``'s ``train_job``. A
PettingZoo env's copies go into a checkpoint as data and come back into the copies ``env_fn``
makes."""
import os
import random
import re
import shutil

import numpy as np
import pandas as pd
import pytest
import torch

from oapo_lite import __main__ as cli, store
from oapo_lite.envs import MazeParallelEnv, parse_maze
from oapo_lite.envs.pettingzoo_vec import PettingZooVec, restore, snapshot
from oapo_lite.neural import runstate
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.results import learning
from oapo_lite.neural.runstate import load_checkpoint, load_history
from oapo_lite.neural.train import train
from oapo_lite.study.runs.executors import train_job

import fakes

torch.set_num_threads(1)

CORRIDOR = """\
agents: red black
start: 1,1 1,1
######
#...*#
######
"""
TINY = dict(env=CORRIDOR, n_envs=16, rollout_len=10, max_steps=10, eval_every=2, eval_episodes=16, steps=320)
SYSTEM = f"{os.system.__module__}.system"  # what pickle names os.system by: posix.system here


class Planted:
    """What someone who can write to a run folder adds to its checkpoint: unpickling it runs a
    shell command, here one that makes a marker file."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run's folder, and its rows."""
    out = tmp_path_factory.mktemp("finished")
    return out, train(TrainConfig(algo="oappo", **TINY), out, progress=False)


def plant(run, where: str, value) -> None:
    """Put ``value`` into ``run``'s checkpoint: at the top, or deep in the last history entry."""
    ck = load_checkpoint(run)
    if where == "top":
        ck["extra"] = value
    else:
        ck["history"][-1]["note"] = [value]
    torch.save(ck, run / "checkpoint.pt")


READERS = {
    "load_checkpoint": lambda run: load_checkpoint(run),
    "load_history": lambda run: load_history(run),
    "train": lambda run: train(TrainConfig(algo="oappo", **TINY), run, progress=False),  # resume=True
}


@pytest.mark.parametrize("where", ["top", "history"])
@pytest.mark.parametrize("reader", READERS)
def test_a_planted_object_is_refused_naming_it_and_nothing_runs(finished, tmp_path, reader, where):
    shutil.copytree(finished[0], tmp_path / "run")
    marker = tmp_path / "ran"
    plant(tmp_path / "run", where, Planted(marker))
    with pytest.raises(store.DamagedFile) as err:
        READERS[reader](tmp_path / "run")
    assert not marker.exists()
    assert f"checkpoint {tmp_path / 'run' / 'checkpoint.pt'} holds ['{SYSTEM}']" in str(err.value)
    assert "nothing in it was run" in str(err.value) and "resume=False" in str(err.value)


def test_the_command_line_refuses_it_in_one_line_and_reproduce_trains_the_run_again(tmp_path, capfd):
    argv = ["train", "--env", "black_red", "--n-envs", "8", "--rollout-len", "25", "--steps", "400",
            "--eval-episodes", "4", "--no-progress", "--out", str(tmp_path)]
    assert cli.main(argv) == 0
    (run,) = tmp_path.iterdir()
    first = pd.read_csv(run / "results.csv")
    marker = tmp_path.parent / f"{tmp_path.name}-ran"
    plant(run, "top", Planted(marker))
    capfd.readouterr()
    assert cli.main(argv) == 2
    err = capfd.readouterr().err.strip()
    assert "\n" not in err and f"checkpoint {run / 'checkpoint.pt'} holds ['{SYSTEM}']" in err and "--no-resume" in err
    assert not marker.exists()
    # reproduce's way: named on stderr, then trained again from the start, to the same rows
    cfg = TrainConfig(algo="oappo", env="black_red", n_envs=8, rollout_len=25, steps=400, eval_episodes=4)
    rows, error, _ = train_job(cfg, str(run))
    assert error is None and not marker.exists()
    assert f"holds ['{SYSTEM}']" in capfd.readouterr().err
    assert len(rows) == len(first)
    pd.testing.assert_frame_equal(learning(first), learning(pd.read_csv(run / "results.csv")))


def test_an_array_of_objects_is_refused_by_its_dtype(finished, tmp_path):
    """An object array would hold objects: its dtype is outside the allowlist, whatever it holds."""
    shutil.copytree(finished[0], tmp_path / "run")
    plant(tmp_path / "run", "history", np.array([1, "a"], dtype=object))
    with pytest.raises(store.DamagedFile, match=r"holds \['numpy.dtypes.ObjectDType'\]"):
        load_checkpoint(tmp_path / "run")


@pytest.mark.parametrize("fields", [
    dict(algo="oappo", **TINY),
    dict(algo="oatrpo", normalize=True, **TINY),
    dict(algo="seps", **{**TINY, "seps_pretrain_steps": 240, "checkpoint_every": 1}),  # stopped in pre-training
    dict(algo="happo", **{**TINY, "env_fn": lambda: MazeParallelEnv(parse_maze(CORRIDOR), max_steps=10)}),
], ids=["maze", "normalized", "seps", "pettingzoo"])
def test_what_a_run_writes_holds_only_data(tmp_path, fields):
    """Every global a checkpoint's pickle names is one of ``runstate.DATA`` (listed without
    unpickling), and none of the old layout's objects."""
    if fields["algo"] == "seps":
        fakes.interrupt(TrainConfig(**fields), tmp_path, at=2)  # the buffer holds its transitions
    else:
        train(TrainConfig(**fields), tmp_path, progress=False)
    named = torch.serialization.get_unsafe_globals_in_checkpoint(tmp_path / "checkpoint.pt")
    assert set(named) <= set(runstate.allowed_names(runstate.DATA)), named
    ck = load_checkpoint(tmp_path)
    assert type(ck["step"]) is dict
    if fields["algo"] == "seps":
        assert type(ck["learner"]["buffer"]) is list and ck["learner"]["buffer"]


class Odd:
    """An env-like object: shared and self-referring attributes, a generator, code, and data a
    protocol-2 pickle writes as calls (empty bytes, an empty array, a frozenset)."""

    def __init__(self):
        self.shared = {"a": np.arange(3)}
        self.also = self.shared
        self.me = self
        self.rng = np.random.default_rng(0)
        self.fn = len
        self.t = 0
        self.parts = [np.zeros(2), np.zeros(0, np.float32), b"", frozenset({1}), {2}, np.int64(3), np.array(["x"])]


def test_a_snapshot_comes_back_through_a_checkpoint_file_into_the_live_objects(tmp_path):
    """Into the live objects at the same places, keeping what was one object one (and a cycle)."""
    live = Odd()
    saved = Odd()
    saved.shared["a"][:] = 7
    saved.t = 5
    saved.rng.random(3)
    saved.parts.append(np.ones(1))
    torch.save(snapshot(saved, "odd"), tmp_path / "odd.pt")
    back = restore(live, runstate.read_data(tmp_path / "odd.pt"), "odd")
    assert back is live and live.me is live and live.also is live.shared
    assert live.shared["a"].tolist() == [7, 7, 7] and live.t == 5 and live.fn is len
    assert [type(x) for x in live.parts] == [type(x) for x in saved.parts] and live.parts[-1].tolist() == [1.0]
    assert live.parts[1].dtype == np.float32 and live.parts[2:6] == [b"", frozenset({1}), {2}, 3]
    assert live.rng.random() == saved.rng.random()


def test_a_snapshot_refuses_what_is_not_data_and_restore_makes_nothing_from_a_name():
    odd = Odd()
    odd.rng = random.Random(0)  # its state is kept in C, not in its attributes
    with pytest.raises(TypeError, match=r"env\.rng is a random\.Random, which a checkpoint cannot hold as data"):
        snapshot(odd, "env")
    data = snapshot(Odd(), "env")
    data["type"] = "subprocess.Popen"
    expected = f"env held a subprocess.Popen; this env has a {Odd.__module__}.Odd"
    with pytest.raises(ValueError, match=re.escape(expected)):
        restore(Odd(), data, "env")


def test_a_pettingzoo_env_resumes_through_a_checkpoint_file_into_fresh_copies(tmp_path):
    def make():
        return PettingZooVec(lambda: MazeParallelEnv("black_red", max_steps=6), n_envs=3, seed=0)

    env = make()
    env.reset()
    actions = np.random.default_rng(0).integers(0, env.n_actions, (30, 3, env.n_agents))
    for a in actions[:7]:
        env.step(a)
    torch.save(env.get_state(), tmp_path / "state.pt")
    first = [env.step(a) for a in actions[7:]]
    fresh = make()
    fresh.reset()
    fresh.set_state(runstate.read_data(tmp_path / "state.pt"))
    again = [fresh.step(a) for a in actions[7:]]
    assert sum(s.truncated.sum() for s in first) > 0
    for a, b in zip(first, again):
        for name in a.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
